"""Spread of a figure across repeated runs that differ only in their random seeds.

A run with simulated GPS noise and dropouts is one random draw; repeating it over seeds
(``bench run --seeds``) shows how much a figure moves with the draw alone. That spread is a
different thing from the bootstrap interval (:mod:`posbench.metrics.bootstrap`), which measures how
much it would move with other drives; the report gives both side by side.
"""

from __future__ import annotations

import numpy as np

#: what each figure of this module means (the report's glossary collects these)
DEFINITIONS = {
    "across seeds": (
        "the run repeated with other GPS-noise and dropout seeds (same drives, same "
        "predictors): mean, sd (sample standard deviation, n - 1), min and max of the figure "
        "over the seeds. It measures the effect of the random draw, not of the choice of "
        "drives (that is the 95 % CI)."
    ),
}


def spread(values: np.ndarray) -> dict[str, float | int]:
    """mean, sd (ddof 1; NaN with one value), min and max of the finite ``values``, and
    their number ``n``; NaN figures without any."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    nan = float("nan")
    if v.size == 0:
        return {"mean": nan, "sd": nan, "min": nan, "max": nan, "n": 0}
    return {
        "mean": float(v.mean()),
        "sd": float(v.std(ddof=1)) if v.size > 1 else nan,
        "min": float(v.min()),
        "max": float(v.max()),
        "n": int(v.size),
    }


def paired_mean_difference(baseline: np.ndarray, other: np.ndarray) -> float:
    """Mean error of ``other`` minus that of ``baseline`` [m] over the queries both answered
    (finite in both; the two arrays are the same queries in the same order); NaN when they
    are not the same queries or none was answered by both."""
    a, b = np.asarray(baseline, dtype=float), np.asarray(other, dtype=float)
    if a.size != b.size:
        return float("nan")
    both = np.isfinite(a) & np.isfinite(b)
    return float(b[both].mean() - a[both].mean()) if both.any() else float("nan")
