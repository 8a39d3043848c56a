"""Bootstrap confidence intervals for pooled error figures, resampling whole drives.

Queries inside one drive are correlated (the same stretch of road, the same filter state a
few milliseconds apart), so resampling single queries would make every interval too narrow.
Every interval here is a **cluster bootstrap**: one resample draws D clusters (drives) with
replacement from the D that contribute to a figure, the figure is recomputed over the pooled
queries of the drawn clusters (a cluster drawn twice counts twice), and the interval is the
percentile interval of the B recomputed figures. A resample is a row of integer
multiplicities, one per cluster (:func:`resample_counts`); so that

- a pooled mean needs only each cluster's error sum and count: B resamples are one B x D
  matrix product (:func:`ratio_ci`, :func:`paired_ratio_diff`);
- a quantile (median, p95) of the pooled errors is computed exactly, as ``np.percentile``
  (linear interpolation) of each resample would give it, from the pooled errors sorted once
  with their cluster index (:func:`resampled_quantiles`).

With one cluster (a single drive), queries are resampled in contiguous blocks instead
(circular block bootstrap, :func:`block_resample`, block length :func:`block_length`): the
blocks keep the correlation that whole drives keep above. Everything is seeded: the same
inputs and seed give the same interval on any machine. Pure numpy (the exact resampled
quantiles are in :mod:`posbench.metrics.resampled_quantiles`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from posbench.metrics.autocovariance import autocovariance as _autocovariance

# resampled_quantiles was defined here before it got its own module: still importable from here
from posbench.metrics.resampled_quantiles import resampled_quantiles as resampled_quantiles
from posbench.metrics.resampled_quantiles import resampled_quantiles_many

#: resamples per interval (B)
DEFAULT_RESAMPLES = 2000
#: coverage of every interval
LEVEL = 0.95
#: at most this many units in a block bootstrap (longer series get longer units)
MAX_UNITS = 1024
#: a resample joins at least this many blocks (a block is at most 1/MIN_BLOCKS of the series)
MIN_BLOCKS = 10
#: the quantiles whose intervals :func:`summary_ci` gives, with their results keys
QUANTILES = {"median_m": 0.5, "p95_m": 0.95}

#: what each figure of this module means (the report's glossary collects these)
DEFINITIONS = {
    "95 % CI": (
        "95 % confidence interval [lo, hi] of the figure beside it: percentile interval of "
        "the figure recomputed on B seeded resamples (B and the seed: the report's header). "
        "Cluster bootstrap: each resample draws, with replacement, as many "
        "drives as contribute to the figure and pools every scored query of the drawn drives "
        "(queries inside a drive are correlated, so they are never resampled one by one)."
    ),
    "block bootstrap": (
        "For a figure from a single drive: the drive's queries (in time order) are resampled "
        "as circular blocks of contiguous queries instead of drives; the block length follows "
        "the automatic rule of Politis & White (2004, corrected 2009) from the errors' "
        "autocorrelation (longer the longer errors stay correlated; at least 10 blocks per "
        "resample; for a whole drive, the longest among its predictors, so that they are "
        "resampled alike), is rounded to the block grid, and is given in queries where it is "
        "used."
    ),
    "paired difference": (
        "Δ mean = mean error of the predictor minus mean error of the baseline, over the "
        "queries both answered (negative: the predictor is better); its 95 % CI resamples "
        "drives jointly for both, so their shared difficulty cancels."
    ),
    "wins": (
        "drives (among those with paired queries) on which the predictor's mean error is "
        "below the baseline's; win share = wins / drives."
    ),
    "conclusive": (
        "`*` beside a paired difference: its 95 % CI excludes 0. `?` beside a route-type "
        "cell: not conclusive, its 95 % CI is wider than the value itself."
    ),
}


# ----------------------------------------------------------------- resamples
@lru_cache(maxsize=64)
def _cluster_counts(n_clusters: int, n_resamples: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, n_clusters, size=(n_resamples, n_clusters))
    draws += (np.arange(n_resamples) * n_clusters)[:, None]
    counts = np.bincount(draws.ravel(), minlength=n_resamples * n_clusters)
    out = counts.reshape(n_resamples, n_clusters).astype(np.float32)
    out.flags.writeable = False
    return out


def resample_counts(
    n_clusters: int, n_resamples: int = DEFAULT_RESAMPLES, seed: int = 0
) -> np.ndarray:
    """Multiplicity of each cluster in each cluster-bootstrap resample.

    Row ``b`` is one multinomial draw of ``n_clusters`` clusters with replacement (equal
    probabilities): entries are integers >= 0 summing to ``n_clusters``. Deterministic for
    a seed.

    Returns:
        (n_resamples, n_clusters) int64 array.
    """
    if n_clusters < 1 or n_resamples < 1:
        raise ValueError(
            f"need at least one cluster and one resample, got {n_clusters}, {n_resamples}"
        )
    return _cluster_counts(int(n_clusters), int(n_resamples), int(seed)).astype(np.int64)


def cluster_weights(
    n_clusters: int, n_resamples: int = DEFAULT_RESAMPLES, seed: int = 0
) -> np.ndarray:
    """:func:`resample_counts` as a read-only float32 array (integers, exact), cached: what
    the interval functions multiply with; the same arguments return the same array."""
    if n_clusters < 1 or n_resamples < 1:
        raise ValueError(
            f"need at least one cluster and one resample, got {n_clusters}, {n_resamples}"
        )
    return _cluster_counts(int(n_clusters), int(n_resamples), int(seed))


def percentile_interval(stats: np.ndarray, level: float = LEVEL) -> tuple[float, float]:
    """The percentile interval: the (1 -/+ level) / 2 quantiles of the finite ``stats``
    (linear interpolation, as ``np.quantile``, without its overhead)."""
    s = np.sort(stats[np.isfinite(stats)])
    if s.size == 0:
        return float("nan"), float("nan")
    out = []
    for p in ((1.0 - level) / 2.0, (1.0 + level) / 2.0):
        h = (s.size - 1) * p
        i = min(int(h), s.size - 1)
        j = min(i + 1, s.size - 1)
        out.append(float(s[i] + (h - i) * (s[j] - s[i])))
    return out[0], out[1]


# --------------------------------------------------------------------- means
def resampled_means(sums: np.ndarray, counts: np.ndarray, counts_matrix: np.ndarray) -> np.ndarray:
    """Pooled mean sum(w * sums) / sum(w * counts) for each row w of ``counts_matrix``
    (NaN where a resample holds no query). ``sums``, ``counts``: per cluster. A float32
    ``counts_matrix`` (the cached ones) is multiplied in float32 (relative precision ~1e-7,
    far below any interval's width); any other in float64."""
    w = np.asarray(counts_matrix)
    ftype = np.float32 if w.dtype == np.float32 else np.float64
    w = w.astype(ftype, copy=False)
    num = (w @ np.asarray(sums, dtype=ftype)).astype(np.float64)
    den = (w @ np.asarray(counts, dtype=ftype)).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def ratio_ci(
    sums: np.ndarray, counts: np.ndarray, counts_matrix: np.ndarray, level: float = LEVEL
) -> tuple[float, float]:
    """Percentile interval of the pooled mean under the resamples of ``counts_matrix``.

    Args:
        sums: per cluster, the sum of its values (e.g. errors [m]); counts: per cluster,
            how many values; counts_matrix: (B, D) multiplicities (:func:`resample_counts`,
            or :attr:`BlockResample.counts` with the sums per block unit).
        level: coverage (0.95).

    Returns:
        (lo, hi) in the values' unit; NaN when no resample holds a value.
    """
    return percentile_interval(resampled_means(sums, counts, counts_matrix), level)


def paired_ratio_diff(
    sum_a: np.ndarray,
    count_a: np.ndarray,
    sum_b: np.ndarray,
    count_b: np.ndarray,
    counts_matrix: np.ndarray,
    level: float = LEVEL,
) -> dict[str, float]:
    """Difference of two pooled means over the same clusters, with its interval.

    Sign convention (kept everywhere): ``diff = mean_b - mean_a``, where mean_x =
    sum(sum_x) / sum(count_x). With errors, a the baseline and b a predictor, a negative
    difference means b is better. Both means are recomputed on the **same** resample (the
    same row of ``counts_matrix``), so what the two share (hard drives) cancels.

    Args:
        sum_a, count_a, sum_b, count_b: per cluster, sums and counts of each side (e.g.
            ``mean_m * count`` of per-drive summaries); counts_matrix: (B, D).

    Returns:
        ``{"diff": ..., "lo": ..., "hi": ...}`` (NaN without values).
    """
    ca, cb = float(np.sum(count_a)), float(np.sum(count_b))
    diff = (
        (float(np.sum(sum_b)) / cb - float(np.sum(sum_a)) / ca)
        if ca > 0 and cb > 0
        else float("nan")
    )
    d = resampled_means(sum_b, count_b, counts_matrix) - resampled_means(
        sum_a, count_a, counts_matrix
    )
    lo, hi = percentile_interval(d, level)
    return {"diff": diff, "lo": lo, "hi": hi}


# ----------------------------------------------------------------- quantiles
def quantile_ci(
    sorted_values: np.ndarray,
    units: np.ndarray,
    counts_matrix: np.ndarray,
    qs: tuple[float, ...] = (0.5, 0.95),
    level: float = LEVEL,
) -> list[tuple[float, float]]:
    """Percentile interval of each quantile in ``qs`` of the pooled values under the
    resamples of ``counts_matrix`` (see :func:`resampled_quantiles`)."""
    stats = resampled_quantiles(sorted_values, units, counts_matrix, qs)
    return [percentile_interval(stats[:, j], level) for j in range(len(qs))]


# ----------------------------------------------------------- block bootstrap
def block_length(x: np.ndarray) -> int:
    """Block length [samples] for the circular block bootstrap of a series in time order.

    The automatic rule of Politis & White (2004) with the correction of Patton, Politis &
    White (2009): b = (2 G^2 / D)^(1/3) n^(1/3), D = 4/3 g(0)^2, with g(0) (the long-run
    variance) and G = sum |k| gamma(k) estimated from the sample autocovariances gamma(k)
    under a flat-top window of 2m lags, m the first lag after which Kn = max(5,
    log10 n) autocorrelations in a row are insignificant (|rho| < 2 sqrt(log10 n / n)).
    It grows with how long the series remembers itself (about 75 samples for an AR(1) of
    coefficient 0.9 and n = 3000; 1-3 for independent samples). Rounded, at least 1, at
    most min(3 sqrt(n), n / :data:`MIN_BLOCKS`) so that a resample joins at least
    :data:`MIN_BLOCKS` blocks.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    cap = max(1, min(math.ceil(3.0 * math.sqrt(n)), n // MIN_BLOCKS))
    if n < 3:
        return 1
    kn = max(5, int(math.log10(n)))
    m_max = min(n - 1, math.ceil(math.sqrt(n)) + kn)
    acv = _autocovariance(x, m_max)
    if not acv[0] > 0:
        return 1  # a constant series: nothing to keep together
    small = np.abs(acv[1:] / acv[0]) < 2.0 * math.sqrt(math.log10(n) / n)  # lags 1 .. m_max
    runs = np.convolve(small.astype(np.int64), np.ones(kn, dtype=np.int64), "valid")
    first = np.flatnonzero(runs == kn)
    m = min(2 * max(int(first[0]), 1), m_max) if first.size else m_max
    k = np.arange(1, m + 1)
    t = k / m
    lam = np.where(t <= 0.5, 1.0, 2.0 * (1.0 - t))
    g0 = acv[0] + 2.0 * float(np.sum(lam * acv[1 : m + 1]))
    g = 2.0 * float(np.sum(lam * k * acv[1 : m + 1]))
    if not g0 > 0 or g == 0:
        return 1
    b = (2.0 * g * g / (4.0 / 3.0 * g0 * g0)) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    return int(max(1, min(round(b), cap)))


@dataclass(frozen=True)
class BlockResample:
    """A circular block bootstrap of one series of n samples, expressed as a cluster
    bootstrap over units of contiguous samples.

    Attributes:
        units: (n,) unit index of each sample (sample i is in unit i // unit_len).
        counts: (B, U) float64 multiplicity of each unit in each resample.
        block_len: samples per resampled block (a multiple of ``unit_len``).
        unit_len: samples per unit.
    """

    units: np.ndarray
    counts: np.ndarray
    block_len: int
    unit_len: int


@lru_cache(maxsize=16)
def _block_counts(n_units: int, per_block: int, n_resamples: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n_blocks = -(-n_units // per_block)
    starts = rng.integers(0, n_units, size=(n_resamples, n_blocks))
    starts += (np.arange(n_resamples) * n_units)[:, None]
    c = np.bincount(starts.ravel(), minlength=n_resamples * n_units).reshape(n_resamples, n_units)
    # a block starting at unit s covers s .. s+per_block-1 (circularly): the weight of
    # unit u is the number of starts in u-per_block+1 .. u, a circular moving sum
    m = min(per_block, n_units)
    if m <= 4:  # a few shifted additions along the flat array, wrapped rows corrected
        w = c.astype(np.float32)
        flat_w, flat_c = w.ravel(), c.ravel()
        for j in range(1, m):
            flat_w[j:] += flat_c[:-j]
            w[1:, :j] -= c[:-1, n_units - j :]
            w[:, :j] += c[:, n_units - j :]
    else:  # a cumulative sum over the row with its last m-1 units in front
        ext = np.zeros((n_resamples, n_units + m), dtype=np.int32)
        ext[:, 1:m] = c[:, n_units - m + 1 :]
        ext[:, m:] = c
        np.cumsum(ext, axis=1, out=ext)
        w = (ext[:, m:] - ext[:, :n_units]).astype(np.float32)
    w.flags.writeable = False
    return w


#: a block spans about this many units (block starts lie on a grid of one unit)
UNITS_PER_BLOCK = 4


def unit_length(n: int, block_len: int = 1) -> int:
    """Samples per unit in :func:`block_resample` of a series of ``n`` in blocks of
    ``block_len``: a quarter block (:data:`UNITS_PER_BLOCK`), but at least half of n^(1/3)
    (finer grids cost time and change little) and long enough for at most
    :data:`MAX_UNITS` units."""
    return int(
        max(1, round(n ** (1.0 / 3.0) / 2.0), -(-block_len // UNITS_PER_BLOCK), -(-n // MAX_UNITS))
    )


def block_resample(
    n: int, block_len: int, n_resamples: int = DEFAULT_RESAMPLES, seed: int = 0
) -> BlockResample:
    """Circular block bootstrap of a series of ``n`` samples in time order.

    The series is cut into units of :func:`unit_length` contiguous samples; a block is
    ``per_block`` = round(block_len / unit_len) consecutive units (at least one; wrapping
    around the end), its start drawn uniformly among the units; each resample joins
    ceil(U / per_block) blocks, about n samples. Block starts are thus on a grid of one
    unit (a circular block bootstrap whose starts are every unit_len-th sample). The
    multiplicities per unit plug into :func:`ratio_ci` and :func:`resampled_quantiles` as
    clusters do. The block length actually used (per_block * unit_len) is returned.
    """
    if n < 1 or block_len < 1:
        raise ValueError(f"need n >= 1 and block_len >= 1, got {n}, {block_len}")
    unit_len = unit_length(n, block_len)
    n_units = -(-n // unit_len)
    per_block = min(n_units, max(1, round(min(block_len, n) / unit_len)))
    counts = _block_counts(n_units, per_block, int(n_resamples), int(seed))
    return BlockResample(np.arange(n) // unit_len, counts, per_block * unit_len, unit_len)


# ------------------------------------------------------------------ summaries
def _compact(clusters: np.ndarray) -> tuple[np.ndarray, int]:
    """Cluster labels as 0 .. D-1 (order of first sorted label) and D."""
    c = np.asarray(clusters)
    if c.dtype.kind in "iu" and (c.size == 0 or c.min() >= 0):
        present = np.bincount(c) > 0 if c.size else np.zeros(0, dtype=bool)
        index = np.cumsum(present) - 1
        return index[c], int(present.sum())
    uniq, inv = np.unique(c, return_inverse=True)
    return inv.ravel(), int(uniq.size)


def _time_order(values: np.ndarray, times: np.ndarray | None) -> np.ndarray:
    """Indices putting one cluster's values in time order (as given without times)."""
    if times is None:
        return np.arange(values.shape[-1])
    t = np.asarray(times, dtype=np.float64)
    if t.size < 2 or bool(np.all(t[1:] >= t[:-1])):
        return np.arange(t.size)
    return np.argsort(t, kind="stable")


def summary_ci(
    errors: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
    quantiles: bool = True,
) -> dict[str, Any]:
    """Intervals of the mean, median and p95 of the finite ``errors`` (what
    :func:`posbench.metrics.accuracy.summarize` reports), resampling ``clusters`` (e.g. the drive of
    each query); with a single cluster, a block bootstrap over the queries in time order
    (``times`` [s]; default: the order given).

    Returns:
        ``{"mean_m": [lo, hi], "median_m": [lo, hi], "p95_m": [lo, hi], "clusters": D,
        "block_len": L}``: ``block_len`` is the block length [queries] when one cluster was
        block-resampled, else None; with no finite error every interval is NaN and D = 0.
        ``quantiles`` False: the mean's interval only (median and p95 NaN, no quantile
        pass paid).
    """
    return interval_batch([(errors, clusters, times)], False, n_resamples, seed, level, quantiles)[
        0
    ]


def summary_cis(
    errors: Sequence[np.ndarray],
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> list[dict[str, Any]]:
    """:func:`summary_ci` of several error arrays over the same queries (``clusters`` and
    ``times`` shared; e.g. each predictor's errors on one drive), in one pass per set of
    resamples. With a single cluster, the series with the same number of finite errors are
    resampled alike: in blocks of the longest of their :func:`block_length` (so one
    series alone gets exactly what :func:`summary_ci` gives it)."""
    return interval_batch([(e, clusters, times) for e in errors], True, n_resamples, seed, level)


def group_cis(
    errors: np.ndarray,
    keys: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> dict[object, dict[str, Any]]:
    """:func:`summary_ci` of the errors of each distinct key (e.g. scenario label, speed
    bin, query kind): key -> intervals, exactly what :func:`summary_ci` gives each group."""
    k = np.asarray(keys)
    if k.size == 0:
        return {}
    if k.dtype.kind in "iu" and k.min() >= 0:
        counts = np.bincount(k)
        names: Sequence[object] = np.flatnonzero(counts).tolist()
        code = k
    else:
        uniq, code = np.unique(k, return_inverse=True)
        code = code.ravel()
        names = uniq.tolist()
        counts = np.bincount(code)
    order = np.argsort(code, kind="stable")  # stable: each group keeps its time order
    bounds = np.cumsum(counts)[np.flatnonzero(counts)]
    starts = bounds - counts[np.flatnonzero(counts)]
    e = np.asarray(errors, dtype=np.float64)[order]
    c = np.asarray(clusters)[order]
    t = None if times is None else np.asarray(times, dtype=np.float64)[order]
    items = [
        (e[a:b], c[a:b], None if t is None else t[a:b]) for a, b in zip(starts, bounds, strict=True)
    ]
    return dict(zip(names, interval_batch(items, False, n_resamples, seed, level), strict=True))


def interval_batch(
    items: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray | None]],
    share_blocks: bool,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
    quantiles: bool = True,
) -> list[dict[str, Any]]:
    """:func:`summary_ci` of each (errors, clusters, times) of ``items``; those that end up
    with the same resamples (as many clusters, or one cluster and the same block) share one
    quantile pass. ``share_blocks``: the items are series over the same queries, and the
    single-cluster ones of equal length use the longest of their block lengths.
    ``quantiles`` False: the means' intervals only (no quantile pass)."""
    nan2 = [float("nan"), float("nan")]
    out: list[dict[str, Any]] = []
    prepared: list[tuple[int, np.ndarray, np.ndarray | None, int]] = []
    for i, (err, clusters, times) in enumerate(items):
        e = np.asarray(err, dtype=np.float64)
        ok = np.isfinite(e)
        e = e[ok]
        out.append(
            {
                "mean_m": list(nan2),
                "median_m": list(nan2),
                "p95_m": list(nan2),
                "clusters": 0,
                "block_len": None,
            }
        )
        if e.size == 0:
            continue
        c, d = _compact(np.asarray(clusters)[ok])
        if d == 1:
            e = e[_time_order(e, None if times is None else np.asarray(times)[ok])]
            prepared.append((i, e, None, block_length(e)))
        else:
            prepared.append((i, e, c, d))
    blocks: dict[int, int] = {}
    if share_blocks:  # one block length per series length among the single-cluster series
        for _, values, codes, block_len in prepared:
            if codes is None:
                blocks[values.size] = max(blocks.get(values.size, 1), block_len)
    shared: dict[tuple[int, int], tuple[np.ndarray, list[tuple[int, np.ndarray, np.ndarray]]]] = {}
    for i, e, codes, d in prepared:
        if codes is None:
            br = block_resample(
                e.size, blocks.get(e.size, d) if share_blocks else d, n_resamples, seed
            )
            units, w, block, n_clusters = br.units, br.counts, br.block_len, 1
        else:
            units, w, block, n_clusters = codes, cluster_weights(d, n_resamples, seed), None, d
        n_units = w.shape[1]
        sums = np.bincount(units, weights=e, minlength=n_units)
        counts = np.bincount(units, minlength=n_units)
        out[i].update(
            mean_m=list(ratio_ci(sums, counts, w, level)), clusters=n_clusters, block_len=block
        )
        if not quantiles:
            continue
        order = np.argsort(e)  # ties hold equal values: any order of them gives the same
        # series over the same queries share a pass when they share their resamples
        key = (id(w), e.size) if share_blocks else (id(w), i)
        shared.setdefault(key, (w, []))[1].append((i, e[order], units[order]))
    for w, members in shared.values():
        stats = resampled_quantiles_many(
            [(v, u) for _, v, u in members], w, tuple(QUANTILES.values())
        )
        for (i, _, _), st in zip(members, stats, strict=True):
            for j, figure in enumerate(QUANTILES):
                out[i][figure] = list(percentile_interval(st[:, j], level))
    return out


def paired_summary(
    errors_a: np.ndarray,
    errors_b: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> dict[str, object]:
    """Paired comparison of two sets of errors on the same queries (a: baseline, b: the
    predictor compared), over the queries both answered (finite in both); ``times`` [s]
    order the queries of a single cluster for its block bootstrap.

    Returns:
        ``diff_m`` (mean b - mean a: negative = b better), ``ci95`` [lo, hi] (cluster
        bootstrap over ``clusters``, or a block bootstrap of the queries in the given order
        when there is one cluster; block length from the per-query differences),
        ``drives`` (clusters with paired queries), ``wins`` (clusters where b's mean error
        is below a's), ``win_share``, ``conclusive`` (the interval excludes 0),
        ``queries`` (paired queries) and ``block_len`` (None unless block-resampled).
    """
    a = np.asarray(errors_a, dtype=np.float64)
    b = np.asarray(errors_b, dtype=np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    nan = float("nan")
    if a.size == 0:
        return {
            "diff_m": nan,
            "ci95": [nan, nan],
            "drives": 0,
            "wins": 0,
            "win_share": nan,
            "conclusive": False,
            "queries": 0,
            "block_len": None,
        }
    c, d = _compact(np.asarray(clusters)[ok])
    per_a = np.bincount(c, weights=a, minlength=d)
    per_b = np.bincount(c, weights=b, minlength=d)
    wins = int(np.sum(per_b < per_a))  # same counts on both sides: compare the sums
    block = None
    if d == 1:
        order = _time_order(a, None if times is None else np.asarray(times)[ok])
        a, b = a[order], b[order]
        block = block_length(b - a)
        br = block_resample(a.size, block, n_resamples, seed)
        units, w, block = br.units, br.counts, br.block_len
    else:
        units, w = c, cluster_weights(d, n_resamples, seed)
    n_units = w.shape[1]
    cnt = np.bincount(units, minlength=n_units)
    r = paired_ratio_diff(
        np.bincount(units, weights=a, minlength=n_units),
        cnt,
        np.bincount(units, weights=b, minlength=n_units),
        cnt,
        w,
        level,
    )
    conclusive = bool(r["lo"] > 0 or r["hi"] < 0)
    return {
        "diff_m": r["diff"],
        "ci95": [r["lo"], r["hi"]],
        "drives": d,
        "wins": wins,
        "win_share": wins / d,
        "conclusive": conclusive,
        "queries": int(a.size),
        "block_len": block,
    }
