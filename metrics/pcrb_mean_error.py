"""The position bound (:mod:`posbench.metrics.pcrb`) as a bound on a predictor's error
against a reference: a receiver's slow error added where it belongs, and the mean Euclidean
error [m] of the resulting zero-mean 2-D Gaussian error.

**Mean error.** A Gaussian model makes the optimal estimator's error zero-mean Gaussian with
covariance ``P`` and independent of the data; any other estimator's error is that plus a
term that is a function of the data, so (Anderson's inequality) its mean Euclidean error is
no smaller: :func:`mean_error_bound` (per-axis variance ``s^2``: ``s sqrt(pi/2)``) and
:func:`mean_error_2d` (any 2x2 covariance: the mean of a Hoyt distribution) bound a
predictor's mean error, not only its mean squared error.

**A receiver's slow error** (``predictors/kalman/gnss_noise.py``: a fix's stated variance is a
white part plus a slow part that wanders over seconds to minutes): the recursion takes the
white part as ``R``; against an independent truth the slow part adds its variance to the
bound (no fix can reveal it), against the receiver's own fixes it adds nothing
(:func:`with_slow_error`).

Variances in m^2 per axis (local ENU), errors in metres. Pure numpy (scipy.special for the
elliptic integral).
"""

from __future__ import annotations

import math

import numpy as np


def with_slow_error(var: np.ndarray, slow_var: float, *, independent_truth: bool) -> np.ndarray:
    """The bound ``var`` [m^2] per axis with a receiver's slow error (variance ``slow_var``
    [m^2] per axis; ``predictors/kalman/gnss_noise.py``: the stated total minus the white part).

    The recursion takes the fixes' white part as their noise ``R``. A slow error shifts every
    fix of a stretch alike, so the fixes cannot tell it from the motion: against an
    **independent truth** (``independent_truth=True``, e.g. a survey-grade INS) it adds its
    whole variance, ``var + slow_var`` (exact for an error that stays constant over the
    stretch and a wide prior on position; a slow error of correlation time far beyond the
    horizon keeps its stationary variance, as in the kf). Against the **receiver's own
    fixes** as the reference (``independent_truth=False``), the reference carries the same
    slow error: nothing is added.
    """
    v = np.asarray(var, dtype=float)
    if not (math.isfinite(slow_var) and slow_var >= 0):
        raise ValueError(f"slow_var: a finite variance >= 0 [m^2], not {slow_var}")
    out: np.ndarray = v + slow_var if independent_truth else v.copy()
    return out


def mean_error_bound(var: np.ndarray | float) -> np.ndarray:
    """Mean Euclidean error [m] of a zero-mean 2-D Gaussian with per-axis variance ``var``
    [m^2], axes independent: ``sqrt(var) sqrt(pi / 2)`` (the Rayleigh mean). NaN stays NaN."""
    v = np.asarray(var, dtype=float)
    out: np.ndarray = np.sqrt(v) * math.sqrt(math.pi / 2.0)
    return out


def mean_error_2d(cov: np.ndarray) -> np.ndarray:
    """Mean Euclidean error [m] of a zero-mean 2-D Gaussian of covariance ``cov`` (N, 3) =
    (xx, xy, yy) [m^2] per row (calibration's layout): the mean of a Hoyt distribution,
    ``sqrt(2 l1 / pi) E(1 - l2 / l1)`` with ``l1 >= l2`` the covariance's eigenvalues and
    ``E(m)`` the complete elliptic integral of the second kind (parameter ``m``); equals
    :func:`mean_error_bound` when ``xx = yy``, ``xy = 0``. NaN where not finite or not
    positive semi-definite."""
    from scipy.special import ellipe

    c = np.asarray(cov, dtype=float).reshape(-1, 3)
    xx, xy, yy = c[:, 0], c[:, 1], c[:, 2]
    half_tr = 0.5 * (xx + yy)
    rad = np.sqrt(0.25 * (xx - yy) ** 2 + xy * xy)
    l1, l2 = half_tr + rad, half_tr - rad
    ok = np.isfinite(l1) & np.isfinite(l2) & (l2 >= -1e-12 * np.abs(l1))
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.where(l1 > 0, 1.0 - np.clip(l2, 0.0, None) / np.where(l1 > 0, l1, 1.0), 0.0)
        mean = np.sqrt(2.0 * np.clip(l1, 0.0, None) / math.pi) * ellipe(np.clip(m, 0.0, 1.0))
    out: np.ndarray = np.where(ok, mean, np.nan)
    return out
