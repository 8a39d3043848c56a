"""The ekf bank's filters as rows of one array, stepped by compiled kernels (numba).

Why: a bank of 8 CTRA EKFs (plus 8 shadows) as Python objects costs 8-16 Python calls,
each a few 10x10 numpy products, per IMU sample, wheel speed and fix (a fix step ~180 us,
~90x constant velocity's). So each observation is one call to a compiled kernel that
loops over the rows, as :mod:`~posbench.predictors.kalman.ca_rows` does for the kf bank.

How a row is composed (Stone Soup's split): the motion model is
:mod:`~posbench.predictors.kalman.ctra_model`'s (its step, Jacobian and process noise,
compiled into :func:`predict`: written once); each sensor's update only says what it
measures, as the columns of ``P H'``, ``H P H' + R`` and the innovation
(:func:`update_fix`, :func:`update_imu`, :func:`update_speed`), and one linear update
(:func:`linear_update`, up to 3 measurements at once, ``S^-1`` in closed form) does the
rest. The tests hold the rows to a readable reference (tests/reference_filters:
``CtraEkf``, and filterpy's EKF through it) at a tolerance, not to the bit.

Layout. Row state ``S[i]`` (float64): the mean ``[x, y, yaw, v, yaw_rate, a, b_a, b_w,
b_y, k_v]`` at :data:`X` (``CtraEkf.x``), the 10x10 covariance row-major at :data:`P`,
the time of the state :data:`TS` [s], whether the row is initialised :data:`READY`, the
newest fix held before initialisation ``(t, x, y)`` at :data:`FIX`, the IMU yaw
:data:`YAW_MEAS` [rad] and wheel speed :data:`SPEED_MEAS` [m/s] seen before it, and the
newest fix's innovation ``(nu_x, nu_y, S_xx, S_xy, S_yy)`` at :data:`INNOV` with its
robust log-likelihood at :data:`LL`. Row parameters ``RP[i]``: :data:`RP_NAMES`. Options
``CF``: :data:`CF_NAMES`. ``W``: a work buffer of :data:`NW` floats.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import huber_log_likelihood, kernel, update_scores
from posbench.predictors.kalman.ctra_model import (
    ctra_displacement,
    ctra_motion,
    ctra_noise_entries,
)

X, P = 0, 10
TS, READY, FIX, YAW_MEAS, SPEED_MEAS, INNOV, LL = 110, 111, 112, 115, 116, 117, 122
#: columns of a row's state
NS = 123
#: a row's parameters, in order: white-jerk and white-yaw-acceleration densities, the
#: accelerometer and gyro bias densities, the prior variances of b_a, b_w, b_y, k_v, the
#: variances of the IMU yaw rate, accel and yaw and of the wheel speed, the speed's
#: relative sigma, whether the row takes the IMU (0/1), its yaw (0/1), the wheel speed (0/1)
RP_NAMES = tuple(
    "jerk_psd yaw_acc_psd accel_bias_psd gyro_bias_psd var_ba0 var_bw0 var_by0 var_kv0 "
    "r_w r_a r_yaw r_v rel_sigma has_imu use_yaw has_speed".split()
)
(JERK, YAWACC, QBA, QBW, VBA0, VBW0, VBY0, VKV0) = range(8)
(R_W, R_A, R_YAW, R_V, REL, HAS_IMU, USE_YAW, HAS_SPEED) = range(8, 16)
NP = len(RP_NAMES)
#: the options array ``CF``, in order: position random-walk density [m^2/s], calibration
#: random-walk density, prior speed variance without a speed [m^2/s^2], Huber k of the
#: fix likelihood
CF_NAMES = ("pos_psd", "calib_psd", "var_v0", "huber_k")
POS_PSD, CALIB_PSD, VAR_V0, HUBER_K = range(4)
#: floats of the work buffer: P H' (10 x 3 by columns) at 0, the gain K at :data:`WK`,
#: H P H' + R (3 x 3) at :data:`WS`, its inverse at :data:`WI`
NW = 80
WK, WS, WI = 30, 60, 69

TWO_PI = 2.0 * math.pi  # as predictors/_geometry.py
PI2 = math.pi**2
VAR_W0 = 0.3**2  # the prior yaw rate and acceleration variances of CtraEkf._init
VAR_A0 = 2.0**2
#: the two states an IMU channel (yaw rate, accel, yaw) measures the sum of: yaw_rate +
#: b_w, a + b_a, yaw + b_y
IMU_J, IMU_B = (4, 5, 2), (7, 6, 8)
#: the entries of the covariance Q adds to, in ctra_noise_entries' order (ctra_model.Q_ENTRIES)
Q_AT = (0, 11, 1, 10, 3, 30, 13, 31, 5, 50, 15, 51, 33, 35, 53, 55, 22, 24, 42, 44)


def new_rows(n: int) -> np.ndarray:
    """State of ``n`` rows, none initialised (``CtraEkf.reset``)."""
    S = np.zeros((n, NS))
    for k in range(10):
        S[:, P + 11 * k] = 1.0
    S[:, TS] = math.nan
    S[:, FIX : FIX + 3] = math.nan
    S[:, YAW_MEAS] = S[:, SPEED_MEAS] = math.nan
    return S


@kernel
def _wrap(a: float) -> float:
    return (a + math.pi) % TWO_PI - math.pi


@kernel
def _jacobian(S: np.ndarray, i: int, T: float) -> tuple[float, ...]:
    """:func:`~posbench.predictors.kalman.ctra_model.ctra_motion` at row i's mean over T [s]."""
    return ctra_motion(S[i, 2], S[i, 3], S[i, 4], S[i, 5], T)


