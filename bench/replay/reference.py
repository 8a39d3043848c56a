"""Reference ("ground truth") positions at query times.

- Drives with a truth stream: the truth interpolated at the query time with a
  cubic spline (truth is 10-100 Hz); NaN outside the truth's span or inside gaps
  longer than ``max_gap_s`` (:data:`~posbench.scenarios.truth_gaps.TRUTH_MAX_GAP_S`, 0.5 s:
  why in :mod:`posbench.scenarios.truth_gaps`). A truth of more than
  :data:`SPLINE_MAX_SAMPLES` samples (hours at 100-200 Hz) is splined in blocks of
  :data:`SPLINE_BLOCK` samples, each with :data:`SPLINE_OVERLAP` samples more on either
  side, instead of at once (whose coefficients alone take 64 bytes a sample: 714 MB at the
  peak for an 8 h truth of 5.8 M samples): a not-a-knot end condition's influence shrinks
  by 2 - sqrt(3) ~ 0.27 per sample, so 64 samples on from a block's edge the blocks give
  the whole spline's values (tested to 1e-9 m).
- Drives without truth (the paper's routes): the paper's convention, a cubic
  fitted through the surrounding real fixes (``n_side`` before and after the query,
  past and future); NaN where there are fewer than 2 fixes within ``max_gap_s``
  on either side. Solved in blocks of :data:`CUBIC_BLOCK` queries: memory is bounded
  whatever the number of queries (which grows with the drive's span).
"""

from __future__ import annotations

import numpy as np

from posbench.scenarios.drive import Drive
from posbench.scenarios.truth_gaps import TRUTH_MAX_GAP_S
from posbench.scoring.reference import FIX_CUBIC, TRUTH, truth_name

__all__ = ["FIX_CUBIC", "TRUTH", "cubic_through_fixes", "reference_at", "truth_at", "truth_source"]


def truth_source(drive: Drive) -> str:
    """What ``drive``'s truth is, in words (``DriveRun.truth_source``), e.g. ``the OXTS
    RT3003 INS/GNSS solution``; "" for a drive without one (scored against its fixes)."""
    if drive.truth is None:
        return ""
    topic = ((drive.meta.extra.get("topics") or {}).get("truth") or {}).get("topic")
    return truth_name(drive.meta.format, str(topic) if topic else None)


def reference_at(drive: Drive, tq: np.ndarray) -> np.ndarray:
    """(N, 2) reference positions [m] of ``drive`` at times ``tq`` [s]: its truth
    (:func:`truth_at`) or, without one, the cubic through its fixes
    (:func:`cubic_through_fixes`); NaN where neither covers a time."""
    if drive.truth is not None:
        tr = drive.truth
        return truth_at(tr.t, tr.x, tr.y, tq)
    g = drive.gps
    return cubic_through_fixes(g.t, g.x, g.y, tq)


#: truths up to this many samples are splined at once (every shared and synthetic drive)
SPLINE_MAX_SAMPLES = 1 << 20
#: samples per block of a longer truth, and the samples added on either side of a block
SPLINE_BLOCK = 1 << 17
SPLINE_OVERLAP = 64


def truth_at(
    t_truth: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    tq: np.ndarray,
    max_gap_s: float = TRUTH_MAX_GAP_S,
    max_samples: int = SPLINE_MAX_SAMPLES,
    block: int = SPLINE_BLOCK,
) -> np.ndarray:
    """(N, 2) truth positions [m] at times tq [s] by cubic spline; NaN where not covered.
    A truth of more than ``max_samples`` samples is splined ``block`` samples at a time
    (module doc)."""
    tq = np.asarray(tq, dtype=float)
    out = np.full((tq.size, 2), np.nan)
    if t_truth.size < 4:
        return out
    if t_truth.size <= max_samples:
        val = _spline_at(t_truth, x, y, tq)
    else:
        val = _spline_in_blocks(t_truth, x, y, tq, block)
    i = np.clip(np.searchsorted(t_truth, tq), 1, t_truth.size - 1)
    gap = t_truth[i] - t_truth[i - 1]
    ok = (tq >= t_truth[0]) & (tq <= t_truth[-1]) & (gap <= max_gap_s)
    out[ok] = val[ok]
    return out


