"""The limit of one drive: per-query bounds on the mean error, from the drive's own arrays.

:mod:`posbench.metrics.pcrb` gives the posterior Cramér-Rao bound for a set of fixes; this
module puts together what a drive needs for it, as pure functions on arrays (seconds,
metres, local ENU):

- the fixes' white noise, estimated from the fixes alone (:func:`fix_white_variance`, the
  estimator of the filters' ``FixNoise`` over a whole drive, made robust);
- the IMU's white noise, estimated from its own samples (:func:`imu_white_variance`);
- the fixes' total error against an independent truth (:func:`fix_error_variance`), of
  which the part that is not white is the receiver's slow error;
- the per-query bound on the mean Euclidean error, fixes only and with the IMU as a known
  acceleration input (:func:`mean_error_bounds`); with a slow error drawn by the harness,
  the realised error at each query as an offset no predictor can remove
  (:func:`mean_error_offset`, the Rice mean);
- how few independent samples of a slow error one drive holds
  (:func:`correlation_time_s`, :func:`slow_floor_sd`).

Which of these a drive uses (a simulated GPS profile's known noise, a receiver's stated
accuracy, the reference's kind) is the harness's choice (``posbench.replay.limit``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from posbench.metrics.bootstrap import summary_ci
from posbench.metrics.cluster_bootstrap import DEFAULT_RESAMPLES, LEVEL
from posbench.metrics.pcrb import (
    JerkPsd,
    position_variance_bound,
    position_variance_bound_with_acceleration,
)
from posbench.metrics.pcrb_mean_error import mean_error_bound, with_slow_error

#: how the bound is named wherever it appears beside the predictors (never ranked with them)
LIMIT_NAME = "limit (PCRB, CA model)"
#: ... and its variant that also knows the IMU
LIMIT_IMU_NAME = "limit with IMU (PCRB, CA + IMU)"
#: the smallest fix variance [m^2] per axis the bound takes (1 mm^2: exact simulated fixes
#: and numerical safety; the filters' ``FixNoise`` floor)
MIN_FIX_VAR_M2 = 1e-6
#: the smallest IMU variance [m^2/s^4] per axis the IMU variant takes
MIN_IMU_VAR = 1e-6
#: a fix farther from the truth than this many times the median distance is a glitch, left
#: out of :func:`fix_error_variance` (a Gaussian error reaches it with odds below 1e-15)
OUTLIER_FACTOR = 5.0
#: beyond this ``|offset|^2 / (2 var)`` the Rice mean is taken in its asymptotic form
#: ``nu + var / (2 nu)`` (:func:`mean_error_offset`; relative error below 1e-12 there)
RICE_ASYMPTOTIC = 1e12
#: the grid [s] on which :func:`correlation_time_s` reads a slow error's autocorrelation
CORRELATION_STEP_S = 1.0

#: what each figure means (the report's glossary collects these)
DEFINITIONS = {
    "limit": f"`{LIMIT_NAME}`: the smallest mean error [m] any predictor can reach on the "
    "same queries if the vehicle moved as the constant-acceleration model says (white jerk "
    "of the PSD its reference shows, as it varies along the drive) and the fixes had the "
    "noise the bound "
    "takes (a simulated profile's own, else the fixes' estimated white noise); against an "
    "independent truth, plus the receiver's slow error, which no fix reveals (on simulated "
    "fixes the error drawn for the drive). A predictor that reads the IMU is held against "
    "the limit with IMU. A bound under "
    "stated assumptions, never a predictor: it is not ranked, compared or gated.",
    "limit with IMU": f"`{LIMIT_IMU_NAME}`: the same bound for a predictor that also "
    "observes the acceleration at every IMU sample, with the IMU's white noise as its "
    "samples show it (bias, tilt and mounting taken as known: optimistic).",
    "x limit": "a predictor's mean error / the limit's mean error over the same scored "
    "queries (1 = at the bound; 2 = twice the smallest error possible under the bound's "
    "assumptions). Below 1 by more than the predictor's interval (against the limit with "
    "IMU for a predictor that reads the IMU): it uses information the bound does not have, "
    "or the bound's assumptions do not hold on that data.",
}


def fix_white_variance(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    """The white noise variance [m^2] per axis of a drive's fixes (``t`` [s] increasing,
    ``x``, ``y`` [m] ENU), from the fixes alone.

    Each fix against the quadratic through the three before it (Lagrange extrapolation to
    its time; any constant-acceleration motion drops out): white noise of variance ``s2``
    gives the sample ``|r|^2 / (2 (1 + sum L_i^2))`` an Exp(1) distribution scaled by
    ``s2``, so ``s2 = median(samples) / ln 2``; the median ignores manoeuvres and glitches
    (the filters' ``FixNoise`` does the same with a running, clipped mean). At least
    :data:`MIN_FIX_VAR_M2`; NaN with fewer than 4 usable fixes.
    """
    tt, xx, yy = (np.asarray(a, dtype=float) for a in (t, x, y))
    ok = np.isfinite(tt) & np.isfinite(xx) & np.isfinite(yy)
    tt, xx, yy = tt[ok], xx[ok], yy[ok]
    if tt.size < 4:
        return math.nan
    t0, t1, t2, tk = tt[:-3], tt[1:-2], tt[2:-1], tt[3:]
    # a glitch far out (1e200 m) squares to inf: its sample is left out below, as a
    # repeated time's is
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        l0 = (tk - t1) * (tk - t2) / ((t0 - t1) * (t0 - t2))
        l1 = (tk - t0) * (tk - t2) / ((t1 - t0) * (t1 - t2))
        l2 = (tk - t0) * (tk - t1) / ((t2 - t0) * (t2 - t1))
        rx = xx[3:] - (l0 * xx[:-3] + l1 * xx[1:-2] + l2 * xx[2:-1])
        ry = yy[3:] - (l0 * yy[:-3] + l1 * yy[1:-2] + l2 * yy[2:-1])
        samples = (rx * rx + ry * ry) / (2.0 * (1.0 + l0 * l0 + l1 * l1 + l2 * l2))
    samples = samples[np.isfinite(samples)]
    if samples.size == 0:
        return math.nan
    return max(MIN_FIX_VAR_M2, float(np.median(samples)) / math.log(2.0))


def imu_white_variance(t: np.ndarray, ax: np.ndarray, ay: np.ndarray) -> float:
    """The white noise variance [m^2/s^4] per axis of an IMU's accelerations (``t`` [s],
    ``ax``, ``ay`` [m/s^2], any frame: the noise is taken alike on both axes).

    From sample-to-sample differences, robustly: the true acceleration barely changes
    between samples (jerk x interval), white noise of variance ``s2`` gives differences of
    variance ``2 s2``; ``s2 = (1.4826 MAD)^2 / 2`` over both axes, so rare glitches of
    hundreds of m/s^2 do not count. A bias, a tilt or a slow drift is not seen (the bound
    takes them as known). At least :data:`MIN_IMU_VAR`; NaN with fewer than 3 samples.
    """
    tt, a, b = (np.asarray(v, dtype=float) for v in (t, ax, ay))
    ok = np.isfinite(tt) & np.isfinite(a) & np.isfinite(b)
    tt, a, b = tt[ok], a[ok], b[ok]
    if tt.size < 3:
        return math.nan
    step = np.diff(tt) > 0
    d = np.concatenate([np.diff(a)[step], np.diff(b)[step]])
    if d.size < 2:
        return math.nan
    mad = float(np.median(np.abs(d - np.median(d))))
    return max(MIN_IMU_VAR, (1.4826 * mad) ** 2 / 2.0)


def fix_error_variance(ex: np.ndarray, ey: np.ndarray) -> float:
    """The mean square [m^2] per axis of fixes' errors against an independent truth (``ex``,
    ``ey`` [m]: fix minus truth at the fix times, ENU): bias and slow error included, glitches
    (farther than :data:`OUTLIER_FACTOR` x the median distance) left out. NaN without a
    finite error."""
    e = np.column_stack([np.asarray(ex, dtype=float), np.asarray(ey, dtype=float)])
    e = e[np.isfinite(e).all(axis=1)]
    if e.shape[0] == 0:
        return math.nan
    r = np.hypot(e[:, 0], e[:, 1])
    med = float(np.median(r))
    keep = r <= OUTLIER_FACTOR * med if med > 0 else np.ones(r.size, dtype=bool)
    return float(np.mean(r[keep] ** 2) / 2.0)


def mean_error_offset(var: np.ndarray | float, offset_m: np.ndarray | float) -> np.ndarray:
    """Mean Euclidean error [m] of a 2-D Gaussian with per-axis variance ``var`` [m^2] (axes
    independent) offset by a fixed vector of length ``offset_m`` [m]: the mean of a Rice
    distribution, ``s sqrt(pi/2) L_1/2(-a)`` with ``s = sqrt(var)``, ``a = nu^2 / (2 s^2)``,
    taken as ``(1 + a) i0e(a/2) + a i1e(a/2)`` (scipy's exponentially scaled Bessel
    functions: no overflow) and as ``nu + s^2 / (2 nu)`` beyond :data:`RICE_ASYMPTOTIC`.
    ``offset_m = 0`` gives :func:`~posbench.metrics.pcrb_mean_error.mean_error_bound` (the Rayleigh
    mean), ``var = 0`` gives ``offset_m``; averaged over offsets drawn from a 2-D Gaussian
    of per-axis variance ``v``, it is the Rayleigh mean of ``var + v``. NaN where either is
    NaN."""
    from scipy.special import i0e, i1e

    v = np.asarray(var, dtype=float)
    nu = np.abs(np.asarray(offset_m, dtype=float))
    v, nu = np.broadcast_arrays(v, nu)
    out = np.full(v.shape, np.nan)
    ok = np.isfinite(v) & np.isfinite(nu) & (v >= 0)
    zero = ok & (v == 0)
    out[zero] = nu[zero]
    pos = ok & (v > 0)
    with np.errstate(over="ignore"):
        a = np.where(pos, nu * nu / np.where(pos, 2.0 * v, 1.0), 0.0)
    far = pos & ~(a <= RICE_ASYMPTOTIC)  # an inf a too
    out[far] = nu[far] + v[far] / (2.0 * nu[far])
    near = pos & ~far
    an, sn = a[near], np.sqrt(v[near])
    lag = (1.0 + an) * i0e(an / 2.0) + an * i1e(an / 2.0)
    out[near] = sn * math.sqrt(math.pi / 2.0) * lag
    return out


def correlation_time_s(t: np.ndarray, ex: np.ndarray, ey: np.ndarray) -> float:
    """The correlation time [s] of an error ``ex``, ``ey`` [m] at times ``t`` [s] (fix minus
    truth, say): on a grid of :data:`CORRELATION_STEP_S`, the first lag at which its
    autocorrelation ``sum e(t) e(t + L) / sum e(t)^2`` (both axes, the mean **not**
    removed: a bias is one sample however long the drive) falls below 1/e; at least the
    grid step, at most the span of ``t``. NaN with fewer than 2 finite samples or no
    error."""
    tt, a, b = (np.asarray(v, dtype=float) for v in (t, ex, ey))
    ok = np.isfinite(tt) & np.isfinite(a) & np.isfinite(b)
    tt, a, b = tt[ok], a[ok], b[ok]
    if tt.size < 2 or not np.all(np.diff(tt) >= 0):
        return math.nan
    span = float(tt[-1] - tt[0])
    if not (span > 0):
        return math.nan
    step = min(CORRELATION_STEP_S, span)
    grid = tt[0] + step * np.arange(int(span / step) + 1)
    e = np.column_stack([np.interp(grid, tt, a), np.interp(grid, tt, b)])
    scale = float(np.max(np.abs(e)))
    if not (scale > 0 and math.isfinite(scale)):
        return math.nan
    e = e / scale  # no overflow in the products below
    n = grid.size
    f = np.fft.rfft(e, n=2 * n, axis=0)  # zero-padded: every lag's sum at once
    acf = np.fft.irfft(f * np.conj(f), n=2 * n, axis=0)[:n].sum(axis=1)
    rho = acf / acf[0] * n / (n - np.arange(n))  # each lag's mean product over its mean square
    below = np.flatnonzero(rho[1:] < math.exp(-1.0))
    return float((below[0] + 1) * step) if below.size else span


def slow_floor_sd(total_var_m2: float, duration_s: float, tau_s: float) -> float:
    """The standard deviation [m^2] of a slow error's variance per axis as measured over one
    drive: ``total_var_m2 / sqrt(n)`` with ``n = max(1, duration_s / tau_s)`` independent
    samples (the mean square of an exponentially correlated error over ``T`` has the
    variance ``2 s^4 tau / T`` per axis; two axes halve it). NaN where an input is not
    finite or ``tau_s`` not positive."""
    vals = (total_var_m2, duration_s, tau_s)
    if not all(math.isfinite(v) for v in vals) or tau_s <= 0 or total_var_m2 < 0:
        return math.nan
    return float(total_var_m2) / math.sqrt(max(1.0, duration_s / tau_s))


def mean_error_bounds(
    t_fix: np.ndarray,
    r_var: float,
    q: JerkPsd,
    t_issue: np.ndarray,
    t_query: np.ndarray,
    *,
    slow_var: float = 0.0,
    slow_offset_m: np.ndarray | None = None,
    independent_truth: bool = True,
    latency_s: float = 0.0,
    t_acc: np.ndarray | None = None,
    r_acc: float | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Per query, the bound [m] on the mean Euclidean error of any predictor, fixes only,
    and with the IMU (None without ``t_acc``).

    ``t_fix`` [s] the fixes received (non-decreasing), each observing the position with
    white noise ``r_var`` [m^2] per axis; ``q`` [m^2/s^5] the jerk PSD, one value or a
    profile along the drive (:data:`~posbench.metrics.pcrb.JerkPsd`); queries asked at
    ``t_issue`` [s] for the position at ``t_query`` [s] (same shape). A fix stamped ``t``
    that holds the position at ``t - latency_s`` [s] (a receiver's latency) is an
    observation at ``t - latency_s``, known from ``t`` on. ``slow_var`` [m^2] per axis, the
    receiver's slow error, is added where ``independent_truth`` is the reference
    (:func:`~posbench.metrics.pcrb_mean_error.with_slow_error`); ``slow_offset_m`` [m] (same
    shape as the queries), a slow error's realised length at each query, instead takes it as
    an offset (:func:`mean_error_offset`; ``slow_var`` is then not added). ``t_acc`` [s],
    ``r_acc`` [m^2/s^4]: IMU samples observing the acceleration per axis
    (:func:`~posbench.metrics.pcrb.position_variance_bound_with_acceleration`; with a
    latency, the IMU samples of the last ``latency_s`` before a query are not used).
    Both axes alike, so the mean error is the Rayleigh mean of the per-axis variance
    (:func:`~posbench.metrics.pcrb_mean_error.mean_error_bound`). NaN before the first fix and
    everywhere when ``q`` is not finite (or an empty profile) or there is no fix.
    """
    ti = np.asarray(t_issue, dtype=float)
    tq = np.asarray(t_query, dtype=float)
    tf = np.asarray(t_fix, dtype=float)
    nan = np.full(tq.shape, np.nan)
    no_q = q[0].size == 0 if isinstance(q, tuple) else not math.isfinite(q)
    if tf.size == 0 or no_q or not math.isfinite(r_var):
        return nan, (None if t_acc is None else nan.copy())
    r = max(float(r_var), MIN_FIX_VAR_M2)
    obs, issue = tf - latency_s, ti - latency_s
    offset = None
    if slow_offset_m is not None and independent_truth:
        offset = np.broadcast_to(np.asarray(slow_offset_m, dtype=float), tq.shape)
        slow_var = 0.0

    def mean_error(v: np.ndarray) -> np.ndarray:
        v = with_slow_error(v, slow_var, independent_truth=independent_truth)
        return mean_error_bound(v) if offset is None else mean_error_offset(v, offset)

    bound = mean_error(position_variance_bound(obs, r, q, tq, t_issue=issue))
    if t_acc is None:
        return bound, None
    ta = np.asarray(t_acc, dtype=float)
    ra = r_acc if r_acc is not None and math.isfinite(r_acc) else math.nan
    if ta.size == 0 or not math.isfinite(ra):
        return bound, nan.copy()
    var_i = position_variance_bound_with_acceleration(
        obs, r, q, tq, ta, max(ra, MIN_IMU_VAR), t_issue=issue
    )
    return bound, mean_error(var_i)


def mean_ci(
    values: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> dict[str, Any]:
    """The interval of the mean [m] of the finite ``values`` (a bound's per-query mean
    errors), resampling ``clusters`` (drives), or with one cluster in blocks of its queries
    in time order (``times`` [s]): :func:`posbench.metrics.bootstrap.summary_ci` without
    its quantile pass, so ``median_m`` and ``p95_m`` are NaN (a bound's median and p95 are
    no bound). Keys as ``summary_ci``'s."""
    return summary_ci(values, clusters, times, n_resamples, seed, level, quantiles=False)
