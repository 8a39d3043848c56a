"""How well could any predictor do? The posterior Cramér-Rao bound (PCRB) of position.

The bound (Tichavsky, Muravchik, Nehorai 1998) is for a predictor that knows the motion model
and the noise of its inputs. The model, per axis (east and north independent and identical,
local ENU metres, seconds):

- state ``[p, v, a]`` [m, m/s, m/s^2], constant acceleration driven by white jerk of
  spectral density ``q`` [m^2/s^5]: ``x(t + dt) = F(dt) x(t) + w``, ``w ~ N(0, Q(dt))``,
  ``F(dt) = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]``,
  ``Q(dt) = q [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]]``
  (the kf's ``ca_process_noise``);
- a fix at ``t_k`` observes the position with white noise of variance ``R_k`` [m^2] per axis
  (``H = [1, 0, 0]``); optionally an IMU sample at ``s_j`` observes the acceleration with
  variance ``r_acc`` [m^2/s^4] per axis (``H = [0, 0, 1]``);
- a prior ``N(., diag(prior_var))`` on the state at the first fix (default: nothing known
  of the position, the kf's initial velocity and acceleration sigmas).

**The recursion.** The information matrices (inverse bounds) at the observation times are
``J_0 = P0^-1 + H' R_0^-1 H`` (``P0^-1``'s position entry 0 by default) and
``J_k = (F J_{k-1}^-1 F' + Q)^-1 + H' R_k^-1 H`` with ``F``, ``Q`` over the interval since
the previous observation. For this linear-Gaussian model
the recursion is exactly the Kalman filter's covariance recursion, ``J_k^-1 = P_k`` (the
information filter and the covariance filter are the same filter), so it is computed in the
covariance form (predict, then the scalar update ``P - P H' H P / (H P H' + R)``), which needs
no matrix inverse and keeps ``P`` symmetric; :func:`information_recursion` returns the ``J_k``
themselves.

**At a query.** Asked at ``t_issue`` (every observation at or before it known) for the
position at ``t_query >= t_issue``, the bound on the position's error variance per axis is
``[F(d) P_k F(d)' + Q(d)]_00`` with ``P_k`` after the newest observation at or before
``t_issue`` and ``d = t_query - t_k``: the error variance of the best predictor given those
observations (``t_issue = t_query``: a `now` query; ``t_issue`` = fix time, ``t_query`` =
fix time + horizon: a `future` query). NaN before the first fix.

**After a gap.** White jerk makes the velocity's variance grow as ``q h^3 / 3`` over an
interval ``h`` without observations, without limit: after 1,000 s at q = 80 m^2/s^5 the
model knows the velocity to 160 km/s, and a bound built on that is no bound at all (a
predictor that keeps the velocity it had is "below" it by orders of magnitude). A vehicle's
velocity and acceleration are never less known than the prior says at a drive's start
(the kf's own start, :func:`default_prior`), so over an interval longer than
:func:`gap_scale_s` (where ``q h^3 / 3`` alone exceeds the prior's velocity variance: 2 s at
q = 80, 8.8 s at q = 1, never at q = 0) the recursion, after the observation that ends it,
holds the velocity and acceleration variances at the prior's (``S P S``, every correlation
kept: :func:`_cap_at_prior`); a query across such a gap is at most
``(sqrt(P_k,00) + prior_vel_sigma d)^2`` (a velocity error of the prior's sigma held over the
whole interval). Shorter intervals are untouched, so the bound of a drive without such gaps
is the model's exactly. A lower bound lowered this way stays a bound under the model with
that ceiling; it can only make a predictor less often "below the limit".

**Numbers far from 1.** Where the predicted position variance dwarfs a fix's (a gap, a
reference glitch's jerk), the update is taken in a form without cancellation (``a r / s``,
:func:`_update`); a jerk PSD above :data:`MAX_JERK_PSD` is held there. The bound is then
finite and positive for any finite fix times, variances and q.

**What the bound says.** The bound holds for drives drawn from the model; on real drives it
says what a predictor that knows the model's ``q`` and the fixes' noise would achieve, which
:mod:`posbench.metrics.jerk_psd` estimates from a reference track (also as it varies along
the track; ``q`` may be such a profile, :data:`JerkPsd`, each interval of the recursion and
each query then taking its own). As a bound on a predictor's mean error against a reference
(a receiver's slow error included): :mod:`posbench.metrics.pcrb_mean_error`.

Pure numpy. Times [s] must be non-decreasing.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterator

import numpy as np

from posbench.metrics.ca_model import (
    ca_noise_entries,
    ca_noise_matrix,
    ca_predict_block,
    ca_transition_matrix,
)
from posbench.metrics.jerk_psd import check_times as _check_times

#: default prior standard deviations of velocity [m/s] and acceleration [m/s^2] at the first
#: fix (the kf's ``init_vel_sigma``, ``init_acc_sigma``); position: none (``inf``)
PRIOR_VEL_SIGMA = 15.0
PRIOR_ACC_SIGMA = 3.0

#: the largest jerk PSD [m^2/s^5] the bound takes as it is, a larger one (a reference with a
#: glitch far out) held there: 1e98 times a road vehicle's in a manoeuvre, and already so
#: large that every interval is a gap (velocity and acceleration held at the prior's), so
#: the bound barely depends on it, while its products with any interval stay finite
MAX_JERK_PSD = 1e100

#: what each figure means (the report's glossary collects these)
DEFINITIONS = {
    "PCRB": "posterior Cramér-Rao bound: the smallest error variance [m^2] per axis any "
    "predictor can reach when it knows the motion model (constant acceleration, white jerk "
    "of PSD q) and the noise of the fixes; for this linear-Gaussian model, the covariance of "
    "the Kalman filter with the true q and fix noise, predicted to the query time.",
    "bound mean error": "the mean Euclidean error [m] of a zero-mean 2-D Gaussian error "
    "with the PCRB's covariance (per-axis sigma s: s sqrt(pi/2)); no predictor's mean "
    "error is lower on drives drawn from the model.",
    "jerk PSD q": "spectral density [m^2/s^5] of the white jerk of the constant-acceleration "
    "model, estimated from the reference track's third differences on a uniform grid "
    "(mean square / (11/20 dt^5)); as a profile along the track, the same in a moving "
    "window.",
    "slow error floor": "the variance [m^2] per axis of a receiver's slow error (the part of "
    "its stated accuracy that is not white), added to the bound where an independent "
    "truth is the reference; none where the receiver's own fixes are.",
}

#: the jerk PSD q [m^2/s^5] the bound takes: one value for the whole drive, or a profile
#: ``(times [s], values [m^2/s^5])`` (:func:`posbench.metrics.jerk_psd.jerk_psd_profile`):
#: an interval between two
#: instants takes the profile at its middle (linear interpolation, held beyond its ends)
JerkPsd = float | tuple[np.ndarray, np.ndarray]

#: the six upper entries of a symmetric 3x3 per axis, in the order the loops use
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
_POSITION, _ACCELERATION = 0, 1


#: ``F(dt)`` and ``Q(dt)`` per axis (:mod:`posbench.metrics.ca_model`, the kf's model)
transition_matrix = ca_transition_matrix
process_noise = ca_noise_matrix


def default_prior() -> tuple[float, float, float]:
    """The default prior variances at the first fix: position ``inf`` (nothing known before
    the first fix), velocity :data:`PRIOR_VEL_SIGMA` ^2 [m^2/s^2], acceleration
    :data:`PRIOR_ACC_SIGMA` ^2 [m^2/s^4]. With the first fix, ``J_0 = diag(1/R_0, 1/15^2,
    1/3^2)``: the kf's own start (``kf.init``), so a kf with the true ``q`` and ``R``
    reports the bound itself."""
    return (math.inf, PRIOR_VEL_SIGMA**2, PRIOR_ACC_SIGMA**2)


# ---------------------------------------------------------------------- the recursion
def _variances(r: np.ndarray | float, n: int, what: str) -> np.ndarray:
    v = np.broadcast_to(np.asarray(r, dtype=float), (n,))
    if not np.all(np.isfinite(v) & (v > 0)):
        raise ValueError(f"{what}: variances must be finite and positive")
    return v


def _events(
    t_fix: np.ndarray,
    r_var: np.ndarray | float,
    t_acc: np.ndarray | None,
    r_acc: np.ndarray | float | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observation times, kinds (position / acceleration) and variances, in time order (a fix
    before an IMU sample at the same time); IMU samples before the first fix left out."""
    t = np.asarray(t_fix, dtype=float)
    _check_times(t, "t_fix")
    if t.size == 0:
        raise ValueError("t_fix: no fix")
    r = _variances(r_var, t.size, "r_var")
    if t_acc is None:
        return t, np.full(t.size, _POSITION), r
    if r_acc is None:
        raise ValueError("r_acc: the IMU's acceleration variance is needed with t_acc")
    ta = np.asarray(t_acc, dtype=float)
    _check_times(ta, "t_acc")
    ra = _variances(r_acc, ta.size, "r_acc")
    keep = ta >= t[0]
    times = np.concatenate([t, ta[keep]])
    kinds = np.concatenate([np.full(t.size, _POSITION), np.full(int(keep.sum()), _ACCELERATION)])
    order = np.lexsort((kinds, times))
    return times[order], kinds[order], np.concatenate([r, ra[keep]])[order]