def _spline_at(t: np.ndarray, x: np.ndarray, y: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """(N, 2): the not-a-knot cubic spline through (t, x, y) at tq (NaN outside t)."""
    from scipy.interpolate import CubicSpline

    val: np.ndarray = CubicSpline(t, np.column_stack([x, y]), extrapolate=False)(tq)
    return val


def _spline_in_blocks(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, tq: np.ndarray, block: int
) -> np.ndarray:
    """:func:`_spline_at` of a long truth, ``block`` samples' intervals at a time: each
    block's queries from a spline through the block and :data:`SPLINE_OVERLAP` samples
    either side of it (NaN for queries outside t)."""
    val = np.full((tq.size, 2), np.nan)
    inside = np.flatnonzero((tq >= t[0]) & (tq <= t[-1]))
    # the interval [t[k], t[k + 1]] each query falls in decides its block
    k = np.clip(np.searchsorted(t, tq[inside], side="right") - 1, 0, t.size - 2)
    owner = k // block
    for b in np.unique(owner).tolist():
        lo = max(b * block - SPLINE_OVERLAP, 0)
        hi = min((b + 1) * block + 1 + SPLINE_OVERLAP, t.size)
        rows = inside[owner == b]
        val[rows] = _spline_at(t[lo:hi], x[lo:hi], y[lo:hi], tq[rows])
    return val


#: queries [-] :func:`cubic_through_fixes` solves at once: its batched arrays take about 1 kB
#: a query (``n_side`` = 4), so a block of 2^16 takes ~70 MB however many queries there are
CUBIC_BLOCK = 1 << 16


def cubic_through_fixes(
    t_fix: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    tq: np.ndarray,
    n_side: int = 4,
    max_gap_s: float = 1.0,
) -> np.ndarray:
    """(N, 2) positions [m] at tq from a least-squares cubic through the ``n_side`` fixes
    before and ``n_side`` after each query time (vectorised: batched normal equations
    on times centred at the query and scaled to seconds), in blocks of
    :data:`CUBIC_BLOCK` queries so that memory does not grow with N."""
    tq = np.asarray(tq, dtype=float)
    out = np.full((tq.size, 2), np.nan)
    if t_fix.size < 2 * n_side:
        return out
    for start in range(0, tq.size, CUBIC_BLOCK):
        block = slice(start, start + CUBIC_BLOCK)
        out[block] = _cubic_block(t_fix, x, y, tq[block], n_side, max_gap_s)
    return out


def _cubic_block(
    t_fix: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    tq: np.ndarray,
    n_side: int,
    max_gap_s: float,
) -> np.ndarray:
    """:func:`cubic_through_fixes` of one block of queries (at least 2 ``n_side`` fixes)."""
    n = t_fix.size
    out = np.full((tq.size, 2), np.nan)
    right = np.searchsorted(t_fix, tq, side="right")  # first fix strictly after tq
    start = np.clip(right - n_side, 0, n - 2 * n_side)
    idx = start[:, None] + np.arange(2 * n_side)[None, :]
    tw = t_fix[idx] - tq[:, None]  # [s], query at 0
    before = (tw <= 0).sum(axis=1)
    after = (tw > 0).sum(axis=1)
    near_b = np.where(tw <= 0, -tw, np.inf).min(axis=1)
    near_a = np.where(tw > 0, tw, np.inf).min(axis=1)
    # exact hit on a fix: fine with one side short as long as the other side has support
    ok = (before >= 2) & (after >= 2) & (near_b <= max_gap_s) & (near_a <= max_gap_s)
    V = tw[..., None] ** np.arange(4)  # (N, m, 4)
    A = np.einsum("nmi,nmj->nij", V, V)
    b = np.einsum("nmi,nmk->nik", V, np.stack([x[idx], y[idx]], axis=-1))
    good = np.flatnonzero(ok)
    if good.size:
        coef = np.linalg.solve(A[good], b[good])  # (G, 4, 2)
        out[good] = coef[:, 0, :]  # value at tq (centred time 0)
    return out
