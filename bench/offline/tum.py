"""The TUM trajectory format (as evo, the TUM RGB-D tools and many SLAM packages read it),
written and read by posbench itself.

A TUM file is text, one pose a line, eight numbers separated by spaces::

    timestamp x y z qx qy qz qw

Lines starting with ``#`` are comments; empty lines are skipped. posbench's tracks are
planar: ``timestamp`` is a query time [s], ``x``, ``y`` are metres east and north in the
drive's local ENU frame, ``z`` is 0 and the orientation is the identity quaternion
``0 0 0 1`` (posbench's predictors answer positions only, no heading; a translation APE,
evo's default, never reads the orientation). Numbers are written as Python's ``repr`` of
the float (shortest text that reads back to the same float), so times and positions survive
the round trip bit for bit: an estimate and a reference written from the same query time
carry identical timestamps, which evo associates exactly.

:func:`write_tum` writes one, :func:`read_tum` reads and checks one (a
:class:`~posbench.scenarios.errors.DataError` naming the file and line for anything else).
A comment ``# drive: NAME`` names the drive the poses belong to (written by ``bench
export``, read by ``bench score``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posbench.scenarios.errors import DataError

#: what a TUM file's columns are (its first comment line says so)
COLUMNS = ("timestamp", "x", "y", "z", "qx", "qy", "qz", "qw")
#: the comment that names a file's drive: ``# drive: NAME``
DRIVE_COMMENT = "drive:"
#: the comment ``bench export`` writes: the timestamps are a saved run's drive times
#: (``traces.parquet``'s clock), not a queries folder's (which may start ``t0_s`` later)
RUN_CLOCK_COMMENT = "clock: run"
SUFFIX = ".tum"


def is_tum(path: str | Path) -> bool:
    """Whether ``path`` names a TUM file (suffix ``.tum``, any case)."""
    return Path(path).suffix.lower() == SUFFIX


def tum_lines(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> list[str]:
    """One TUM line per pose: time ``t`` [s], east ``x`` and north ``y`` [m], z = 0, the
    identity quaternion; every number as the float's ``repr`` (exact)."""
    return [
        f"{ti!r} {xi!r} {yi!r} 0.0 0.0 0.0 0.0 1.0"
        for ti, xi, yi in zip(
            np.asarray(t, dtype=float).tolist(),
            np.asarray(x, dtype=float).tolist(),
            np.asarray(y, dtype=float).tolist(),
            strict=True,
        )
    ]


def write_tum(
    path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, comments: Sequence[str] = ()
) -> Path:
    """Write a TUM file: ``comments`` (each a ``# `` line), then one line per pose (see
    :func:`tum_lines`; times [s], ENU positions [m]). Returns ``path``."""
    head = [f"# {c}" for c in comments] + ["# " + " ".join(COLUMNS)]
    path.write_text("\n".join([*head, *tum_lines(t, x, y)]) + "\n")
    return path


@dataclass
class TumFile:
    """A TUM file read back: per pose its time ``t`` [s], ``x``, ``y`` [m] (z and the
    quaternion are read, checked to be numbers and dropped), the 1-based ``line`` it is on,
    and the drive a ``# drive: NAME`` comment names (None: no such comment); ``run_clock``:
    the file says its times are a saved run's (``# clock: run``, written by ``bench export``)."""

    path: Path
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    line: np.ndarray
    drive: str | None
    run_clock: bool = False


def read_tum(path: str | Path) -> TumFile:
    """Read a TUM file (whitespace-separated; ``#`` comments and empty lines skipped).

    Raises:
        DataError: no such file, not text, a line without exactly 8 numbers, a non-finite
            time or position, or no pose at all; each naming the file and line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(path, f"not readable as a TUM text file: {e}") from None
    rows: list[list[float]] = []
    lines: list[int] = []
    drive = None
    run_clock = False
    for n, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s[1:].strip()
            if drive is None and body.lower().startswith(DRIVE_COMMENT):
                drive = body[len(DRIVE_COMMENT) :].strip() or None
            run_clock = run_clock or body.lower() == RUN_CLOCK_COMMENT
            continue
        parts = s.split()
        if len(parts) != len(COLUMNS):
            raise DataError(
                path,
                f"line {n}: {len(parts)} columns, a TUM line has 8 ("
                f"{' '.join(COLUMNS)}, separated by spaces)",
            )
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            bad = next(p for p in parts if not _is_float(p))
            raise DataError(
                path, f"line {n}: {bad!r} is not a number (a TUM line is {' '.join(COLUMNS)})"
            ) from None
        if not all(np.isfinite(vals[:3])):
            raise DataError(
                path,
                f"line {n}: non-finite timestamp, x or y ({' '.join(parts[:3])}"
                f"); leave the line out to give no answer",
            )
        rows.append(vals)
        lines.append(n)
    if not rows:
        raise DataError(
            path, f"no poses: every line is empty or a comment (a TUM line is {' '.join(COLUMNS)})"
        )
    a = np.asarray(rows, dtype=float)
    return TumFile(
        path,
        a[:, 0].copy(),
        a[:, 1].copy(),
        a[:, 2].copy(),
        np.asarray(lines, dtype=np.int64),
        drive,
        run_clock,
    )


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
