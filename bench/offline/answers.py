"""Answers files produced elsewhere (CSV, Parquet or TUM), read and checked to be scored as
``bench run`` scores its predictors.

An answers file (CSV or Parquet, column names case-insensitive) has one row per answered
query: ``drive`` (as in the queries list), ``kind`` (``future`` or ``now``), ``t_query`` [s]
(as in the queries list: from the drive's first input sample), ``x``, ``y`` [m] (the drive's
local ENU frame, as the inputs) and optionally ``latency_us`` [us] (how long the system took
for that answer; empty = not timed) and ``cov_xx``, ``cov_xy``, ``cov_yy`` [m^2] (the answer's
reported 2x2 ENU covariance, all three or none; empty = no uncertainty for that answer; it
must be positive semi-definite). Other columns are ignored.

A row answers the query of its drive and kind whose ``t_query`` is within
:data:`~posbench.scoring.score.MATCH_TOLERANCE_S` (1e-6 s) of its own. A query without an answer is
scored as ``missing`` (never dropped); an answer to no query, two answers to one query, a
drive the queries folder does not hold, a missing or non-finite cell, an x or y more than
:data:`MAX_POSITION_M` (1e9 m) from the drive's origin, a latency below 0 or over
:data:`MAX_LATENCY_US` (1e9 us, 1000 s): a :class:`DataError` naming the
file and the first such row (CSV line number, header = line 1; Parquet row).

A TUM trajectory file (suffix ``.tum``: lines ``timestamp x y z qx qy qz qw`` separated
by whitespace, ``#`` comments; :mod:`posbench.offline.tum`) answers the ``now`` queries of
one drive: ``timestamp`` is ``t_query`` [s] on the queries folder's clock (as in
``queries.csv``: from the drive's first input sample, not Unix time), ``x``, ``y`` [m] the
local ENU position; ``z`` and the quaternion are read and ignored. Its drive is the one a
comment line ``# drive: NAME`` names (the drive's id in the queries folder or its name, as
``bench export`` writes it), else the drive id its file name starts with (``ID.tum``,
``ID.anything.tum``; the longest such id). A line that is not 8 numbers, a drive it cannot
name and a timestamp matching no now query are errors naming the file and line.

The answers are read and checked here (:func:`read_answers`); they are scored against a
queries folder by :mod:`posbench.offline.answer_scoring`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.offline.tum import is_tum, read_tum
from posbench.scenarios.drive import MAX_POSITION_M as DRIVE_MAX_POSITION_M
from posbench.scenarios.errors import DataError
from posbench.scenarios.text import quoted
from posbench.scoring.schema import COV_COLUMNS, KINDS

if TYPE_CHECKING:
    from posbench.scenarios.loaders.table_file import TableFile

REQUIRED = ("drive", "kind", "t_query", "x", "y")
#: the farthest an answer's x or y may lie from its drive's origin [m]: no point on Earth is
#: that far in local metres (ENU or Mercator), and the squares the figures take stay finite
MAX_POSITION_M = DRIVE_MAX_POSITION_M  # the bound a loader holds a drive's positions to
COVARIANCE = COV_COLUMNS  # the answer's reported covariance, as in the traces
OPTIONAL = ("latency_us", *COVARIANCE)
#: the longest latency [us] an answer may state: 1000 s, beyond any machine answering a
#: position query (a larger figure is another unit or a placeholder, and its nanoseconds
#: would overflow the int64 the latency figures are taken in)
MAX_LATENCY_US = 1e9


@dataclass
class Answers:
    """A checked answers file: ``frame`` has columns drive, kind (str), t_query [s], x, y [m],
    latency_us [us] (NaN: not timed), one row per answer, indexed by the file's data row."""

    path: Path
    frame: pd.DataFrame
    is_csv: bool
    ignored: list[str] = field(default_factory=list)
    #: a TUM file: the line of each data row (1-based), its ``# drive:`` comment (None: none;
    #: the drive is then told by the file name when matched to a queries folder)
    lines: np.ndarray | None = None
    tum_drive: str | None = None
    #: a TUM file on a saved run's clock (``# clock: run``, ``bench export``): its times are
    #: moved onto the queries folder's clock (minus the drive's ``t0_s``) when matched
    tum_run_clock: bool = False

    @property
    def is_tum(self) -> bool:
        """Whether these answers came from a TUM file (``now`` answers of one drive)."""
        return self.lines is not None

    def where(self, row: int) -> str:
        """Data row ``row`` (0-based) as the user finds it: ``line N`` (CSV, TUM) or
        ``row N`` (Parquet)."""
        if self.lines is not None:
            return f"line {int(self.lines[row])}"
        return f"line {row + 2}" if self.is_csv else f"row {row + 1}"

    def fail(self, row: int, detail: str) -> DataError:
        """The error to raise for data row ``row``: the file, the row, ``detail``."""
        return DataError(self.path, f"{self.where(row)}: {detail}")


