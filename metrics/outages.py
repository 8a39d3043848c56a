"""GPS-outage metrics: pure functions on per-query errors [m] and times [s].

- error as a function of time since the last received fix, at fixed checkpoints
  (0.2, 0.5, 1, 2, 5 s: a query counts for a checkpoint when its time since the last
  fix is within ``tolerance_s`` of it);
- per outage: ADE (mean error over the outage's queries), FDE (error of its last
  query, just before the fix returns) and the miss rate (share of outages whose FDE
  exceeds ``miss_threshold_m``, 2 m by default).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from posbench.metrics.accuracy import summarize

SINCE_FIX_CHECKPOINTS_S = (0.2, 0.5, 1.0, 2.0, 5.0)
#: edges [s] of the time-since-last-fix bins of a curve of error over it, 0.1 s to 10 min
#: (:func:`since_fix_bins` with ``open_last``: the last bin takes everything past 300 s)
SINCE_FIX_CURVE_EDGES_S = (
    0,
    0.1,
    0.2,
    0.3,
    0.5,
    0.75,
    1,
    1.5,
    2,
    3,
    4,
    5,
    6,
    8,
    10,
    15,
    20,
    30,
    45,
    60,
    90,
    120,
    180,
    300,
    600,
)
#: a query counts for a checkpoint when its time since the last fix is this close to it [s]
SINCE_FIX_TOLERANCE_S = 0.05
#: an outage is missed when its FDE exceeds this [m]
MISS_THRESHOLD_M = 2.0

#: what each figure of this module means (the report's glossary collects these)
DEFINITIONS = {
    "after fix": (
        "mean current-position (now) error over the queries whose time since the "
        f"last received fix is within {SINCE_FIX_TOLERANCE_S:g} s of the checkpoint "
        "(0.2 s, 0.5 s, ...), in runs with GPS dropouts."
    ),
    "ADE": "average displacement error: mean now-error over one GPS outage's queries, then "
    "averaged over outages [m].",
    "FDE": "final displacement error: now-error of an outage's last query, just before the "
    "fix returns, averaged over outages (FDE p95: its 95th percentile) [m].",
    "miss rate": f"share of outages whose FDE exceeds {MISS_THRESHOLD_M:g} m.",
}


def outage_ids(t_query: np.ndarray, outages: Sequence[tuple[float, float]]) -> np.ndarray:
    """Index of the outage (t_last_fix, t_next_fix) each query time falls strictly
    inside; -1 if none."""
    t = np.asarray(t_query, dtype=float)
    ids = np.full(t.size, -1, dtype=np.int64)
    if not len(outages):
        return ids
    o = np.asarray(outages, dtype=float)
    order = np.argsort(o[:, 0])
    starts, ends = o[order, 0], o[order, 1]
    k = np.searchsorted(starts, t, side="left") - 1  # last outage starting strictly before t
    inside = (k >= 0) & (t < ends[np.clip(k, 0, None)])
    ids[inside] = order[k[inside]]
    return ids


#: an outage's run-wide key: its drive's code x OUTAGE_ID_BASE + its index in the drive
OUTAGE_ID_BASE = 1_000_000


def outage_keys(drive_codes: np.ndarray, outage: np.ndarray) -> np.ndarray:
    """A run-wide key of each query's outage (:func:`outage_ids` within its drive, the
    drive's integer code): ``code * OUTAGE_ID_BASE + outage``; -1 outside outages."""
    outage = np.asarray(outage)
    return np.where(outage >= 0, np.asarray(drive_codes) * OUTAGE_ID_BASE + outage, -1)


def outage_drive(keys: np.ndarray) -> np.ndarray:
    """The drive code of each outage key of :func:`outage_keys` (the bootstrap's cluster)."""
    return np.asarray(keys) // OUTAGE_ID_BASE


