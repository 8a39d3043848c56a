"""Quantiles of bootstrap resamples, computed exactly and without writing them out.

A resample gives each unit (drive, or block of queries) an integer multiplicity; its
quantile is what ``np.percentile`` (linear interpolation) gives on the values repeated that
often. Writing B resamples of n values out costs B x n; here the pooled values are sorted
once and each resample's quantile is found through a coarse pass (one matrix product over
blocks of sorted positions) and a fine pass inside one block. Used by
:mod:`posbench.metrics.bootstrap`; pure numpy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def _coarse_blocks(n: int, n_units: int) -> int:
    """How many position blocks the coarse pass of :func:`resampled_quantiles` uses: a
    balance between the B x D x K product (cheap per element) and the B x n/K gathers of
    the fine pass; any value gives the same (exact) result."""
    return int(min(n, max(1, round(math.sqrt(COST_RATIO * n / n_units)))))


#: cost of one gathered element in the fine pass over one multiply-add of the coarse product
COST_RATIO = 400.0


def _last_at_most(table: np.ndarray, rank: np.ndarray) -> np.ndarray:
    """Per row of ``table`` (ascending along the row, first column <= rank), the last
    column j with table[row, j] <= rank[row]."""
    n_rows, n_cols = table.shape
    if n_cols <= 64:  # a comparison with every column is cheaper than a search
        counted: np.ndarray = (
            (table[:, 1:] <= rank[:, None]).view(np.int8).sum(axis=1, dtype=np.int64)
        )
        return counted
    flat = table.ravel()  # contiguous: a view
    base = np.arange(n_rows, dtype=np.int64) * n_cols
    lo = np.zeros(n_rows, dtype=np.int64)
    hi = np.full(n_rows, n_cols - 1, dtype=np.int64)
    for _ in range(int(n_cols).bit_length()):  # a vectorised binary search
        mid = (lo + hi + 1) >> 1
        ok = flat[base + mid] <= rank
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid - 1)
    return lo


def resampled_quantiles(
    sorted_values: np.ndarray,
    units: np.ndarray,
    counts_matrix: np.ndarray,
    qs: tuple[float, ...] = (0.5, 0.95),
) -> np.ndarray:
    """Quantiles of every resample, exactly as ``np.percentile`` (linear interpolation)
    would give them on the resample written out (each value repeated as often as its unit
    is drawn).

    Args:
        sorted_values: pooled values, ascending; units: unit (cluster) index of each value,
            0 .. D-1; counts_matrix: (B, D) integer multiplicities (floats allowed);
        qs: quantiles in [0, 1].

    Returns:
        (B, len(qs)) array; NaN rows for resamples that hold no value.

    Method: the sorted positions are cut into K blocks; one product W @ M (M: count of each
    unit's values before each block start) gives, per resample, the weighted count before
    every block, so a search finds the block holding the wanted rank; inside that block a
    cumulative sum of the resample's weights finds the exact position. Cost B x D x K +
    B x n / K instead of B x n. All counts are integers, exact in floating point (float32
    while every count stays below 2**23). :func:`resampled_quantiles_many` does several
    series under the same resamples at once.
    """
    return resampled_quantiles_many([(sorted_values, units)], counts_matrix, qs)[0]


def resampled_quantiles_within(
    sorted_values: np.ndarray,
    units: np.ndarray,
    counts_matrix: np.ndarray,
    qs: tuple[float, ...],
    totals: np.ndarray,
    below: np.ndarray,
) -> np.ndarray:
    """:func:`resampled_quantiles` of values of which only a slice is at hand: the sorted
    values (and units) between two bounds, every order statistic the quantiles read lying
    between them (:mod:`posbench.metrics.two_pass_quantiles`). ``totals``: each resample's
    weighted count of all its values, ``below``: of those below the slice ((B,) each). The
    same figures as :func:`resampled_quantiles` on all the values, to the bit."""
    return resampled_quantiles_many([(sorted_values, units)], counts_matrix, qs, [(totals, below)])[
        0
    ]


def resampled_quantiles_many(
    series: Sequence[tuple[np.ndarray, np.ndarray]],
    counts_matrix: np.ndarray,
    qs: tuple[float, ...] = (0.5, 0.95),
    slices: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
) -> list[np.ndarray]:
    """:func:`resampled_quantiles` of several series (each: sorted values and their units)
    whose units share the resamples ``counts_matrix`` (e.g. each predictor's errors on the
    same queries), in one pass: one matrix product and one search for all of them.
    ``slices``: per series, (totals, below) of :func:`resampled_quantiles_within`."""
    w = np.asarray(counts_matrix)
    n_res, n_units = w.shape
    outs = [np.full((n_res, len(qs)), np.nan) for _ in series]
    live = [i for i, (v, _) in enumerate(series) if np.asarray(v).size]
    if not live:
        return outs
    n_max = max(np.asarray(series[i][0]).size for i in live)
    # a resample holds at most n * n_units values: exact in float32 below 2**23
    ftype = np.float32 if float(n_max) * n_units < 2.0**23 else np.float64
    wf = np.ascontiguousarray(w, dtype=ftype)  # no copy for the cached float32 weights
    k = _coarse_blocks(n_max, n_units)
    length = -(-n_max // k)
    k = -(-n_max // length)
    n_ser = len(live)
    before = np.zeros((n_units, n_ser, k), dtype=ftype)
    sizes = np.zeros((n_units, n_ser), dtype=ftype)
    values = [np.asarray(series[i][0], dtype=np.float64) for i in live]
    units = [np.asarray(series[i][1]) for i in live]
    for j, u in enumerate(units):
        # each unit's count in each block of sorted positions, a block at a time (no
        # temporaries the size of the series)
        hist = np.empty((n_units, k), dtype=np.int64)
        for b in range(k):
            hist[:, b] = np.bincount(u[b * length : (b + 1) * length], minlength=n_units)
        np.cumsum(hist[:, :-1], axis=1, out=before[:, j, 1:])
        sizes[:, j] = hist.sum(axis=1)
        del hist
    # per (series, resample) row: weight before each block start, and the resample's size
    wm = np.ascontiguousarray(
        (wf @ before.reshape(n_units, n_ser * k)).reshape(n_res, n_ser, k).transpose(1, 0, 2)
    ).reshape(-1, k)
    total = (wf @ sizes).T.ravel().astype(np.float64)
    n_rows = n_ser * n_res
    rows = np.arange(n_rows)
    series_of = rows // n_res
    flat_w = wf.ravel()
    row_base = ((rows % n_res) * n_units)[:, None]
    offsets = np.arange(length)
    sizes_of = np.array([v.size for v in values])

    def positions(tab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Series of each block-table row ``tab`` and its block's sorted positions, those
        past the series' end on its last value (its weight adds only after the resample's
        last value, so is never counted; and that value is the last)."""
        ser = tab // k
        pos = (tab % k * length)[:, None] + offsets
        return ser, np.minimum(pos, (sizes_of[ser] - 1)[:, None])

    def units_at(tab: np.ndarray) -> np.ndarray:
        ser, pos = positions(tab)
        out = np.empty(pos.shape, dtype=np.int64)
        for j, u in enumerate(units):
            mine = ser == j
            out[mine] = u[pos[mine]]
        return out

    def values_at(tab: np.ndarray, at: np.ndarray) -> np.ndarray:
        ser = tab // k
        pos = np.minimum(tab % k * length + at, sizes_of[ser] - 1)
        out = np.empty(tab.shape)
        for j, v in enumerate(values):
            mine = ser == j
            out[mine] = v[pos[mine]]
        return out

    upper = np.triu(np.ones((length, length), dtype=ftype)) if length <= 64 else None

    def count_le(cum: np.ndarray, limit: np.ndarray) -> np.ndarray:
        counted: np.ndarray = (cum <= limit[:, None]).view(np.int8).sum(axis=1, dtype=np.int64)
        return counted

    def locate(rank: np.ndarray, which: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Row of the block table and cumulative weights of the block holding ``rank``
        (in rows ``which``, default all)."""
        sub = wm if which is None else wm[which]
        blk = _last_at_most(sub, rank)
        tab = blk + (series_of * k if which is None else series_of[which] * k)
        base = row_base if which is None else row_base[which]
        wts = flat_w.take(units_at(tab) + base)
        # a running sum along short rows is faster as a product with a triangle of ones
        cum = wts @ upper if upper is not None else np.cumsum(wts, axis=1)
        cum += sub[np.arange(len(blk)), blk][:, None]
        return tab, cum

    def value_pair(rank: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values at ``rank`` and ``rank + 1`` (0-based) of each sorted resample."""
        tab, cum = locate(rank)
        at = count_le(cum, rank)
        at1 = count_le(cum, rank + 1)
        lo = values_at(tab, np.minimum(at, length - 1))
        hi = values_at(tab, np.minimum(at1, length - 1))
        spill = np.flatnonzero(at1 >= length)  # rank + 1 in a later block: look there
        if spill.size:
            tab2, cum2 = locate(rank[spill] + 1, spill)
            at2 = np.minimum(count_le(cum2, rank[spill] + 1), length - 1)
            hi[spill] = values_at(tab2, at2)
        return lo, hi

    offset = np.zeros(n_rows)
    if slices is not None:  # ranks among all of each resample's values, found in the slice
        total = np.concatenate([np.asarray(slices[i][0], dtype=np.float64) for i in live])
        offset = np.concatenate([np.asarray(slices[i][1], dtype=np.float64) for i in live])
    ok = total > 0
    last = np.where(ok, total - 1.0, 0.0)
    res = np.full((n_rows, len(qs)), np.nan)
    for j, q in enumerate(qs):
        h = last * q
        r = np.floor(h)
        lo, hi = value_pair((r - offset).astype(ftype))
        hi = np.where(r + 1.0 <= last, hi, lo)
        res[:, j] = np.where(ok, lo + (h - r) * (hi - lo), np.nan)
    for j, i in enumerate(live):
        outs[i] = res[j * n_res : (j + 1) * n_res]
    return outs