@kernel
def predict(S: np.ndarray, RP: np.ndarray, CF: np.ndarray, i: int, t: float) -> None:
    """Row i to time t [s] (``CtraEkf._predict_to``: only forward): the CTRA step, then
    P = F P F' + Q, symmetrised. F is the identity but for rows 0-3 (x, y from yaw, v,
    yaw_rate, a; yaw from yaw_rate; v from a), so only those rows and columns change."""
    T = t - S[i, TS]
    if not T > 0.0:
        return
    dx, dy, f02, f03, f04, f05, f12, f13, f14, f15, c, s = _jacobian(S, i, T)
    yaw, v, w, a = S[i, 2], S[i, 3], S[i, 4], S[i, 5]
    S[i, 0] += dx
    S[i, 1] += dy
    S[i, 2] = _wrap(yaw + w * T)
    S[i, 3] = v + a * T
    for j in range(10):  # F P: rows 0 and 1 read the old rows 2-5, then rows 2 and 3
        p2, p3 = S[i, P + 20 + j], S[i, P + 30 + j]
        p4, p5 = S[i, P + 40 + j], S[i, P + 50 + j]
        S[i, P + j] += f02 * p2 + f03 * p3 + f04 * p4 + f05 * p5
        S[i, P + 10 + j] += f12 * p2 + f13 * p3 + f14 * p4 + f15 * p5
        S[i, P + 20 + j] = p2 + T * p4
        S[i, P + 30 + j] = p3 + T * p5
    for r in range(10):  # (F P) F', by columns alike
        o = P + 10 * r
        q2, q3, q4, q5 = S[i, o + 2], S[i, o + 3], S[i, o + 4], S[i, o + 5]
        S[i, o] += q2 * f02 + q3 * f03 + q4 * f04 + q5 * f05
        S[i, o + 1] += q2 * f12 + q3 * f13 + q4 * f14 + q5 * f15
        S[i, o + 2] = q2 + q4 * T
        S[i, o + 3] = q3 + q5 * T
    # + Q: the motion's at the heading before the step, and the sensor states' random walks
    q = ctra_noise_entries(c, s, T, RP[i, JERK], RP[i, YAWACC], CF[POS_PSD])
    for k in range(20):
        S[i, P + Q_AT[k]] += q[k]
    S[i, P + 66] += RP[i, QBA] * T
    S[i, P + 77] += RP[i, QBW] * T
    S[i, P + 88] += CF[CALIB_PSD] * T
    S[i, P + 99] += CF[CALIB_PSD] * T
    for r in range(10):  # symmetrise: P = (P + P') / 2
        for k in range(r + 1, 10):
            m = (S[i, P + 10 * r + k] + S[i, P + 10 * k + r]) * 0.5
            S[i, P + 10 * r + k] = m
            S[i, P + 10 * k + r] = m
    S[i, TS] = t


