"""Answers produced elsewhere, scored exactly as ``bench run`` scores its predictors.

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

The answers are turned into the same :class:`~posbench.scoring.records.DriveRun` records as a replay
(:func:`score_answers`), through :func:`posbench.scoring.score.score`, so aggregation, the report
and ``results.json`` are those of ``bench run``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.offline.queries_folder import QueryFolder
from posbench.offline.tum import is_tum, read_tum
from posbench.scenarios.drive import MAX_POSITION_M as DRIVE_MAX_POSITION_M
from posbench.scenarios.errors import DataError
from posbench.scenarios.text import quoted
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import COV_COLUMNS, KINDS
from posbench.scoring.score import MATCH_TOLERANCE_S, answer_positions, score

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


def tum_drive(folder: QueryFolder, answers: Answers) -> str:
    """The id (in ``folder``) of the drive a TUM file answers: the drive its ``# drive:``
    comment names (by id or by name), else the longest drive id its file name starts with,
    followed by ``.`` (``ID.tum``, ``ID.kf.now.tum``).

    Raises:
        DataError: a ``# drive:`` comment naming no drive of the folder, or no comment and
            a file name that starts with no drive id.
    """
    ids = [str(d["id"]) for d in folder.drives]
    by_name = {str(d["name"]): str(d["id"]) for d in folder.drives}
    shown = ", ".join(ids[:5]) + (", ..." if len(ids) > 5 else "")
    name = answers.tum_drive
    if name is not None:
        if name in ids:
            return name
        if name in by_name:
            return by_name[name]
        raise DataError(
            answers.path,
            f"'# drive: {name}' names no drive of the queries "
            f"folder {folder.folder} (its drives: {shown})",
        )
    file = answers.path.name
    hits = [i for i in ids if file.startswith(i + ".")]
    if not hits:
        raise DataError(
            answers.path,
            f"cannot tell which drive it answers: no '# drive: ID' "
            f"line and its name does not start with a drive id of "
            f"the queries folder {folder.folder} followed by '.' "
            f"(its drives: {shown}); name it ID.tum or add the line",
        )
    return max(hits, key=len)


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


@dataclass
class Scored:
    """Answers scored against a queries folder: the per-drive records (as a replay gives
    them) and, per drive name, the queries without an answer per kind."""

    runs: list[DriveRun]
    unanswered: dict[str, dict[str, int]]
    answered: int
    queries: int

    @property
    def missing(self) -> int:
        """Queries without an answer, all drives and kinds."""
        return sum(sum(k.values()) for k in self.unanswered.values())


def _nearest_hint(times: np.ndarray, t: float) -> str:
    if times.size == 0:
        return "that drive has no such queries"
    j = int(np.argmin(np.abs(times - t)))
    return f"nearest: {float(times[j])!r} s, {abs(float(times[j]) - t):.3g} s away"


def match(folder: QueryFolder, answers: Answers) -> np.ndarray:
    """For each answer row, the row of ``folder.key`` it answers (raising on answers to no
    query, to a drive not in the folder or skipped there, and on a second answer to one query)."""
    a = answers.frame
    ids = {d["id"]: d for d in folder.drives}
    if answers.is_tum:
        a["drive"] = tum_drive(folder, answers)
        if answers.tum_run_clock and a["drive"].iloc[0] in ids:
            a["t_query"] = a["t_query"] - float(ids[a["drive"].iloc[0]]["t0_s"])
    known = np.isin(a["drive"].to_numpy(), list(ids))
    if not known.all():
        i = int(np.flatnonzero(~known)[0])
        shown = ", ".join(list(ids)[:5]) + (", ..." if len(ids) > 5 else "")
        raise answers.fail(
            int(a.index[i]),
            f"drive {a['drive'].iloc[i]!r} is not in the queries "
            f"folder {folder.folder} (its drives: {shown})",
        )
    skipped = np.array([ids[d]["skipped"] is not None for d in a["drive"].to_numpy()], dtype=bool)
    if skipped.any():
        i = int(np.flatnonzero(skipped)[0])
        d = ids[a["drive"].iloc[i]]
        raise answers.fail(
            int(a.index[i]),
            f"drive {d['id']!r} has no queries (skipped by bench queries: {d['skipped']})",
        )
    public = folder.public_times()
    pos = answer_positions(public, a)
    if (pos < 0).any():
        i = int(np.flatnonzero(pos < 0)[0])
        row = a.iloc[i]
        same = (public["drive"] == row["drive"]) & (public["kind"] == row["kind"])
        hint = _nearest_hint(public.loc[same, "t_query"].to_numpy(float), float(row["t_query"]))
        if answers.is_tum:
            hint += (
                "; a TUM timestamp is the query's t_query as in queries.csv: seconds from "
                "the drive's first input sample, not Unix time"
            )
        raise answers.fail(
            int(a.index[i]),
            f"no query of drive {row['drive']!r}, kind "
            f"{row['kind']} at t_query "
            f"{float(row['t_query'])!r} s "
            f"({hint}; times match within "
            f"{MATCH_TOLERANCE_S:g} s)",
        )
    dup = pd.Series(pos).duplicated().to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        first = int(np.flatnonzero(pos == pos[i])[0])
        row = a.iloc[i]
        raise answers.fail(
            int(a.index[i]),
            f"a second answer to the query answered on "
            f"{answers.where(int(a.index[first]))} (drive "
            f"{row['drive']!r}, kind {row['kind']}, t_query "
            f"{float(public['t_query'].iloc[pos[i]])!r} s)",
        )
    return pos


def score_answers(
    folder: QueryFolder,
    answers: Answers,
    predictor: str,
    on_done: Callable[[str], None] | None = None,
) -> Scored:
    """Score ``answers`` as predictor ``predictor`` against ``folder``: per drive (folder
    order) the :class:`~posbench.scoring.records.DriveRun` a replay would give, traces from
    :func:`posbench.scoring.score.score` (unanswered queries NaN, i.e. ``missing``), step latency
    from the ``latency_us`` of future answers and query latency from that of now answers [ns].
    ``on_done(drive name)`` is called as each drive is scored."""
    pos = match(folder, answers)
    key = folder.key
    n = len(key)
    xy = np.full((n, 2), np.nan)
    xy[pos] = answers.frame[["x", "y"]].to_numpy(float)
    cov = np.full((n, 3), np.nan)
    cov[pos] = answers.frame[list(COVARIANCE)].to_numpy(float)
    lat_us = np.full(n, np.nan)
    lat_us[pos] = answers.frame["latency_us"].to_numpy(float)
    answered = np.zeros(n, dtype=bool)
    answered[pos] = True
    codes, names = pd.factorize(key["drive"].astype(str))
    rows_of = {str(name): np.flatnonzero(codes == c) for c, name in enumerate(names)}
    kind = key["kind"].astype(str).to_numpy()
    runs, unanswered = [], {}
    for d in folder.drives:
        if d["skipped"] is not None:
            runs.append(folder.drive_run(d, pd.DataFrame()))
            continue
        rows = rows_of.get(d["name"], np.empty(0, dtype=np.int64))
        traces = score(key.iloc[rows], predictor, xy[rows], cov=cov[rows])
        run = folder.drive_run(d, traces)
        for k, attr in (("future", "step_ns"), ("now", "query_ns")):
            mine = rows[(kind[rows] == k) & np.isfinite(lat_us[rows])]
            getattr(run, attr)[predictor] = np.round(lat_us[mine] * 1e3).astype(np.int64)
        miss = {k: int(((kind[rows] == k) & ~answered[rows]).sum()) for k in KINDS}
        if sum(miss.values()):
            unanswered[d["name"]] = miss
            run.notes = [
                *run.notes,
                f"answers: {sum(miss.values())} of {rows.size} queries "
                f"without an answer (future {miss['future']}, now "
                f"{miss['now']}), scored as missing",
            ]
        runs.append(run)
        if on_done:
            on_done(d["name"])
    return Scored(runs, unanswered, len(pos), n)
