"""The cluster bootstrap's resamples and the intervals of pooled figures under them.

A resample draws D clusters (e.g. drives) with replacement from D and is stored as a row of
integer multiplicities, one per cluster (:func:`resample_counts`); B resamples are a B x D
matrix. A pooled mean then needs only each cluster's sum and count: B resamples are one
matrix product (:func:`ratio_ci`, :func:`paired_ratio_diff`); a quantile of the pooled values
is computed exactly per resample (:func:`quantile_ci`, through
:mod:`posbench.metrics.resampled_quantiles`). Every interval is the percentile interval of
the B recomputed figures (:func:`percentile_interval`). The same functions take the unit
multiplicities of a block bootstrap (:mod:`posbench.metrics.block_bootstrap`). Seeded and
deterministic; pure numpy. Units: those of the values (errors in metres).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from posbench.metrics.resampled_quantiles import resampled_quantiles

#: resamples per interval (B)
DEFAULT_RESAMPLES = 2000
#: coverage of every interval
LEVEL = 0.95


# ----------------------------------------------------------------- resamples
@lru_cache(maxsize=4)  # B x D each (3 MB at 384 drives): a few, not one per drive count
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
    return cluster_weights(n_clusters, n_resamples, seed).astype(np.int64)


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
            or :attr:`posbench.metrics.block_bootstrap.BlockResample.counts` with the sums
            per block unit).
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
    resamples of ``counts_matrix`` (see
    :func:`posbench.metrics.resampled_quantiles.resampled_quantiles`)."""
    stats = resampled_quantiles(sorted_values, units, counts_matrix, qs)
    return [percentile_interval(stats[:, j], level) for j in range(len(qs))]
