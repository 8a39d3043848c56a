"""What a ``bench run`` owns in its output folder, so a re-run into the same folder
replaces its own files and never touches anyone else's.

Each run lists the files it wrote in ``results.json`` (key ``outputs``, paths relative
to the folder). The next run into that folder removes exactly those files first (and,
for folders written before the list existed, the fixed names older runs wrote), so no
stale figure of an earlier run survives beside the new report.
"""

from __future__ import annotations

import json
from pathlib import Path

#: what runs wrote before ``outputs`` was recorded (exact names, in the folder itself)
LEGACY_OUTPUTS = (
    "results.json",
    "report.md",
    "traces.parquet",
    "error_cdf.png",
    "error_vs_speed.png",
    "error_vs_since_fix.png",
    "path.png",
    "paper_fig_prediction.png",
    "paper_fig_current_position.png",
    "paper_fig_path.png",
    "paper_fig_kalman.png",
)


def previous_outputs(out: Path) -> list[Path]:
    """The files an earlier run recorded as written into ``out`` (only paths inside it)."""
    res = out / "results.json"
    if not res.is_file():
        return []
    try:
        listed = json.loads(res.read_text()).get("outputs")
    except (OSError, ValueError, AttributeError):
        listed = None
    names = listed if isinstance(listed, list) else list(LEGACY_OUTPUTS)
    root = out.resolve()
    paths = []
    for n in names:
        if not isinstance(n, str):
            continue
        p = (out / n).resolve()
        if p.is_relative_to(root) and p != root:
            paths.append(out / n)
    return paths


def remove_previous_outputs(out: Path) -> list[Path]:
    """Delete the files an earlier run wrote into ``out``; return those removed. Folders the
    run made (e.g. ``drives/``) are removed when that leaves them empty."""
    removed = []
    for p in previous_outputs(out):
        if p.is_file() or p.is_symlink():
            p.unlink()
            removed.append(p)
    for d in sorted({p.parent for p in removed if p.parent != out}, reverse=True):
        try:
            d.rmdir()
        except OSError:  # not empty: someone else's files are there
            pass
    return removed


def relative_outputs(out: Path, written: list[Path]) -> list[str]:
    """``written`` as POSIX paths relative to ``out``, for ``results.json``."""
    return sorted({p.relative_to(out).as_posix() for p in written})
