"""Error at the end of GPS outages of given lengths, in metres and as a share of the distance
driven since the last fix: pure functions on per-query errors [m], times [s] and reference
positions [m] (local ENU).

Per outage (the queries between the last fix before it and the fix that ends it):

- its **length class**: the longest of the profile's lengths [s] that the outage (time from
  the last fix before it to the first fix after it) is at least as long as
  (:func:`length_classes`; an outage cut as L seconds lasts L plus the fix intervals on
  either side);
- **FDE** [m]: error of its last query, just before the fix returns (as
  :func:`posbench.metrics.outages.per_outage`);
- **ATE** [m]: root mean square of the error over its queries (the RMS, as evo's and the
  TUM benchmark's absolute trajectory error is an RMSE; the outage's ADE is the mean);
- **distance** [m]: path length of the reference from the last fix to the outage's last
  query (:func:`path_lengths`).

Per length class, over its outages (:func:`length_figures`): the mean FDE and ATE [m], and
the same as **% of the distance travelled**: 100 x sum(FDE) / sum(distance) (a ratio of
sums, as TrackEval recomputes ratios from summed counts: an outage at a standstill adds its
error and no distance, instead of a division by nearly zero).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: what each figure of this module means (the report's glossary collects these)
DEFINITIONS = {
    "outage length": "an outage's length class: the longest of the profile's lengths (1, 2, "
    "5, 10, 30, 60 s) that the time from the last fix before it to the fix after it reaches.",
    "ATE (outage)": "absolute trajectory error of one outage: root mean square of the "
    "now-error over its queries [m] (evo's ATE is an RMSE too), averaged over outages.",
    "% of distance": "100 x sum of FDE (or ATE) / sum of the reference's path length from "
    "the last fix to the outage's last query, over one length's outages: error per distance "
    "driven without GPS (not KITTI's t_rel: see the Concepts page on outage lengths).",
}


def length_classes(
    duration_s: np.ndarray, lengths_s: Sequence[float], tol_s: float = 1e-6
) -> np.ndarray:
    """The length class [s] of each outage of ``duration_s`` (last fix before it to first
    fix after it): the longest of ``lengths_s`` not above its duration (+ ``tol_s``);
    NaN for an outage shorter than all of them."""
    d = np.asarray(duration_s, dtype=float)
    ls = np.sort(np.asarray(lengths_s, dtype=float))
    k = np.searchsorted(ls, d + tol_s, side="right") - 1
    out = np.full(d.shape, np.nan)
    ok = (k >= 0) & np.isfinite(d)
    out[ok] = ls[k[ok]]
    return out


def path_lengths(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, t0: np.ndarray, t1: np.ndarray
) -> np.ndarray:
    """Path length [m] of the track (t [s], x, y [m]; t increasing) from each ``t0`` to its
    ``t1`` [s]: the polyline through the track's points, its ends interpolated linearly;
    NaN where either end lies outside the track's time span."""
    t = np.asarray(t, dtype=float)
    t0 = np.asarray(t0, dtype=float)
    t1 = np.asarray(t1, dtype=float)
    if t.size < 2:
        return np.full(np.broadcast(t0, t1).shape, np.nan)
    steps = np.hypot(np.diff(np.asarray(x, dtype=float)), np.diff(np.asarray(y, dtype=float)))
    cum = np.concatenate([[0.0], np.cumsum(steps)])
    out = np.interp(t1, t, cum) - np.interp(t0, t, cum)
    inside = (t0 >= t[0]) & (t1 <= t[-1]) & (t0 <= t1)
    return np.where(inside, out, np.nan)


def per_outage_ate(
    errors: np.ndarray, t_query: np.ndarray, ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per outage with at least one finite error, in increasing id: its id, FDE [m] (error
    of its last query), ATE [m] (RMS of the error over its queries) and the time of its
    last query [s]."""
    e = np.asarray(errors, dtype=float)
    t = np.asarray(t_query, dtype=float)
    ids = np.asarray(ids)
    m = (ids >= 0) & np.isfinite(e)
    e, t, ids = e[m], t[m], ids[m]
    order = np.lexsort((t, ids))  # by outage, then time: each outage's last query ends its run
    e, t, ids = e[order], t[order], ids[order]
    uid, start, count = np.unique(ids, return_index=True, return_counts=True)
    last = start + count - 1
    ate = np.sqrt(np.add.reduceat(e * e, start) / count) if uid.size else np.empty(0)
    return uid.astype(np.int64), e[last], ate.astype(float), t[last]


def length_figures(
    fde_m: np.ndarray, ate_m: np.ndarray, distance_m: np.ndarray
) -> dict[str, float | int]:
    """Figures of one length class's outages: ``outages`` (those with a finite FDE and
    distance), ``distance_mean_m``, ``fde_mean_m``, ``ate_mean_m`` [m], and ``fde_pct``,
    ``ate_pct``: 100 x sum(FDE or ATE) / sum(distance) [% of the distance travelled since
    the last fix]; NaN without outages (and the % NaN when no distance was travelled)."""
    f = np.asarray(fde_m, dtype=float)
    a = np.asarray(ate_m, dtype=float)
    d = np.asarray(distance_m, dtype=float)
    m = np.isfinite(f) & np.isfinite(a) & np.isfinite(d)
    f, a, d = f[m], a[m], d[m]
    n = int(f.size)
    total = float(d.sum())
    nan = float("nan")
    return {
        "outages": n,
        "distance_mean_m": float(d.mean()) if n else nan,
        "fde_mean_m": float(f.mean()) if n else nan,
        "ate_mean_m": float(a.mean()) if n else nan,
        "fde_pct": 100.0 * float(f.sum()) / total if n and total > 0 else nan,
        "ate_pct": 100.0 * float(a.sum()) / total if n and total > 0 else nan,
    }
