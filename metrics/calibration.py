"""Is a predictor's reported uncertainty honest? Calibration of 2-D position covariances.

A predictor answers a position p and a covariance P (2x2, ENU, m^2). With the error
e = p - truth [m], the squared Mahalanobis distance d^2 = e' P^-1 e is chi-square with 2
degrees of freedom when P is the error's true covariance (Gaussian errors). So:

- **NEES** (normalised estimation error squared) = mean d^2, expected 2; above: the
  predictor is *overconfident* (its ellipses are too small), below: *underconfident*.
  For n independent queries, n * NEES ~ chi-square(2n), which gives the 95 % interval of
  a calibrated predictor's mean NEES (:func:`nees_interval`). Queries of one drive are
  correlated, so that interval is narrow: the cluster-bootstrap CI (resampling drives,
  :mod:`posbench.metrics.bootstrap`) says how well the mean NEES itself is known.
- **Coverage** of the p-ellipse {e : d^2 <= r^2}, r^2 = -2 ln(1 - p) (the chi-square 2 DoF
  quantile): the share of queries whose truth falls inside; calibrated = p. The
  **calibration curve** is observed vs expected coverage over a grid of p.
- **Sharpness**: the median area of the 95 % ellipse, pi r95^2 sqrt(det P) [m^2] (smaller
  is sharper; only meaningful next to a good coverage).
- **Log-likelihood** of the truth under N(p, P): -ln(2 pi) - ln(det P)/2 - d^2/2 per
  query, averaged [nats]; rewards sharp *and* honest covariances.

Verdict (:func:`verdict`): ``calibrated`` when the 95 % coverage lies within the band
0.95 +- max(0.02, 1.96 sqrt(0.95 0.05 / n)) and the mean NEES is consistent with 2: inside
its chi-square 95 % interval for the query count, or (queries of a drive being correlated,
which that interval ignores) its cluster-bootstrap 95 % CI holds 2. Otherwise
``overconfident`` when the coverage is below the band (or, coverage in the band, the NEES
above), ``underconfident`` in the mirrored case. A correct Kalman filter on data drawn
from its own model gives NEES 1.95-2.02 over 11 200 correlated queries (bootstrap CIs all
holding 2) while the chi-square interval for that count is 1.96-2.04: the bootstrap clause
keeps such a filter "calibrated".

Inputs: errors (N, 2) [m] and covariances as (N, 3) columns (xx, xy, yy) [m^2]; rows with
a non-finite error or a covariance that is not finite and positive definite are left
out. Pure numpy (scipy.special for the chi-square quantiles).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: the ellipses whose coverage is reported (probability mass)
COVERAGE_LEVELS = (0.5, 0.9, 0.95, 0.99)
#: the calibration curve's expected coverages
CURVE_LEVELS = tuple(round(p, 2) for p in np.arange(0.05, 1.0, 0.05)) + (0.99,)
#: time since the last fix, bin edges [s] (outages are where calibration matters most)
SINCE_FIX_EDGES_S = (0.0, 0.25, 0.5, 1.0, 2.0, math.inf)
#: verdicts
CALIBRATED, OVERCONFIDENT, UNDERCONFIDENT = "calibrated", "overconfident", "underconfident"

#: what each figure means (the report's glossary collects these)
DEFINITIONS = {
    "NEES": "mean normalised estimation error squared, mean of e' P^-1 e over the queries "
    "(e: answer - reference [m], P: the reported 2x2 covariance [m^2]); 2 when the "
    "covariance is honest, above 2: overconfident, below: underconfident.",
    "coverage": "share of queries whose reference lies inside the reported p-ellipse "
    "(e' P^-1 e <= -2 ln(1 - p)); p when calibrated.",
    "sharpness": "median area of the reported 95 % ellipse, pi (-2 ln 0.05) sqrt(det P) [m^2].",
    "log-likelihood": "mean log density of the reference under N(answer, P) [nats]; higher is "
    "better (sharp and honest).",
}


def ellipse_r2(p: float | np.ndarray) -> float | np.ndarray:
    """Squared Mahalanobis radius of the 2-D ellipse holding probability p: -2 ln(1 - p)."""
    return -2.0 * np.log1p(-np.asarray(p, dtype=float)) if np.ndim(p) else -2.0 * math.log1p(-p)


def mahalanobis_sq(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """d^2 = e' P^-1 e per row: ``err`` (N, 2) [m], ``cov`` (N, 3) = (xx, xy, yy) [m^2].
    NaN where the error is not finite or P is not finite and positive definite."""
    e = np.asarray(err, dtype=float).reshape(-1, 2)
    c = np.asarray(cov, dtype=float).reshape(-1, 3)
    xx, xy, yy = c[:, 0], c[:, 1], c[:, 2]
    det = xx * yy - xy * xy
    ok = np.isfinite(det) & (det > 0) & (xx > 0) & np.isfinite(e).all(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        d2 = (yy * e[:, 0] ** 2 - 2.0 * xy * e[:, 0] * e[:, 1] + xx * e[:, 1] ** 2) / det
    return np.where(ok, d2, np.nan)


def log_det(cov: np.ndarray) -> np.ndarray:
    """ln det P per row of (N, 3) covariances (NaN where not positive definite)."""
    c = np.asarray(cov, dtype=float).reshape(-1, 3)
    det = c[:, 0] * c[:, 2] - c[:, 1] ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(det > 0, np.log(np.where(det > 0, det, 1.0)), np.nan)


def nees_interval(n: int, level: float = 0.95) -> tuple[float, float]:
    """The central ``level`` interval of the mean of n independent chi-square(2) values
    (n NEES ~ chi-square(2n)): where a calibrated predictor's mean NEES falls."""
    if n < 1:
        return math.nan, math.nan
    # the chi-square(k) quantile is 2 gammaincinv(k / 2, q): what scipy.stats.chi2.ppf
    # computes, to the bit, without importing scipy.stats (~1 s)
    from scipy.special import gammaincinv

    a = (1.0 - level) / 2.0
    return (
        float(2.0 * gammaincinv(float(n), a) / n),
        float(2.0 * gammaincinv(float(n), 1.0 - a) / n),
    )


