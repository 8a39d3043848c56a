"""Answers produced elsewhere, scored exactly as ``bench run`` scores its predictors: each
answer matched to the query it answers (:func:`match`; a TUM file's drive found by
:func:`tum_drive`), then turned into the same :class:`~posbench.scoring.records.DriveRun`
records as a replay (:func:`score_answers`), through :func:`posbench.scoring.score.score`, so
aggregation, the report and ``results.json`` are those of ``bench run``. The answers files
themselves are read and checked by :mod:`posbench.offline.answers`. Times in seconds,
positions in metres (the drive's local ENU frame), latencies in microseconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from posbench.offline.answers import COVARIANCE, Answers
from posbench.offline.queries_folder import QueryFolder
from posbench.scenarios.errors import DataError
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.score import MATCH_TOLERANCE_S, answer_positions, score


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
