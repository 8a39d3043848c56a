"""Scoring: queries + a predictor's answers -> per-query traces (:func:`score`,
:func:`score_many`), with answers from a file matched to their queries by drive, kind and
query time (:func:`answer_positions`, :func:`match_answers`). Pure: no replay, no file."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.metrics.accuracy import euclidean_error
from posbench.metrics.track_errors import track_errors
from posbench.scoring.schema import COV_COLUMNS, TRACK_QUERY_COLUMNS

#: answers from a file are matched to queries whose t_query is this close [s]: far below
#: the query spacing (>= 1 ms), far above what a CSV round trip of the times can change
MATCH_TOLERANCE_S = 1e-6


def answer_positions(
    queries: pd.DataFrame, answers: pd.DataFrame, tolerance_s: float = MATCH_TOLERANCE_S
) -> np.ndarray:
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
    gq, ga = group[: len(queries)], group[len(queries) :]
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
        nearest = np.where(
            np.abs(ta[mine] - times[left]) <= np.abs(times[right] - ta[mine]), left, right
        )
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
        raise ValueError(
            f"no query for drive {a['drive']}, kind {a['kind']}, "
            f"t_query {float(a['t_query']):.9f} s"
        )
    seen, first = np.unique(pos, return_index=True)
    if seen.size < pos.size:
        twice = np.setdiff1d(np.arange(pos.size), first)[0]
        a = answers.iloc[int(twice)]
        raise ValueError(
            f"two answers for drive {a['drive']}, kind {a['kind']}, "
            f"t_query {float(a['t_query']):.9f} s"
        )
    xy = np.full((len(queries), 2), np.nan)
    xy[pos] = answers[["x", "y"]].to_numpy(float)
    return xy


def score(
    queries: pd.DataFrame,
    predictor: str,
    answers: np.ndarray | pd.DataFrame,
    cov: np.ndarray | None = None,
) -> pd.DataFrame:
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
    cov = (
        np.full((len(queries), 3), np.nan)
        if cov is None
        else np.asarray(cov, dtype=float).reshape(-1, 3).copy()
    )
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
    heading = (
        np.tile(queries["heading_ref"].to_numpy(float), k)
        if "heading_ref" in queries
        else np.full(n * k, np.nan)
    )
    along, cross = track_errors(xy, ref, heading)
    names = np.empty(k, dtype=object)
    names[:] = [a[0] for a in answers]
    cols: dict[str, Any] = {c: tiled(c) for c in ("dataset", "drive")}
    cols["predictor"] = pd.array(np.repeat(names, n), dtype=cols["drive"].dtype)
    cols.update({c: tiled(c) for c in ("kind", "t_issue", "t_query")})
    cols.update(
        {
            "x": xy[:, 0],
            "y": xy[:, 1],
            "x_ref": ref[:, 0],
            "y_ref": ref[:, 1],
            "error_m": euclidean_error(xy, ref),
            "along_m": along,
            "cross_m": cross,
        }
    )
    cols.update({c: tiled(c) for c in ("label", "speed_mps", "since_fix_s", "outage", "warmup")})
    for c in TRACK_QUERY_COLUMNS:
        cols[c] = tiled(c) if c in queries else np.nan
    cov = np.full((n * k, 3), np.nan)
    for j, a in enumerate(answers):
        if len(a) > 2 and a[2] is not None:
            cov[j * n : (j + 1) * n] = a[2]
    cols.update({c: cov[:, i] for i, c in enumerate(COV_COLUMNS)})
    return pd.DataFrame(cols)