def coverage_counts(
    d2: np.ndarray, levels: Sequence[float] = COVERAGE_LEVELS
) -> tuple[np.ndarray, int]:
    """How many of the finite ``d2`` fall inside each level's ellipse, and how many are
    finite: counts that add over pieces (one drive at a time) to the whole's."""
    d = np.asarray(d2, dtype=float)
    d = d[np.isfinite(d)]
    r2 = np.asarray(ellipse_r2(np.asarray(levels, dtype=float)))  # typed float | array: an array
    # a count per level, not an (N, levels) table: a row's bytes once
    return np.array([np.count_nonzero(d <= r) for r in r2], dtype=np.int64), int(d.size)


def coverage(d2: np.ndarray, levels: Sequence[float] = COVERAGE_LEVELS) -> np.ndarray:
    """Observed share of the finite ``d2`` inside each level's ellipse (NaN with none)."""
    inside, n = coverage_counts(d2, levels)
    if n == 0:
        return np.full(inside.shape, np.nan)
    share: np.ndarray = inside.astype(float) / n
    return share


def calibration_curve(
    d2: np.ndarray, levels: Sequence[float] = CURVE_LEVELS
) -> list[tuple[float, float]]:
    """(expected, observed) coverage pairs over ``levels``: the calibration curve (on the
    diagonal when calibrated; below it: overconfident)."""
    obs = coverage(d2, levels)
    return [(float(p), float(o)) for p, o in zip(levels, obs, strict=True)]


def sharpness_m2(cov: np.ndarray, p: float = 0.95) -> float:
    """Median area [m^2] of the p-ellipses, pi r^2 sqrt(det P) (NaN with none valid)."""
    return sharpness_of(log_det(cov), p)


def sharpness_of(ln_det: np.ndarray, p: float = 0.95) -> float:
    """:func:`sharpness_m2` from each covariance's ln det P (:func:`log_det`)."""
    ld = np.asarray(ln_det, dtype=float)
    ld = ld[np.isfinite(ld)]
    if ld.size == 0:
        return math.nan
    return sharpness_from_median(float(np.median(np.exp(0.5 * ld))), p)