def _text(tab: TableFile, col: str) -> np.ndarray:
    """A text column stripped, every cell a non-empty string (else a DataError on its row)."""
    s = tab.df[col]
    txt = s.astype("string").str.strip()
    empty = (txt.isna() | (txt == "")).to_numpy()
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise DataError(
            tab.path, f"{tab.where(i)}, column {col!r}: empty; {int(empty.sum())} such rows in all"
        )
    text: np.ndarray = txt.to_numpy(dtype=object).astype(str)
    return text


def read_answers(path: str | Path) -> Answers:
    """Read and check an answers file (see the module docstring; a ``.tum`` file:
    :func:`read_tum_answers`).

    Raises:
        DataError: missing file or columns, a non-numeric, missing or non-finite t_query, x or
            y, an unknown kind, a negative latency or one over :data:`MAX_LATENCY_US`; each
            naming the first row at fault.
    """
    from posbench.scenarios.loaders.table_file import numeric_column, read_table_file

    path = Path(path)
    if is_tum(path):
        return read_tum_answers(path)
    tab = read_table_file(path, text_columns=("drive", "kind"))
    df = tab.df
    missing = [c for c in REQUIRED if c not in df.columns]
    if missing:
        raise DataError(
            path,
            f"missing column(s) {', '.join(missing)}: an answers file has "
            f"columns {', '.join(REQUIRED)} and optionally latency_us",
        )
    ignored = [c for c in df.columns if c not in REQUIRED + OPTIONAL]
    where = tab.where
    drive = _text(tab, "drive")
    kind = np.char.lower(_text(tab, "kind").astype(str))
    bad = ~np.isin(kind, KINDS)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataError(
            path,
            f"{where(i)}, column 'kind': {df['kind'].iloc[i]!r} is not a query "
            f"kind (future or now)",
        )
    num = {}
    for c in ("t_query", "x", "y"):
        v = numeric_column(tab, c)
        nonfinite = ~np.isfinite(v)
        if nonfinite.any():
            i = int(np.flatnonzero(nonfinite)[0])
            hint = "; leave the row out to give no answer" if c in ("x", "y") else ""
            raise DataError(
                path,
                f"{where(i)}, column {c!r}: missing or non-finite value "
                f"({quoted(df[c].iloc[i])}){hint}; {int(nonfinite.sum())} such rows "
                f"in all",
            )
        num[c] = v
    lat = np.full(len(df), np.nan)
    if "latency_us" in df.columns:
        lat = numeric_column(tab, "latency_us")
        bad = np.isinf(lat) | (lat < 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataError(
                path,
                f"{where(i)}, column 'latency_us': {quoted(df['latency_us'].iloc[i])} "
                f"is not a duration >= 0 [us] (leave it empty if not timed)",
            )
        slow = lat > MAX_LATENCY_US
        if slow.any():
            i = int(np.flatnonzero(slow)[0])
            raise DataError(
                path,
                f"{where(i)}, column 'latency_us': {lat[i]:g} us is over {MAX_LATENCY_US:g} us "
                f"({MAX_LATENCY_US / 1e6:g} s), longer than any machine takes to answer "
                f"(microseconds expected; leave it empty if not timed); "
                f"{int(slow.sum())} such rows",
            )
    frame = pd.DataFrame(
        {"drive": drive, "kind": kind, **num, "latency_us": lat, **_covariance(tab, path)}
    )
    return _positions_checked(Answers(path, frame, tab.is_csv, ignored))


def read_tum_answers(path: str | Path) -> Answers:
    """Read and check a TUM file as ``now`` answers (see the module docstring): times
    ``t_query`` [s], positions ``x``, ``y`` [m] ENU, no latency, no covariance. Its drive is
    left empty here and told when the answers are matched to a queries folder
    (:func:`tum_drive`).

    Raises:
        DataError: as :func:`posbench.offline.tum.read_tum` (file and line named).
    """
    tum = read_tum(path)
    n = tum.t.size
    frame = pd.DataFrame(
        {
            "drive": np.full(n, "", dtype=object),
            "kind": "now",
            "t_query": tum.t,
            "x": tum.x,
            "y": tum.y,
            "latency_us": np.full(n, np.nan),
            **{c: np.full(n, np.nan) for c in COVARIANCE},
        }
    )
    answers = Answers(
        Path(path),
        frame,
        False,
        [],
        lines=tum.line,
        tum_drive=tum.drive,
        tum_run_clock=tum.run_clock,
    )
    return _positions_checked(answers)


def _positions_checked(answers: Answers) -> Answers:
    """``answers`` if every x and y is within :data:`MAX_POSITION_M` of the drive's origin.

    Raises:
        DataError: naming the first row and column beyond it.
    """
    for c in ("x", "y"):
        v = answers.frame[c].to_numpy(float)
        far = np.abs(v) > MAX_POSITION_M
        if far.any():
            i = int(np.flatnonzero(far)[0])
            raise DataError(
                answers.path,
                f"{answers.where(i)}, column {c!r}: {quoted(v[i])} is no position: more than "
                f"{MAX_POSITION_M:g} m from the drive's origin, farther than any point on "
                f"Earth; {int(far.sum())} such rows in all",
            )
    return answers


def _covariance(tab: Any, path: Path) -> dict[str, np.ndarray]:
    """The optional covariance columns [m^2] (NaN where a row gives none); a DataError for
    only some of the three columns, or a row whose covariance is not positive semi-definite."""
    from posbench.scenarios.loaders.table_file import numeric_column

    df = tab.df
    given = [c for c in COVARIANCE if c in df.columns]
    if not given:
        return {c: np.full(len(df), np.nan) for c in COVARIANCE}
    if len(given) < len(COVARIANCE):
        raise DataError(
            path,
            f"covariance column(s) {', '.join(given)} without "
            f"{', '.join(c for c in COVARIANCE if c not in given)}: give all "
            f"of {', '.join(COVARIANCE)} [m^2] or none",
        )
    xx, xy, yy = (numeric_column(tab, c) for c in COVARIANCE)
    some = np.isfinite(xx) | np.isfinite(xy) | np.isfinite(yy)
    bad = some & ~(
        np.isfinite(xx)
        & np.isfinite(xy)
        & np.isfinite(yy)
        & (xx >= 0)
        & (yy >= 0)
        & (xx * yy - xy * xy >= -1e-12 * (xx * yy + 1e-300))
    )
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataError(
            path,
            f"{tab.where(i)}, columns cov_xx, cov_xy, cov_yy: "
            f"({quoted(xx[i])}, {quoted(xy[i])}, {quoted(yy[i])}) is not a covariance (all three "
            f"finite, variances >= 0, cov_xy^2 <= cov_xx cov_yy; leave all "
            f"three empty for no uncertainty)",
        )
    return {"cov_xx": xx, "cov_xy": xy, "cov_yy": yy}