@kernel
def linear_update(S: np.ndarray, W: np.ndarray, i: int, m: int, e: tuple) -> None:
    """Row i takes m (1-3) measurements at once: with the columns of P H' in W[10 l + q]
    (l < m, q < 10), H P H' + R in W[WS + 3 l + c] and the innovations ``e[:m]``,
    K = P H' S^-1, x += K e, P -= K (P H')' (``CtraEkf._gain``, ``_update_position`` and
    ``update_imu``)."""
    s = W[WS:]
    si = W[WI:]
    if m == 1:
        si[0] = 1.0 / s[0]
    elif m == 2:
        det = s[0] * s[4] - s[1] * s[3]
        si[0], si[1], si[3], si[4] = s[4] / det, -s[1] / det, -s[3] / det, s[0] / det
    else:
        a, b, c, d, ee, f = s[0], s[1], s[2], s[4], s[5], s[8]
        A00, A01, A02 = d * f - ee * ee, c * ee - b * f, b * ee - c * d
        A11, A12, A22 = a * f - c * c, b * c - a * ee, a * d - b * b
        w = 1.0 / (a * A00 + b * A01 + c * A02)
        si[0], si[1], si[2] = A00 * w, A01 * w, A02 * w
        si[3], si[4], si[5] = A01 * w, A11 * w, A12 * w
        si[6], si[7], si[8] = A02 * w, A12 * w, A22 * w
    for q in range(10):  # K = P H' S^-1, then x += K e
        dx = 0.0
        for c in range(m):
            acc = 0.0
            for k in range(m):
                acc += W[10 * k + q] * si[3 * k + c]
            W[WK + 10 * c + q] = acc
            dx += acc * e[c]
        S[i, q] += dx
    for a in range(10):  # P -= K (P H')'
        for b in range(10):
            acc = 0.0
            for c in range(m):
                acc += W[WK + 10 * c + a] * W[10 * c + b]
            S[i, P + 10 * a + b] -= acc


@kernel
def update_fix(S: np.ndarray, W: np.ndarray, i: int, zx: float, zy: float, r: float) -> None:
    """A position fix (zx, zy) [m] of variance r [m^2] per axis for row i (H selects x,
    y); stores the innovation and its covariance at :data:`INNOV`."""
    for q in range(10):
        W[q], W[10 + q] = S[i, P + 10 * q], S[i, P + 10 * q + 1]
    W[WS], W[WS + 1] = W[0] + r, W[1]
    W[WS + 3], W[WS + 4] = W[10], W[11] + r
    e0, e1 = zx - S[i, 0], zy - S[i, 1]
    S[i, INNOV], S[i, INNOV + 1] = e0, e1
    S[i, INNOV + 2], S[i, INNOV + 3], S[i, INNOV + 4] = W[WS], W[WS + 1], W[WS + 4]
    linear_update(S, W, i, 2, (e0, e1, 0.0))


@kernel
def update_imu(
    S: np.ndarray, RP: np.ndarray, W: np.ndarray, i: int, yaw_rate: float, ax: float, yaw: float
) -> None:
    """The finite ones of yaw rate [rad/s], longitudinal acceleration [m/s^2] and yaw [rad]
    for row i, at once: each measures a state plus its bias (:data:`IMU_J`,
    :data:`IMU_B`); the yaw's innovation is wrapped (``CtraEkf.update_imu``)."""
    z = (yaw_rate, ax, yaw)
    rr = (RP[i, R_W], RP[i, R_A], RP[i, R_YAW])
    sel = [0, 0, 0]
    e = [0.0, 0.0, 0.0]
    m = 0
    for k in range(3):
        if math.isfinite(z[k]):
            j, b = IMU_J[k], IMU_B[k]
            for q in range(10):
                W[10 * m + q] = S[i, P + 10 * q + j] + S[i, P + 10 * q + b]
            innov = z[k] - S[i, j] - S[i, b]
            e[m] = _wrap(innov) if k == 2 else innov
            sel[m] = k
            m += 1
    if m == 0:
        return
    for row in range(m):
        j, b = IMU_J[sel[row]], IMU_B[sel[row]]
        for col in range(m):
            W[WS + 3 * row + col] = W[10 * col + j] + W[10 * col + b]
        W[WS + 4 * row] += rr[sel[row]]
    linear_update(S, W, i, m, (e[0], e[1], e[2]))
    if sel[m - 1] == 2:
        S[i, 2] = _wrap(S[i, 2])