def log_likelihood(d2: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Per-row log density [nats] of the truth under
    N(answer, P): -ln 2pi - ln det P / 2 - d^2 / 2."""
    return log_likelihood_of(d2, log_det(cov))


def log_likelihood_of(d2: np.ndarray, ln_det: np.ndarray) -> np.ndarray:
    """:func:`log_likelihood` from d^2 and ln det P (:func:`log_det`) per row."""
    ld = np.asarray(ln_det, dtype=float)
    return -math.log(2.0 * math.pi) - 0.5 * ld - 0.5 * np.asarray(d2, dtype=float)


def coverage_scale(d2: np.ndarray, p: float = 0.95) -> float:
    """The factor k by which to multiply the reported covariances so that a fraction p of
    the queries fall inside their p-ellipse: scaling P by k divides every squared
    Mahalanobis distance d2 by k, so k = (p-quantile of d2) / r2(p). k > 1: the predictor was
    overconfident, k < 1: underconfident. NaN without a finite d2."""
    d = np.asarray(d2, dtype=float)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return math.nan
    return float(np.quantile(d, p) / ellipse_r2(p))


def coverage_band(n: int, p: float = 0.95) -> tuple[float, float]:
    """Where a calibrated predictor's observed p-coverage falls for n queries:
    p +- max(0.02, 1.96 sqrt(p (1 - p) / n))."""
    if n < 1:
        return math.nan, math.nan
    h = max(0.02, 1.96 * math.sqrt(p * (1.0 - p) / n))
    return p - h, min(1.0, p + h)


def verdict(
    nees: float, cov95: float, n: int, nees_ci: Sequence[float] | None = None
) -> str | None:
    """``calibrated`` / ``overconfident`` / ``underconfident`` from the mean NEES, the
    observed 95 % coverage, the query count n and optionally the NEES's bootstrap CI
    (see the module doc); None with n = 0."""
    if n < 1 or not (math.isfinite(nees) and math.isfinite(cov95)):
        return None
    lo, hi = nees_interval(n)
    c_lo, c_hi = coverage_band(n)
    if cov95 < c_lo:
        return OVERCONFIDENT
    if cov95 > c_hi:
        return UNDERCONFIDENT
    if nees_ci is not None and nees_ci[0] <= 2.0 <= nees_ci[1]:
        return CALIBRATED
    if nees > hi:
        return OVERCONFIDENT
    if nees < lo:
        return UNDERCONFIDENT
    return CALIBRATED


def calibration_summary(
    err: np.ndarray,
    cov: np.ndarray,
    clusters: np.ndarray | None = None,
    times: np.ndarray | None = None,
    with_ci: bool = True,
) -> dict[str, Any]:
    """Every figure of one group of queries.

    Args:
        err: (N, 2) answer - reference [m, ENU]. cov: (N, 3) reported (xx, xy, yy) [m^2].
        clusters: (N,) drive of each query, for the NEES cluster-bootstrap CI (None: one).
        times: (N,) query times [s] (the block bootstrap's order with a single cluster).
        with_ci: compute the bootstrap CI (the costly part).

    Returns:
        ``{"count", "nees", "nees_ci95": [lo, hi] | None, "nees_chi2_95": [lo, hi],
        "coverage": {"50": .., "90": .., "95": .., "99": ..}, "sharpness_m2",
        "loglik", "verdict"}``; count = queries with a valid covariance and error.
    """
    return calibration_of(mahalanobis_sq(err, cov), log_det(cov), clusters, times, with_ci)


def calibration_of(
    d2: np.ndarray,
    ln_det: np.ndarray,
    clusters: np.ndarray | None = None,
    times: np.ndarray | None = None,
    with_ci: bool = True,
) -> dict[str, Any]:
    """:func:`calibration_summary` from each query's d^2 (:func:`mahalanobis_sq`) and ln det
    P (:func:`log_det`): all it needs of the errors and covariances, two numbers a query
    (a caller that reads its queries in parts keeps these, not the (N, 2) and (N, 3)
    arrays). The NEES's interval is the cluster bootstrap's interval of the mean (no
    quantile pass: the mean's interval is all it reports)."""
    d2 = np.asarray(d2, dtype=float)
    ld = np.asarray(ln_det, dtype=float)
    ok = np.isfinite(d2)
    n = int(ok.sum())
    v = d2[ok]
    nees_ci = None
    if with_ci and n:
        from posbench.metrics.bootstrap import summary_ci

        cl = np.zeros(n, dtype=np.int64) if clusters is None else np.asarray(clusters)[ok]
        tt = None if times is None else np.asarray(times, dtype=float)[ok]
        nees_ci = list(summary_ci(v, cl, tt, quantiles=False)["mean_m"])
    return calibration_figures(
        n,
        float(v.mean()) if n else math.nan,
        coverage(v),
        sharpness_of(ld[ok]),
        float(np.mean(log_likelihood_of(v, ld[ok]))) if n else math.nan,
        nees_ci,
    )


def calibration_figures(
    n: int,
    nees: float,
    covered: np.ndarray,
    sharpness_m2: float,
    loglik: float,
    nees_ci: list[float] | None,
) -> dict[str, Any]:
    """:func:`calibration_of`'s figures from their parts: n queries with a finite d^2, the
    mean NEES, the :func:`coverage` at :data:`COVERAGE_LEVELS`, the sharpness [m^2], the
    mean log-likelihood [nats] and the NEES's interval (None: none); for a caller that
    computes the parts from its queries one piece at a time."""
    out: dict[str, Any] = {
        "count": n,
        "nees": nees,
        "nees_ci95": nees_ci,
        "nees_chi2_95": list(nees_interval(n)),
        "coverage": {
            f"{round(p * 100):d}": float(c) for p, c in zip(COVERAGE_LEVELS, covered, strict=True)
        },
        "sharpness_m2": sharpness_m2,
        "loglik": loglik,
    }
    out["verdict"] = verdict(nees, float(covered[COVERAGE_LEVELS.index(0.95)]), n, nees_ci)
    return out


def sharpness_from_median(median_area_factor: float, p: float = 0.95) -> float:
    """:func:`sharpness_of` from the median of sqrt(det P) (NaN: none valid)."""
    return float(math.pi * ellipse_r2(p) * median_area_factor)


def since_fix_bin(
    since_fix_s: np.ndarray, edges: Sequence[float] = SINCE_FIX_EDGES_S
) -> tuple[np.ndarray, list[str]]:
    """Bin index of each time since the last fix [s] (-1: NaN or outside) and the bins'
    names (``"0-0.25s"``, ..., ``">=2s"``)."""
    from posbench.metrics.outages import since_fix_bins

    e = np.asarray(edges, dtype=float)
    idx = since_fix_bins(since_fix_s, e)
    names = [
        f"{a:g}-{b:g}s" if math.isfinite(b) else f">={a:g}s"
        for a, b in zip(e[:-1], e[1:], strict=True)
    ]
    return idx, names
