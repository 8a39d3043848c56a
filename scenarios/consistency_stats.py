"""Statistics of the data consistency check (pure numpy): scale, correlation and lag of a
stream against its reference, and the white scatter of sampled positions."""

from __future__ import annotations

import numpy as np

from posbench.scenarios.consistency_model import FAIL, PASS, WARN


def pairs(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples finite in both ``a`` and ``b``."""
    ok = np.isfinite(a) & np.isfinite(b)
    return a[ok], b[ok]


def slope_corr(ref: np.ndarray, val: np.ndarray) -> tuple[float, float, float]:
    """Scale of ``val`` against ``ref``, their correlation and the offset ``val - scale *
    ref`` at the mean, over samples finite in both.

    The scale is the geometric-mean (reduced major axis) least-squares slope
    sign(r) sd(val) / sd(ref): both sides are noisy (a position-derived rate is the
    noisier), and the ordinary slope of val on ref would read low by r^2 (0.7 at r = 0.84)
    with a perfect sensor. It lies between the slopes of val on ref and of ref on val."""
    r, v = pairs(ref, val)
    if r.size < 3:
        return float("nan"), float("nan"), float("nan")
    rc, vc = r - r.mean(), v - v.mean()
    sxx, syy, sxy = float(rc @ rc), float(vc @ vc), float(rc @ vc)
    if sxx <= 0 or syy <= 0:
        return float("nan"), float("nan"), float("nan")
    corr = sxy / np.sqrt(sxx * syy)
    slope = float(np.sign(corr) * np.sqrt(syy / sxx))
    return slope, corr, float(v.mean() - slope * r.mean())


def best_lag(ref: np.ndarray, val: np.ndarray, dt: float, max_lag_s: float) -> tuple[float, float]:
    """Lag [s] of ``val`` behind ``ref`` by normalised cross-correlation within
    +-``max_lag_s`` (parabolic refinement of the peak), and the peak correlation."""
    n = int(round(max_lag_s / dt))
    lags = np.arange(-n, n + 1)
    cc = np.full(lags.size, np.nan)
    for i, k in enumerate(lags):
        a = ref[: ref.size - k] if k >= 0 else ref[-k:]
        b = val[k:] if k >= 0 else val[: val.size + k]
        cc[i] = slope_corr(a, b)[1]
    if not np.any(np.isfinite(cc)):
        return float("nan"), float("nan")
    j = int(np.nanargmax(cc))
    frac = 0.0
    if 0 < j < lags.size - 1 and np.all(np.isfinite(cc[j - 1 : j + 2])):
        den = cc[j - 1] - 2 * cc[j] + cc[j + 1]
        if den < 0:
            frac = 0.5 * (cc[j - 1] - cc[j + 1]) / den
    return float((lags[j] + frac) * dt), float(cc[j])


def scale_verdict(scale: float, warn: float, fail: float) -> str:
    """``fail`` / ``warn`` / ``pass`` for |log(scale)| above log(1 + fail) / log(1 + warn)."""
    e = abs(np.log(scale)) if scale > 0 else np.inf
    return FAIL if e > np.log1p(fail) else WARN if e > np.log1p(warn) else PASS


def scatter_1d(t: np.ndarray, v: np.ndarray) -> float:
    """White scatter of one sampled signal ``v`` (times ``t`` [s]): each inner sample minus
    the time-weighted line through its two neighbours, scaled to one sample's noise (the
    residual's variance is (1 + w^2 + (1 - w)^2) sigma^2); robust (MAD). NaN for fewer
    than 3 samples."""
    ok = np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size < 3:
        return float("nan")
    d1, d2 = t[1:-1] - t[:-2], t[2:] - t[1:-1]
    w = d2 / (d1 + d2)
    e = (v[1:-1] - (w * v[:-2] + (1 - w) * v[2:])) / np.sqrt(1 + w**2 + (1 - w) ** 2)
    return float(1.4826 * np.median(np.abs(e - np.median(e))))


def fix_scatter(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    """Horizontal white scatter [m] of fixes (:func:`scatter_1d` of x and of y, combined as
    hypot: sqrt(2) x a per-axis noise). Motion over 0.1-0.5 s adds at most a*dt^2/8
    (~ 1 cm). Slow, correlated GPS errors are not seen."""
    if t.size < 3:
        return float("nan")
    return float(np.hypot(scatter_1d(t, x), scatter_1d(t, y)))
