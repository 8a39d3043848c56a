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

from metrics.accuracy import summarize

SINCE_FIX_CHECKPOINTS_S = (0.2, 0.5, 1.0, 2.0, 5.0)


def outage_ids(t_query: np.ndarray, outages: Sequence[tuple[float, float]]) -> np.ndarray:
    """Index of the outage (t_last_fix, t_next_fix) each query time falls strictly inside; -1 if none."""
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


def error_vs_since_fix(errors: np.ndarray, since_fix_s: np.ndarray,
                       checkpoints_s: Sequence[float] = SINCE_FIX_CHECKPOINTS_S,
                       tolerance_s: float = 0.05) -> dict[str, dict]:
    """Summary of errors at each checkpoint of time since the last fix, keyed like ``"1s"``."""
    e = np.asarray(errors, dtype=float)
    s = np.asarray(since_fix_s, dtype=float)
    return {f"{c:g}s": summarize(e[np.abs(s - c) <= tolerance_s]) for c in checkpoints_s}


def outage_scores(errors: np.ndarray, t_query: np.ndarray, ids: np.ndarray,
                  miss_threshold_m: float = 2.0) -> dict[str, float | int]:
    """ADE / FDE statistics over outages and the miss rate.

    Args:
        errors: per-query errors [m]; t_query: their times [s]; ids: outage index per
            query (-1 outside outages), from :func:`outage_ids`.
    """
    e = np.asarray(errors, dtype=float)
    t = np.asarray(t_query, dtype=float)
    ids = np.asarray(ids)
    ade, fde = [], []
    for k in np.unique(ids[ids >= 0]):
        sel = np.flatnonzero((ids == k) & np.isfinite(e))
        if sel.size == 0:
            continue
        ade.append(e[sel].mean())
        fde.append(e[sel[np.argmax(t[sel])]])
    ade_a, fde_a = np.asarray(ade), np.asarray(fde)
    n = int(fde_a.size)
    return {
        "outages": n,
        "ade_mean_m": float(ade_a.mean()) if n else float("nan"),
        "fde_mean_m": float(fde_a.mean()) if n else float("nan"),
        "fde_p95_m": float(np.percentile(fde_a, 95)) if n else float("nan"),
        "miss_rate": float(np.mean(fde_a > miss_threshold_m)) if n else float("nan"),
    }