@kernel
def update_speed(S: np.ndarray, RP: np.ndarray, W: np.ndarray, i: int, v: float) -> None:
    """A wheel speed v [m/s] for row i: z = (1 + k_v) v, linearised at the mean, of
    variance ``r_v + (rel_sigma v)^2`` (``CtraEkf.observe_speed``)."""
    rel = RP[i, REL] * v
    vs, g = S[i, 3], 1.0 + S[i, 9]
    for q in range(10):
        W[q] = g * S[i, P + 10 * q + 3] + vs * S[i, P + 10 * q + 9]
    W[WS] = g * W[3] + vs * W[9] + RP[i, R_V] + rel * rel
    linear_update(S, W, i, 1, (v - g * vs, 0.0, 0.0))


@kernel
def _init_row(
    S: np.ndarray,
    RP: np.ndarray,
    i: int,
    t: float,
    x: float,
    y: float,
    yaw: float,
    v: float,
    var_yaw: float,
    var_v: float,
    r: float,
) -> None:
    """``CtraEkf._init``: at (x, y) [m], heading yaw [rad], speed v [m/s], time t [s]."""
    for k in range(P + 100):  # the mean and the covariance
        S[i, k] = 0.0
    S[i, 0], S[i, 1], S[i, 2], S[i, 3] = x, y, _wrap(yaw), v
    diag = (r, r, var_yaw, var_v, VAR_W0, VAR_A0, RP[i, VBA0], RP[i, VBW0], RP[i, VBY0])
    for k in range(9):
        S[i, P + 11 * k] = diag[k]
    S[i, P + 99] = RP[i, VKV0]
    S[i, TS] = t
    S[i, READY] = 1.0


@kernel
def _try_init(
    S: np.ndarray, RP: np.ndarray, CF: np.ndarray, i: int, t: float, x: float, y: float, r: float
) -> None:
    """``CtraEkf._try_init``: at a fix when an IMU yaw is known, else at the second fix."""
    sp = S[i, SPEED_MEAS]
    v_known = math.isfinite(sp)
    v0 = sp if v_known else 0.0
    var_v = RP[i, R_V] if v_known else CF[VAR_V0]
    if math.isfinite(S[i, YAW_MEAS]):
        _init_row(S, RP, i, t, x, y, S[i, YAW_MEAS], v0, RP[i, R_YAW], var_v, r)
        return
    t0, x0, y0 = S[i, FIX], S[i, FIX + 1], S[i, FIX + 2]
    S[i, FIX], S[i, FIX + 1], S[i, FIX + 2] = t, x, y
    if not t > t0:
        return
    d = math.hypot(x - x0, y - y0)
    var_yaw = min(4.0 * r / (d * d), PI2) if d > 0 else PI2
    if not v_known:
        v0 = d / (t - t0)
        var_v = 2.0 * r / ((t - t0) * (t - t0)) + 1.0
    _init_row(S, RP, i, t, x, y, math.atan2(y - y0, x - x0), v0, var_yaw, var_v, r)


@kernel
def fix_rows(
    S: np.ndarray,
    RP: np.ndarray,
    CF: np.ndarray,
    W: np.ndarray,
    n: int,
    t: float,
    x: float,
    y: float,
    r: float,
    scores: np.ndarray,
    keep: float,
) -> int:
    """A finite fix (x, y) [m] at t [s] weighed with r [m^2] per axis for rows 0..n-1 (the
    members), as :func:`~posbench.predictors.kalman.ca_rows.fix_rows` (innovation, likelihood,
    update, scores; returns the best row or -1); a row not yet initialised tries to
    (``CtraEkf._try_init``) and leaves the scores as they stand."""
    k = CF[HUBER_K]
    for i in range(n):
        if S[i, READY] == 0.0:
            _try_init(S, RP, CF, i, t, x, y, r)
            S[i, LL] = math.nan
            continue
        predict(S, RP, CF, i, t)
        update_fix(S, W, i, x, y, r)
        ex, ey = S[i, INNOV], S[i, INNOV + 1]
        a, b, d = S[i, INNOV + 2], S[i, INNOV + 3], S[i, INNOV + 4]
        S[i, LL] = huber_log_likelihood(ex, ey, a, b, d, k)
    return update_scores(S, n, LL, scores, keep)


