"""`bench view`: open a rerun recording."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Annotated

import typer

from bench.commands.common import (
    fail,
)


def no_display_reason(platform: str | None = None,
                      env: dict[str, str] | None = None) -> str | None:
    """Why a viewer window cannot open here, or None if it can (as far as can be told).

    On Linux (and other X11/Wayland systems) a window needs ``DISPLAY`` or
    ``WAYLAND_DISPLAY``; macOS and Windows always have a desktop session to try.
    """
    platform = sys.platform if platform is None else platform
    env = dict(os.environ) if env is None else env
    if platform.startswith(("darwin", "win", "cygwin")):
        return None
    if env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"):
        return None
    return "no display here (neither DISPLAY nor WAYLAND_DISPLAY is set)"


def view(recording: Annotated[Path, typer.Argument(
        metavar="FILE", help="A .rrd file written by bench run --rerun.")]) -> None:
    """Open a rerun recording in the rerun viewer (needs the viz extra and a display)."""
    import shutil
    import subprocess

    if not recording.is_file():
        raise fail(f"{recording}: no such file")
    exe = shutil.which("rerun") or shutil.which("rerun", path=str(Path(sys.executable).parent))
    if exe is None:  # neither on PATH nor beside this Python (a virtualenv not activated)
        raise fail("the rerun viewer is not installed: pip install 'posbench[viz]'")
    reason = no_display_reason()
    if reason is not None:
        raise fail(f"{reason}: copy {recording} to a machine with a display and run "
                   f"`rerun {recording}` there, or serve it from here with "
                   f"`rerun --web-viewer {recording}` and open the printed URL in a browser")
    # the viewer's own log goes to a pipe: on failure its last line is quoted in ours
    proc = subprocess.run([exe, str(recording)], stdin=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True, errors="replace")
    if proc.returncode != 0:
        log = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", proc.stderr or "")  # no terminal colours
        last = [ln.strip() for ln in log.splitlines() if ln.strip()]
        why = f": {last[-1][:200]}" if last else ""
        raise fail(f"the rerun viewer exited with status {proc.returncode} on {recording}{why}")
