"""Paired differences of two runs on the same drives: pure functions on per-drive arrays.

Two runs (OLD, NEW) scored the same drives; a statistic of each run pooled over those drives
(mean, RMSE, max, a quantile of the errors [m]) is recomputed under the same cluster-bootstrap
resamples of the drives (rows of ``weights``: each drive's multiplicity,
:func:`posbench.metrics.cluster_bootstrap.resample_counts`), so drive-to-drive variation both runs
share cancels in NEW - OLD. The percentile interval of the resampled differences is the
paired CI (:func:`paired_interval`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from posbench.metrics.cluster_bootstrap import LEVEL, percentile_interval, resampled_means
from posbench.metrics.resampled_quantiles import resampled_quantiles

#: statistics pooled from per-drive summaries alone (count, mean / RMSE); the others need
#: every error (quantiles) or the per-drive maxima
SUMMARY_STATS = ("mean_m", "rmse_m")
#: the quantile behind each quantile statistic
QUANTILE_STATS = {"median_m": 0.5, "p95_m": 0.95}


def pooled_mean_by_resample(
    counts: np.ndarray, means: np.ndarray, weights: np.ndarray
) -> tuple[float, np.ndarray]:
    """The mean error [m] pooled over drives from their query counts and means, and its
    value under each resample."""
    n = np.asarray(counts, dtype=float)
    x = np.asarray(means, dtype=float) * n
    return float(x.sum() / n.sum()), resampled_means(x, n, weights)


def pooled_rmse_by_resample(
    counts: np.ndarray, rmses: np.ndarray, weights: np.ndarray
) -> tuple[float, np.ndarray]:
    """The RMSE [m] pooled over drives from their query counts and RMSEs, and its value under
    each resample."""
    n = np.asarray(counts, dtype=float)
    x = np.asarray(rmses, dtype=float) ** 2 * n
    return float(np.sqrt(x.sum() / n.sum())), np.sqrt(resampled_means(x, n, weights))


def pooled_max_by_resample(maxes: np.ndarray, weights: np.ndarray) -> tuple[float, np.ndarray]:
    """The largest error [m] over drives from their maxima, and under each resample (the
    largest of the drives it picked)."""
    m = np.asarray(maxes, dtype=float)
    return float(m.max()), np.where(weights > 0, m, -np.inf).max(axis=1)


def pooled_quantile_by_resample(
    errors: Sequence[np.ndarray], q: float, weights: np.ndarray
) -> tuple[float, np.ndarray]:
    """Quantile ``q`` (0..1, linear interpolation) of the pooled errors [m] of drives (one
    array per drive), and its value under each resample; exact (weights are drive
    multiplicities)."""
    values = np.concatenate(errors)
    units = np.concatenate([np.full(len(e), i, dtype=np.int64) for i, e in enumerate(errors)])
    order = np.argsort(values, kind="stable")
    return (
        float(np.quantile(values, q)),
        resampled_quantiles(values[order], units[order], weights, (q,))[:, 0],
    )


def paired_interval(
    old_resampled: np.ndarray, new_resampled: np.ndarray, level: float = LEVEL
) -> tuple[float, float]:
    """The percentile interval of NEW - OLD over the shared resamples."""
    return percentile_interval(np.asarray(new_resampled) - np.asarray(old_resampled), level)