@kernel
def imu_rows(
    S: np.ndarray,
    RP: np.ndarray,
    CF: np.ndarray,
    W: np.ndarray,
    hi: int,
    t: float,
    ax: float,
    yaw: float,
    yaw_rate: float,
) -> None:
    """An IMU sample (longitudinal ax [m/s^2], yaw [rad], yaw rate [rad/s]) at t [s] for
    the rows 0..hi-1 that take the IMU (``CtraEkf.observe_imu``)."""
    for i in range(hi):
        if RP[i, HAS_IMU] == 0.0:
            continue
        use_yaw = RP[i, USE_YAW] != 0.0
        if S[i, READY] == 0.0:
            if use_yaw and math.isfinite(yaw):
                S[i, YAW_MEAS] = yaw
            continue
        predict(S, RP, CF, i, t)
        update_imu(S, RP, W, i, yaw_rate, ax, yaw if use_yaw else math.nan)


@kernel
def speed_rows(
    S: np.ndarray, RP: np.ndarray, CF: np.ndarray, W: np.ndarray, hi: int, t: float, v: float
) -> None:
    """A finite wheel speed v [m/s] at t [s] for the rows 0..hi-1 that take it
    (``CtraEkf.observe_speed``: z = (1 + k_v) v, linearised)."""
    for i in range(hi):
        if RP[i, HAS_SPEED] == 0.0:
            continue
        if S[i, READY] == 0.0:
            S[i, SPEED_MEAS] = v
            continue
        predict(S, RP, CF, i, t)
        update_speed(S, RP, W, i, v)


@kernel
def position(S: np.ndarray, i: int, t: float) -> tuple[float, float]:
    """Row i's answer for t [s] (``CtraEkf.position_at``): the CTRA extrapolation of its
    mean, or before initialisation the newest fix held (NaN: none)."""
    if S[i, READY] == 0.0:
        x, y = S[i, FIX + 1], S[i, FIX + 2]
        if x == x:
            return x, y
        return math.nan, math.nan
    x, y = S[i, 0], S[i, 1]
    T = t - S[i, TS]
    if not T > 0.0:
        return x, y
    dx, dy = ctra_displacement(S[i, 2], S[i, 3], S[i, 4], S[i, 5], T)
    return x + dx, y + dy


@kernel
def covariance(S: np.ndarray, RP: np.ndarray, CF: np.ndarray, i: int, t: float) -> tuple:
    """(P_xx, P_xy, P_yy) [m^2] of row i (initialised) at t [s], the filter's own part
    (``CtraEkf.covariance_at`` with ``cov_scale`` 1, before the slow part): the position
    rows of F P F' + Q(T) at the current mean, symmetrised."""
    T = t - S[i, TS]
    if not T > 0.0:
        return S[i, P], S[i, P + 1], S[i, P + 11]
    _, _, f02, f03, f04, f05, f12, f13, f14, f15, c, s = _jacobian(S, i, T)
    # rows 0, 1 of F P F' from P's top-left 6x6 block (F's rows 0, 1: e_0 + f0, e_1 + f1)
    f0 = (f02, f03, f04, f05)
    f1 = (f12, f13, f14, f15)
    m0 = [0.0] * 6  # rows 0, 1 of F P
    m1 = [0.0] * 6
    for col in range(6):
        a0, a1 = S[i, P + col], S[i, P + 10 + col]
        for k in range(4):
            pk = S[i, P + 10 * (k + 2) + col]
            a0 += f0[k] * pk
            a1 += f1[k] * pk
        m0[col], m1[col] = a0, a1
    o00, o01, o10, o11 = m0[0], m0[1], m1[0], m1[1]
    for k in range(4):
        o00 += m0[k + 2] * f0[k]
        o01 += m0[k + 2] * f1[k]
        o10 += m1[k + 2] * f0[k]
        o11 += m1[k + 2] * f1[k]
    q = ctra_noise_entries(c, s, T, RP[i, JERK], RP[i, YAWACC], CF[POS_PSD])
    o00 += q[0]
    o11 += q[1]
    o01 += q[2]
    o10 += q[3]
    return o00, 0.5 * (o01 + o10), o11


@kernel
def shadow_distances(S: np.ndarray, n: int, t: float, x: float, y: float, out: np.ndarray) -> bool:
    """Distances [m] of the shadows' (rows n..2n-1) answers for t [s] to (x, y) [m] into
    ``out``; whether every one is finite."""
    ok = True
    for j in range(n):
        px, py = position(S, n + j, t)
        out[j] = math.hypot(x - px, y - py)
        if not out[j] < math.inf:
            ok = False
    return ok
