"""`bench view`: open a rerun recording."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from bench.commands.common import (
    fail,
)


def view(recording: Annotated[Path, typer.Argument(help="A .rrd file written by bench run --rerun.")]
         ) -> None:
    """Open a rerun recording in the rerun viewer (needs the viz extra and a display)."""
    import shutil
    import subprocess

    if not recording.is_file():
        raise fail(f"{recording}: no such file")
    exe = shutil.which("rerun")
    if exe is None:
        raise fail("the rerun viewer is not installed: pip install 'posbench[viz]'")
    raise typer.Exit(subprocess.call([exe, str(recording)]))