def _q_between(q: JerkPsd, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """q [m^2/s^5] over each interval ``(t0, t1)`` [s]: the one value, or the profile at the
    interval's middle (:data:`JerkPsd`)."""
    shape = np.broadcast(np.asarray(t0), np.asarray(t1)).shape
    if isinstance(q, tuple):
        tq, vq = (np.asarray(a, dtype=float) for a in q)
        if tq.ndim != 1 or tq.shape != vq.shape or tq.size == 0:
            raise ValueError("q: a profile is (times, values), two 1-D arrays of one length")
        if not (np.all(np.isfinite(vq)) and np.all(vq >= 0) and np.all(np.isfinite(tq))):
            raise ValueError("q: a profile's values must be finite jerk PSDs >= 0 [m^2/s^5]")
        mid: np.ndarray = np.interp(
            0.5 * (np.asarray(t0) + np.asarray(t1)), tq, np.minimum(vq, MAX_JERK_PSD)
        )
        return mid
    if not q >= 0 or not math.isfinite(q):
        raise ValueError(f"q: a finite jerk PSD >= 0 [m^2/s^5], not {q}")
    return np.full(shape, min(float(q), MAX_JERK_PSD))


#: above this ratio of the predicted position variance to the fix's, the update is taken in
#: the form that loses no precision (``a r / s``; ``a - a a / s`` would keep less than half
#: the digits of ``r``, and 0 or less once ``a + r`` rounds to ``a``); below it the textbook
#: form, so a drive's figures stay as they were to the last bit
_STABLE_RATIO = 1e8


def _update(
    a: float, b: float, c: float, d: float, e: float, f: float, rv: float
) -> tuple[float, float, float, float, float, float]:
    """The scalar update of the six upper entries by an observation of the first state
    (``H = [1, 0, 0]``) of variance ``rv``: ``P - P H' H P / (H P H' + rv)``. Where the
    predicted variance ``a`` dwarfs ``rv`` (:data:`_STABLE_RATIO`: a gap, a glitch's jerk),
    ``a rv / s``, ``b rv / s``, ``c rv / s`` and ``d - b (b / s)``: the same values without
    the cancellation (and without squaring entries near the float range's end)."""
    s = a + rv
    if a <= _STABLE_RATIO * rv:
        return (
            a - a * a / s,
            b - a * b / s,
            c - a * c / s,
            d - b * b / s,
            e - b * c / s,
            f - c * c / s,
        )
    k = rv / s
    bs, cs = b / s, c / s
    return (a * k, b * k, c * k, d - b * bs, e - b * cs, f - c * cs)


def _cap_at_prior(
    a: float, b: float, c: float, d: float, e: float, f: float, pv: float, pa: float
) -> tuple[float, float, float, float, float, float]:
    """The six upper entries with the velocity and acceleration variances held at the
    prior's ``pv`` [m^2/s^2], ``pa`` [m^2/s^4] where they exceed them: ``S P S`` with
    ``S = diag(1, min(1, sqrt(pv / d)), min(1, sqrt(pa / f)))`` (positive semi-definite,
    every correlation kept, no entry larger in magnitude)."""
    sv = math.sqrt(pv / d) if d > pv else 1.0
    sa = math.sqrt(pa / f) if f > pa else 1.0
    return (a, b * sv, c * sa, d * sv * sv, e * sv * sa, f * sa * sa)


def gap_scale_s(q: float, prior_vel_var: float = PRIOR_VEL_SIGMA**2) -> float:
    """The interval [s] past which the motion model alone forgets a vehicle's velocity
    beyond the prior's: ``(3 prior_vel_var / q)^(1/3)``, where white jerk of PSD ``q``
    [m^2/s^5] has added the prior's velocity variance [m^2/s^2] (``q h^3 / 3``; 2.0 s at
    q = 80, 8.8 s at q = 1; inf at q = 0). An interval between observations longer than
    this is a gap (:func:`position_variance_bound`)."""
    if not q > 0:
        return math.inf
    return float((3.0 * prior_vel_var / q) ** (1.0 / 3.0))


def _recursion(
    times: np.ndarray,
    kinds: np.ndarray,
    r: np.ndarray,
    q: JerkPsd,
    prior_var: tuple[float, float, float],
) -> np.ndarray:
    """``P_k = J_k^-1`` (n, 6) after each observation, as the six upper entries (00, 01, 02,
    11, 12, 22). One step per observation in Python floats: ~1 us each, far cheaper than
    3x3 numpy calls (~10 us each); the recursion is sequential, so it does not vectorise."""
    q_steps = _q_between(q, times[:-1], times[1:])
    if len(prior_var) != 3 or not all(v > 0 and not math.isnan(v) for v in prior_var):
        raise ValueError("prior_var: three positive variances (p, v, a; inf: nothing known)")
    if not (math.isfinite(prior_var[1]) and math.isfinite(prior_var[2])):
        raise ValueError("prior_var: the velocity and acceleration variances must be finite")
    # the first observation is the first fix: with a diagonal prior only the position moves,
    # a -> (1/a + 1/r)^-1 (a = inf: r)
    r0, a0 = float(r[0]), float(prior_var[0])
    a = r0 if math.isinf(a0) else a0 * r0 / (a0 + r0)
    b, c, d, e, f = 0.0, 0.0, float(prior_var[1]), 0.0, float(prior_var[2])
    t_prev = float(times[0])
    # six doubles a step (48 bytes), not a tuple of six float objects (~250 bytes): hours of
    # IMU samples are millions of steps
    out = array("d", (a, b, c, d, e, f))
    pv, pa = float(prior_var[1]), float(prior_var[2])
    for t, kind, rv, qk in _steps(times, kinds, r, q_steps):
        h = t - t_prev
        gap = False
        if h > 0.0:
            qb = ca_noise_entries(h, qk)
            a, b, c, d, e, f = ca_predict_block((a, b, c, d, e, f), h, 0.5 * h * h, qb)
            t_prev = t
            gap = qb[3] > pv
        if kind == _POSITION:  # H = [1, 0, 0]
            a, b, c, d, e, f = _update(a, b, c, d, e, f, rv)
        else:  # H = [0, 0, 1]: the same update with p and a swapped
            f, e, c, d, b, a = _update(f, e, c, d, b, a, rv)
        if gap:
            a, b, c, d, e, f = _cap_at_prior(a, b, c, d, e, f, pv, pa)
        out.extend((a, b, c, d, e, f))
    return np.frombuffer(out, dtype=float).reshape(-1, 6)


#: observations :func:`_recursion` turns into Python floats at a time
STEP_CHUNK = 1 << 16


def _steps(
    times: np.ndarray, kinds: np.ndarray, r: np.ndarray, q_steps: np.ndarray
) -> Iterator[tuple[float, int, float, float]]:
    """(t, kind, r, q) of each observation after the first, as Python numbers, converted
    :data:`STEP_CHUNK` at a time (four lists of every observation: ~190 MB at 1.5 M)."""
    for lo in range(1, times.size, STEP_CHUNK):
        hi = lo + STEP_CHUNK
        yield from zip(
            times[lo:hi].tolist(),
            kinds[lo:hi].tolist(),
            r[lo:hi].tolist(),
            q_steps[lo - 1 : hi - 1].tolist(),
            strict=True,
        )


def _full(upper: np.ndarray) -> np.ndarray:
    """(n, 6) upper entries -> (n, 3, 3) symmetric matrices."""
    m = np.empty((upper.shape[0], 3, 3))
    for k, (i, j) in enumerate(_UPPER):
        m[:, i, j] = m[:, j, i] = upper[:, k]
    return m


def _prior(prior_var: tuple[float, float, float] | None) -> tuple[float, float, float]:
    return default_prior() if prior_var is None else prior_var


def filtered_bound(
    t_fix: np.ndarray,
    r_var: np.ndarray | float,
    q: JerkPsd,
    prior_var: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """The PCRB ``J_k^-1`` (n, 3, 3) per axis [m^2, m^2/s, ...] of the state ``[p, v, a]``
    just after each fix (the filtered bound; see the module docstring).

    ``t_fix`` (n,) [s], non-decreasing; ``r_var`` [m^2] per axis, one or one per fix;
    ``q`` [m^2/s^5], one value or a profile (:data:`JerkPsd`); ``prior_var``: the prior's
    diagonal at the first fix (position [m^2], velocity [m^2/s^2], acceleration [m^2/s^4]),
    default :func:`default_prior`.
    """
    times, kinds, r = _events(np.asarray(t_fix, dtype=float), r_var, None, None)
    return _full(_recursion(times, kinds, r, q, _prior(prior_var)))


def information_recursion(
    t_fix: np.ndarray,
    r_var: np.ndarray | float,
    q: JerkPsd,
    prior_var: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """The information matrices ``J_k`` (n, 3, 3) per axis at each fix:
    ``J_0 = P0^-1 + H' R_0^-1 H``, ``J_k = (F J_{k-1}^-1 F' + Q)^-1 + H' R_k^-1 H``,
    ``H = [1, 0, 0]``; the inverse of :func:`filtered_bound` (same arguments), which computes
    the same recursion in the covariance form."""
    j: np.ndarray = np.linalg.inv(filtered_bound(t_fix, r_var, q, prior_var))
    return j


def _at_queries(
    times: np.ndarray,
    upper: np.ndarray,
    q: JerkPsd,
    t_query: np.ndarray,
    t_issue: np.ndarray | None,
    prior_vel_var: float,
) -> np.ndarray:
    """``[F(d) P_k F(d)' + Q(d)]_00`` per query, vectorised (see the module docstring); a
    query across a gap (``q d^3 / 3`` above ``prior_vel_var`` [m^2/s^2]) at most
    ``(sqrt(P_k,00) + sqrt(prior_vel_var) d)^2``. :data:`STEP_CHUNK` queries at a time, so
    that the temporaries of hours of queries are never held at once."""
    tq = np.asarray(t_query, dtype=float)
    ti = tq if t_issue is None else np.broadcast_to(np.asarray(t_issue, dtype=float), tq.shape)
    if np.any(tq < ti):
        raise ValueError("t_query before t_issue: the bound is for predictions, not smoothing")
    flat_q, flat_i = tq.reshape(-1), ti.reshape(-1)
    out = np.empty(flat_q.size)
    for lo in range(0, flat_q.size, STEP_CHUNK):
        hi = lo + STEP_CHUNK
        out[lo:hi] = _at_some_queries(times, upper, q, flat_q[lo:hi], flat_i[lo:hi], prior_vel_var)
    return out.reshape(tq.shape)


def _at_some_queries(
    times: np.ndarray,
    upper: np.ndarray,
    q: JerkPsd,
    tq: np.ndarray,
    ti: np.ndarray,
    prior_vel_var: float,
) -> np.ndarray:
    """:func:`_at_queries` of the queries at ``tq`` [s] issued at ``ti`` [s] (1-D)."""
    k = np.searchsorted(times, ti, side="right") - 1
    known = k >= 0
    p = upper[np.where(known, k, 0)]
    d = np.where(known, tq - times[np.where(known, k, 0)], 0.0)
    q_d = _q_between(q, tq - d, tq)
    d2 = d * d
    var = (
        p[..., 0]
        + 2.0 * d * p[..., 1]
        + d2 * (p[..., 2] + p[..., 3])
        + d2 * d * p[..., 4]
        + 0.25 * d2 * d2 * p[..., 5]
        + q_d * d2 * d2 * d / 20.0
    )
    # across a gap the velocity is no less known than the prior's: the position drifts at
    # most by an error of that sigma held for the whole interval (Var(int v) <= (int s_v)^2)
    gap = q_d * d2 * d / 3.0 > prior_vel_var
    if np.any(gap):
        held = (np.sqrt(p[..., 0]) + math.sqrt(prior_vel_var) * d) ** 2
        var = np.where(gap, np.minimum(var, held), var)
    return np.where(known, var, np.nan)


def position_variance_bound(
    t_fix: np.ndarray,
    r_var: np.ndarray | float,
    q: JerkPsd,
    t_query: np.ndarray,
    *,
    t_issue: np.ndarray | None = None,
    prior_var: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """The PCRB [m^2] per axis on the position at each ``t_query`` [s], asked at
    ``t_issue`` [s] (default: ``t_query``, a `now` query) knowing the fixes at or before it.

    ``[F(d) P_k F(d)' + Q(d)]_00``, ``P_k`` the filtered bound after the newest fix at or
    before ``t_issue``, ``d = t_query - t_k``; NaN before the first fix. ``t_query`` and
    ``t_issue`` (same shape, ``t_query >= t_issue``) in any order; other arguments as
    :func:`filtered_bound`. One recursion step per fix, then vectorised over the queries.
    """
    times, kinds, r = _events(np.asarray(t_fix, dtype=float), r_var, None, None)
    prior = _prior(prior_var)
    upper = _recursion(times, kinds, r, q, prior)
    return _at_queries(times, upper, q, t_query, t_issue, prior[1])


def position_variance_bound_with_acceleration(
    t_fix: np.ndarray,
    r_var: np.ndarray | float,
    q: JerkPsd,
    t_query: np.ndarray,
    t_acc: np.ndarray,
    r_acc: np.ndarray | float,
    *,
    t_issue: np.ndarray | None = None,
    prior_var: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """:func:`position_variance_bound` for a predictor that also has an IMU: at each of
    ``t_acc`` [s] (non-decreasing) the acceleration per axis is observed with variance
    ``r_acc`` [m^2/s^4] (one or one per sample; ``H = [0, 0, 1]``; a known input is an
    observation of the state's acceleration). The recursion runs over fixes and IMU samples
    together, from the first fix (IMU samples before it are left out); a query uses the
    newest observation of either kind at or before its ``t_issue``. Never above the
    fixes-only bound; equal to it as ``r_acc`` grows without bound.
    """
    times, kinds, r = _events(np.asarray(t_fix, dtype=float), r_var, t_acc, r_acc)
    prior = _prior(prior_var)
    upper = _recursion(times, kinds, r, q, prior)
    return _at_queries(times, upper, q, t_query, t_issue, prior[1])