def error_vs_since_fix(
    errors: np.ndarray,
    since_fix_s: np.ndarray,
    checkpoints_s: Sequence[float] = SINCE_FIX_CHECKPOINTS_S,
    tolerance_s: float = SINCE_FIX_TOLERANCE_S,
) -> dict[str, dict[str, float | int]]:
    """Summary of errors at each checkpoint of time since the last fix, keyed like ``"1s"``."""
    e = np.asarray(errors, dtype=float)
    s = np.asarray(since_fix_s, dtype=float)
    return {f"{c:g}s": summarize(e[np.abs(s - c) <= tolerance_s]) for c in checkpoints_s}


def since_fix_bins(
    since_fix_s: np.ndarray, edges: Sequence[float] | np.ndarray, open_last: bool = False
) -> np.ndarray:
    """The bin of each time since the last fix [s] among ``edges`` (bin i holds
    ``edges[i] <= s < edges[i + 1]``); -1 for NaN, before the first edge and past the last
    one, unless ``open_last`` puts those past it into the last bin."""
    s = np.asarray(since_fix_s, dtype=float)
    e = np.asarray(edges, dtype=float)
    idx = np.searchsorted(e, s, side="right") - 1
    if open_last:
        idx = np.where(idx >= e.size - 1, e.size - 2, idx)
    idx[~np.isfinite(s) | (idx < 0) | (idx >= e.size - 1)] = -1
    return idx


def since_fix_checkpoint(
    since_fix_s: np.ndarray,
    checkpoints_s: Sequence[float] = SINCE_FIX_CHECKPOINTS_S,
    tolerance_s: float = SINCE_FIX_TOLERANCE_S,
) -> np.ndarray:
    """The key of :func:`error_vs_since_fix` (``"1s"``, ...) each query counts for, ``""``
    for none (the checkpoints are further apart than twice the tolerance)."""
    s = np.asarray(since_fix_s, dtype=float)
    out = np.full(s.size, "", dtype=object)
    for c in checkpoints_s:
        out[np.abs(s - c) <= tolerance_s] = f"{c:g}s"
    return out


def per_outage(
    errors: np.ndarray, t_query: np.ndarray, ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per outage with at least one finite error, in increasing id: its id, ADE [m] (mean
    error over its queries), FDE [m] (error of its last query) and the time of that last
    query [s]."""
    e = np.asarray(errors, dtype=float)
    t = np.asarray(t_query, dtype=float)
    ids = np.asarray(ids)
    out_id, ade, fde, t_end = [], [], [], []
    for k in np.unique(ids[ids >= 0]):
        sel = np.flatnonzero((ids == k) & np.isfinite(e))
        if sel.size == 0:
            continue
        last = sel[np.argmax(t[sel])]
        out_id.append(k)
        ade.append(e[sel].mean())
        fde.append(e[last])
        t_end.append(t[last])
    return (
        np.asarray(out_id, dtype=np.int64),
        np.asarray(ade, dtype=float),
        np.asarray(fde, dtype=float),
        np.asarray(t_end, dtype=float),
    )


def outage_scores(
    errors: np.ndarray,
    t_query: np.ndarray,
    ids: np.ndarray,
    miss_threshold_m: float = MISS_THRESHOLD_M,
) -> dict[str, float | int]:
    """ADE / FDE statistics over outages and the miss rate.

    Args:
        errors: per-query errors [m]; t_query: their times [s]; ids: outage index per
            query (-1 outside outages), from :func:`outage_ids`.
    """
    _, ade_a, fde_a, _ = per_outage(errors, t_query, ids)
    return outage_figures_of(ade_a, fde_a, miss_threshold_m)


def outage_figures_of(
    ade_a: np.ndarray, fde_a: np.ndarray, miss_threshold_m: float = MISS_THRESHOLD_M
) -> dict[str, float | int]:
    """:func:`outage_scores` from each outage's ADE and FDE [m] (:func:`per_outage`)."""
    n = int(fde_a.size)
    return {
        "outages": n,
        "ade_mean_m": float(ade_a.mean()) if n else float("nan"),
        "fde_mean_m": float(fde_a.mean()) if n else float("nan"),
        "fde_p95_m": float(np.percentile(fde_a, 95)) if n else float("nan"),
        "miss_rate": float(np.mean(fde_a > miss_threshold_m)) if n else float("nan"),
    }
