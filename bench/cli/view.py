"""``bench view``: open a rerun recording, in a window or served to a browser."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.options import ConfigOpt, QuietOpt, VerboseOpt
from posbench.errors import UsageError
from posbench.recording import web as rerun_web


def no_display_reason(platform: str | None = None, env: dict[str, str] | None = None) -> str | None:
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


def _find_rerun() -> str | None:
    """The ``rerun`` CLI: on PATH, or beside this Python (a virtualenv not activated)."""
    import shutil

    return shutil.which("rerun") or shutil.which("rerun", path=str(Path(sys.executable).parent))


def view(
    recording: Annotated[
        Path, typer.Argument(metavar="FILE", help="A .rrd file written by bench run --rerun.")
    ],
    web: Annotated[
        bool,
        typer.Option(
            "--web",
            help="Serve rerun's web viewer instead of opening a window, print the "
            "URL to open in a browser (and the ssh line to reach it from "
            "another machine), and serve until Ctrl-C. Listens on 127.0.0.1 "
            "only.",
        ),
    ] = False,
    port: Annotated[
        int | None,
        typer.Option(
            "--port",
            metavar="N",
            help="With --web: the web viewer's HTTP port N; the "
            "recording is served on port N+1. Default: "
            f"{rerun_web.DEFAULT_WEB_PORT}.",
        ),
    ] = None,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """Open a rerun recording in the rerun viewer (needs the viz extra).

    Without --web a viewer window opens (needs a display). With --web, e.g. on a remote
    machine: `bench view run.rrd --web --port 9090`, then on your own machine
    `ssh -L 9090:localhost:9090 -L 9091:localhost:9091 HOST` and open the printed URL.
    """
    import subprocess

    if port is not None and not web:
        raise UsageError("--port is the web viewer's port: use it with --web")
    web_port, data_port = rerun_web.check_web_port(
        rerun_web.DEFAULT_WEB_PORT if port is None else port
    )
    if not recording.is_file():
        raise UsageError(f"{recording}: no such file")
    exe = _find_rerun()
    if exe is None:
        raise UsageError("the rerun viewer is not installed: pip install 'posbench-harness[viz]'")
    if web:
        _serve_web(exe, recording, web_port, data_port)
        return
    reason = no_display_reason()
    if reason is not None:
        raise UsageError(
            f"{reason}: serve it to a browser with `bench view {recording} --web` "
            f"and open the printed URL (from another machine through ssh -L), or "
            f"copy {recording} to a machine with a display and run `rerun "
            f"{recording}` there"
        )
    # the viewer's own log goes to a pipe: on failure its last line is quoted in ours
    proc = subprocess.run(
        [exe, str(recording)],
        stdin=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        errors="replace",
    )
    if proc.returncode != 0:
        log = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", proc.stderr or "")  # no terminal colours
        last = [ln.strip() for ln in log.splitlines() if ln.strip()]
        why = f": {last[-1][:200]}" if last else ""
        raise UsageError(
            f"the rerun viewer exited with status {proc.returncode} on {recording}{why}"
        )


def _serve_web(exe: str, recording: Path, web_port: int, data_port: int) -> None:
    """Serve ``recording`` until Ctrl-C (returns when stopped by the user).

    Raises:
        UsageError: a port is taken. ServeError: the server did not start or stopped.
    """
    import socket

    rerun_web.check_ports_free(web_port, data_port)
    url = rerun_web.viewer_url(web_port, data_port)

    def ready() -> None:
        print(
            f"serving {recording} with rerun's web viewer on {rerun_web.HOST}, ports "
            f"{web_port} (page) and {data_port} (recording); Ctrl-C stops it",
            flush=True,
        )
        print(f"open: {url}", flush=True)
        print(
            "  (renderer=webgl works without a GPU; drop it to use WebGPU in a browser "
            "that has one)",
            flush=True,
        )
        print(
            "from another machine, forward both ports first: "
            f"{rerun_web.ssh_forward_command(web_port, data_port, socket.gethostname())}",
            flush=True,
        )

    rerun_web.serve(exe, recording.resolve(), web_port, data_port, on_ready=ready)
    print("stopped", flush=True)
