"""Scoring, its own pure step: queries + a predictor's answers -> per-query traces.

``bench run`` replays a drive through each predictor and scores the answers here; answers
that come from elsewhere (a file written by another program) go through the same
:func:`score`, matched to the queries by drive, kind and query time. Aggregation
(:mod:`posbench.results`) works from the traces only.

:data:`TRACE_COLUMNS` documents every column of ``traces.parquet`` (the README's table
is generated from it: :func:`trace_columns_markdown`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.metrics.accuracy import euclidean_error
from posbench.metrics.outages import outage_ids
from posbench.metrics.track_errors import track_errors
from posbench.prepare import LABELS, PreparedDrive, Queries

#: column -> (type, unit, meaning); frames: x/y in the drive's local ENU metres
TRACE_COLUMNS: dict[str, tuple[str, str, str]] = {
    "dataset": ("str", "", "data set (the loader's format, e.g. kitti, aslan, synthetic)"),
    "drive": ("str", "", "drive name"),
    "predictor": ("str", "", "predictor name as run (NAME or NAME@ALIAS)"),
    "kind": ("category", "", "`future`: position at fix time + horizon, asked at the fix; "
             "`now`: current position, asked every now-step"),
    "t_issue": ("float64", "s", "when the query was asked (every observation given is at or before it)"),
    "t_query": ("float64", "s", "the instant whose position was asked for"),
    "x": ("float64", "m", "answer, east (NaN: no answer)"),
    "y": ("float64", "m", "answer, north"),
    "x_ref": ("float64", "m", "reference position, east (truth, or a cubic through the fixes; "
              "NaN: none)"),
    "y_ref": ("float64", "m", "reference position, north"),
    "error_m": ("float64", "m", "Euclidean distance answer - reference"),
    "along_m": ("float64", "m", "error along the reference's direction of travel: + ahead, "
                "- lagging (NaN at standstill, below 0.5 m/s)"),
    "cross_m": ("float64", "m", "error across the reference's direction of travel: + left, "
                "- right (ENU; NaN at standstill)"),
    "label": ("category", "", "scenario at t_query: straight, turn, roundabout, start_stop, "
              "unlabelled"),
    "speed_mps": ("float64", "m/s", "reference speed at t_query (NaN: unknown)"),
    "since_fix_s": ("float64", "s", "t_query minus the time of the last fix received by t_issue"),
    "outage": ("int64", "", "index of the GPS outage t_query falls in within its drive, -1: none"),
    "warmup": ("bool", "", "asked before the drive's second received fix (left out of headline "
               "figures)"),
    "heading_ref": ("float64", "rad", "the reference's direction of travel at t_query, "
                    "counter-clockwise from east (from the reference 0.1 s before and after; "
                    "NaN: standstill or unknown)"),
    "yaw_rate_ref": ("float64", "rad/s", "the reference's yaw rate at t_query, + = turning left "
                     "(NaN: unknown)"),
    "cov_xx": ("float64", "m^2", "the answer's reported covariance (`covariance_at`, ENU): "
               "variance east (NaN: the predictor reports no uncertainty for it)"),
    "cov_xy": ("float64", "m^2", "reported covariance east-north"),
    "cov_yy": ("float64", "m^2", "reported variance north"),
}
#: the answer's reported uncertainty (filled with NaN in traces written before it existed)
COV_COLUMNS = ("cov_xx", "cov_xy", "cov_yy")
#: the columns a query table holds (all but the predictor and its answer)
ANSWER_COLUMNS = ("predictor", "x", "y", "error_m", "along_m", "cross_m", *COV_COLUMNS)
QUERY_COLUMNS = tuple(c for c in TRACE_COLUMNS if c not in ANSWER_COLUMNS)
#: query columns an answer key written before they existed may lack (filled with NaN)
TRACK_QUERY_COLUMNS = ("heading_ref", "yaw_rate_ref")
#: fixed categories keep the string columns of long traces at one byte a row, also
#: after concatenation (identical categories concatenate as categoricals)
LABEL_CATEGORIES = [*LABELS, "unlabelled"]
KIND_DTYPE = pd.CategoricalDtype(["future", "now"])
#: answers from a file are matched to queries whose t_query is this close [s]: far below
#: the query spacing (>= 1 ms), far above what a CSV round trip of the times can change
MATCH_TOLERANCE_S = 1e-6


def warmup_end_s(prep: PreparedDrive) -> float:
    """When a drive's warm-up ends [s]: the time of its second received fix (inf with fewer).

    Queries issued before it are warm-up: no predictor can know a velocity from one fix, so
    their errors measure the cold start, not prediction. They are kept in the traces
    (column ``warmup``) and reported apart, never in the headline figures.
    """
    return float(prep.gps.t[1]) if len(prep.gps) >= 2 else float("inf")


def query_frame(prep: PreparedDrive, kind: str) -> pd.DataFrame:
    """One drive's queries of one kind (``future`` or ``now``) with what they are scored
    against: the :data:`QUERY_COLUMNS` of the traces."""
    q: Queries = prep.future if kind == "future" else prep.now
    return pd.DataFrame({
        "dataset": prep.dataset, "drive": prep.drive.name, "kind": kind,
        "t_issue": q.t_issue, "t_query": q.t_query,
        "x_ref": q.ref_xy[:, 0], "y_ref": q.ref_xy[:, 1],
        "label": pd.Categorical(q.label, categories=LABEL_CATEGORIES),
        "speed_mps": q.speed_mps, "since_fix_s": q.since_fix_s,
        "outage": outage_ids(q.t_query, prep.outages),
        "warmup": q.t_issue < warmup_end_s(prep),
        "heading_ref": _or_nan(q.heading_rad, q.t_query.size),
        "yaw_rate_ref": _or_nan(q.yaw_rate, q.t_query.size),
    }).astype({"kind": KIND_DTYPE})


def _or_nan(values: np.ndarray | None, n: int) -> np.ndarray:
    return np.full(n, np.nan) if values is None else np.asarray(values, dtype=float)


def answer_positions(queries: pd.DataFrame, answers: pd.DataFrame,
                     tolerance_s: float = MATCH_TOLERANCE_S) -> np.ndarray:
    """For each answer row, the 0-based row of ``queries`` it answers: same ``drive`` and
    ``kind``, the nearest ``t_query`` [s] within ``tolerance_s``; -1 where there is none.

    Both frames need columns drive, kind and t_query. Vectorised per (drive, kind) pair.
    """
    q_drive = queries["drive"].astype(str).to_numpy()
    q_kind = queries["kind"].astype(str).to_numpy()
    a_drive = answers["drive"].astype(str).to_numpy()
    a_kind = answers["kind"].astype(str).to_numpy()
    d_codes, _ = pd.factorize(np.concatenate([q_drive, a_drive]))
    k_codes, kinds = pd.factorize(np.concatenate([q_kind, a_kind]))
    group = d_codes.astype(np.int64) * max(len(kinds), 1) + k_codes
    gq, ga = group[:len(queries)], group[len(queries):]
    tq = queries["t_query"].to_numpy(float)
    ta = answers["t_query"].to_numpy(float)
    out = np.full(len(answers), -1, dtype=np.int64)
    order = np.lexsort((tq, gq))  # queries by group, then time
    g_sorted = gq[order]
    for g in np.unique(ga):
        lo, hi = np.searchsorted(g_sorted, [g, g + 1])
        mine = np.flatnonzero(ga == g)
        if lo == hi:
            continue  # no query of this drive and kind
        rows = order[lo:hi]
        times = tq[rows]
        i = np.searchsorted(times, ta[mine])
        left, right = np.clip(i - 1, 0, times.size - 1), np.clip(i, 0, times.size - 1)
        nearest = np.where(np.abs(ta[mine] - times[left]) <= np.abs(times[right] - ta[mine]),
                           left, right)
        ok = np.abs(times[nearest] - ta[mine]) <= tolerance_s
        out[mine[ok]] = rows[nearest[ok]]
    return out


def match_answers(queries: pd.DataFrame, answers: pd.DataFrame) -> np.ndarray:
    """(N, 2) answers [m] in the order of ``queries``, matched on drive, kind and t_query
    (within :data:`MATCH_TOLERANCE_S`, :func:`answer_positions`); a query without an answer
    gets NaN (counted as missing).

    Raises:
        ValueError: an answer matches no query, or two answers match one query.
    """
    pos = answer_positions(queries, answers)
    if (pos < 0).any():
        a = answers.iloc[int(np.flatnonzero(pos < 0)[0])]
        raise ValueError(f"no query for drive {a['drive']}, kind {a['kind']}, "
                         f"t_query {float(a['t_query']):.9f} s")
    seen, first = np.unique(pos, return_index=True)
    if seen.size < pos.size:
        twice = np.setdiff1d(np.arange(pos.size), first)[0]
        a = answers.iloc[int(twice)]
        raise ValueError(f"two answers for drive {a['drive']}, kind {a['kind']}, "
                         f"t_query {float(a['t_query']):.9f} s")
    xy = np.full((len(queries), 2), np.nan)
    xy[pos] = answers[["x", "y"]].to_numpy(float)
    return xy


def score(queries: pd.DataFrame, predictor: str, answers: np.ndarray | pd.DataFrame,
          cov: np.ndarray | None = None) -> pd.DataFrame:
    """Traces of one predictor: ``queries`` (a :func:`query_frame`, or several concatenated)
    with the predictor's answers and their errors, columns as :data:`TRACE_COLUMNS`.

    Args:
        queries: the query table.
        predictor: the predictor's name as run.
        answers: (N, 2) positions [m] in the order of ``queries`` (a live replay), or a
            frame with drive, kind, t_query, x, y (answers from a file), matched by
            :func:`match_answers`.
        cov: with array answers, their (N, 3) reported covariances cov_xx, cov_xy, cov_yy
            [m^2] (NaN: none); a frame of answers brings its own columns.
    """
    cov = (np.full((len(queries), 3), np.nan) if cov is None
           else np.asarray(cov, dtype=float).reshape(-1, 3).copy())
    if isinstance(answers, pd.DataFrame):
        xy = match_answers(queries, answers)
        if all(c in answers for c in COV_COLUMNS):
            cov[answer_positions(queries, answers)] = answers[list(COV_COLUMNS)].to_numpy(float)
    else:
        xy = np.asarray(answers, dtype=float).reshape(-1, 2)
        if len(xy) != len(queries):
            raise ValueError(f"{len(xy)} answers for {len(queries)} queries")
    return score_many(queries, [(predictor, xy, cov)])


def score_many(queries: pd.DataFrame, answers: Sequence[tuple[Any, ...]]) -> pd.DataFrame:
    """Traces of several predictors on the same ``queries``, one after the other, built in
    one go (one frame, not one per predictor and a concatenation); :func:`score` is its
    one-predictor case. A test holds it equal to concatenating per-kind results.

    Args:
        queries: the query table (a :func:`query_frame`, or several concatenated).
        answers: (predictor name as run, (N, 2) positions [m] in the order of ``queries``)
            or, from a live replay of a predictor reporting uncertainty, (name, positions,
            (N, 3) covariances cov_xx, cov_xy, cov_yy [m^2] or None). Durations are not
            traces: they stay in the DriveRun (``cov_ns``), so traces are deterministic.
    """
    if not answers:
        return pd.DataFrame()
    n, k = len(queries), len(answers)
    xy = np.concatenate([np.asarray(a[1], dtype=float).reshape(-1, 2) for a in answers])
    if len(xy) != n * k:
        raise ValueError(f"{len(xy)} answers for {k} x {n} queries")

    def tiled(c: str) -> Any:
        col = queries[c]
        if isinstance(col.dtype, pd.CategoricalDtype):
            return pd.Categorical.from_codes(np.tile(col.cat.codes.to_numpy(), k), dtype=col.dtype)
        return pd.array(np.tile(col.to_numpy(), k), dtype=col.dtype)

    ref = np.tile(queries[["x_ref", "y_ref"]].to_numpy(float), (k, 1))
    heading = (np.tile(queries["heading_ref"].to_numpy(float), k) if "heading_ref" in queries
               else np.full(n * k, np.nan))
    along, cross = track_errors(xy, ref, heading)
    names = np.empty(k, dtype=object)
    names[:] = [a[0] for a in answers]
    cols: dict[str, Any] = {c: tiled(c) for c in ("dataset", "drive")}
    cols["predictor"] = pd.array(np.repeat(names, n), dtype=cols["drive"].dtype)
    cols.update({c: tiled(c) for c in ("kind", "t_issue", "t_query")})
    cols.update({"x": xy[:, 0], "y": xy[:, 1], "x_ref": ref[:, 0], "y_ref": ref[:, 1],
                 "error_m": euclidean_error(xy, ref), "along_m": along, "cross_m": cross})
    cols.update({c: tiled(c) for c in ("label", "speed_mps", "since_fix_s", "outage", "warmup")})
    for c in TRACK_QUERY_COLUMNS:
        cols[c] = tiled(c) if c in queries else np.nan
    cov = np.full((n * k, 3), np.nan)
    for j, a in enumerate(answers):
        if len(a) > 2 and a[2] is not None:
            cov[j * n:(j + 1) * n] = a[2]
    cols.update({c: cov[:, i] for i, c in enumerate(COV_COLUMNS)})
    return pd.DataFrame(cols)


def trace_columns_markdown() -> str:
    """The Markdown table of :data:`TRACE_COLUMNS` (the README shows it; a test keeps the two equal)."""
    lines = ["| column | type | unit | meaning |", "|---|---|---|---|"]
    lines += [f"| `{c}` | {t} | {u or '-'} | {m} |" for c, (t, u, m) in TRACE_COLUMNS.items()]
    return "\n".join(lines)
