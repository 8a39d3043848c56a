"""The ekf bank's filters as rows of one array, stepped by compiled kernels (numba).

Why: a bank of 8 CTRA EKFs (plus 8 shadows) as Python objects costs 8-16 Python calls,
each a few 10x10 numpy products, per IMU sample, wheel speed and fix (a fix step ~180 us,
~90x constant velocity's). So each observation is one call to a compiled kernel that
loops over the rows, as :mod:`~posbench.predictors.kalman.ca_rows` does for the kf bank.

The motion model is :mod:`~posbench.predictors.kalman.ctra_model`'s, compiled into these
kernels (its integrals, step and Jacobian, and process noise: written once); the
covariance algebra and the updates are the tests' member objects (tests/reference_filters:
``CtraEkf``) written out per row in the same order of operations, rounding included:
where the members multiply matrices with numpy (BLAS: each entry a
chain of fused multiply-adds in index order; here those of OpenBLAS's kernels for this
CPU) the rows take the same fused chains (:func:`_fma`), skipping only the Jacobian's
zeros, which add nothing; squares the members take as ``x ** 2`` go through libm's pow
and distances through CPython's hypot (:func:`~posbench.predictors._kernels.hypot`). So
the rows answer as the member objects do, to the bit where BLAS rounds as here
(tests/predictors/test_ekf_batched.py, on every shared drive). That matters: a member
that loses its heading (a fixes-only filter at a standstill) amplifies a difference in
the last bit ~10x a second.

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
from typing import Any

import numpy as np

from posbench.predictors._kernels import (
    fused_multiply_add,
    huber_log_likelihood,
    hypot,
    kernel,
    update_scores,
)
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
#: fix likelihood, and 2.0: the exponent of the members' ``x ** 2`` (libm's pow, now and
#: then not x * x in the last bit; a constant exponent would be compiled into x * x)
CF_NAMES = ("pos_psd", "calib_psd", "var_v0", "huber_k", "two")
POS_PSD, CALIB_PSD, VAR_V0, HUBER_K, TWO = range(5)
#: floats of the work buffer
NW = 80

TWO_PI = 2.0 * math.pi  # as predictors/_geometry.py
PI2 = math.pi**2
VAR_W0 = 0.3**2  # the prior yaw rate and acceleration variances of CtraEkf._init
VAR_A0 = 2.0**2
#: the two states an IMU channel (yaw rate, accel, yaw) measures the sum of: yaw_rate +
#: b_w, a + b_a, yaw + b_y
IMU_J, IMU_B = (4, 5, 2), (7, 6, 8)


def new_rows(n: int) -> np.ndarray:
    """State of ``n`` rows, none initialised (``CtraEkf.reset``)."""
    S = np.zeros((n, NS))
    for k in range(10):
        S[:, P + 11 * k] = 1.0
    S[:, TS] = math.nan
    S[:, FIX : FIX + 3] = math.nan
    S[:, YAW_MEAS] = S[:, SPEED_MEAS] = math.nan
    return S


#: a * b + c rounded once (LLVM's fma: the instruction, where the CPU has one), as BLAS
#: computes the products numpy hands it; made by :func:`_numba_setup`
_fma: Any = None


def _numba_setup() -> None:
    """:data:`_fma`, made when this module's kernels are compiled."""
    global _fma
    _fma = fused_multiply_add()


@kernel
def _wrap(a: float) -> float:
    return (a + math.pi) % TWO_PI - math.pi


@kernel
def _jacobian(S: np.ndarray, i: int, T: float) -> tuple[float, ...]:
    """:func:`~posbench.predictors.kalman.ctra_model.ctra_motion` at row i's mean over T [s]."""
    return ctra_motion(S[i, 2], S[i, 3], S[i, 4], S[i, 5], T)


@kernel
def _predict(S: np.ndarray, RP: np.ndarray, CF: np.ndarray, i: int, t: float) -> None:
    """Row i to time t [s] (``CtraEkf._predict_to``: only forward): the CTRA step, then
    P = F P F' + Q, symmetrised."""
    T = t - S[i, TS]
    if not T > 0.0:
        return
    dx, dy, f02, f03, f04, f05, f12, f13, f14, f15, c, s = _jacobian(S, i, T)
    yaw, v, w, a = S[i, 2], S[i, 3], S[i, 4], S[i, 5]
    S[i, 0] += dx
    S[i, 1] += dy
    S[i, 2] = _wrap(yaw + w * T)
    S[i, 3] = v + a * T
    # F P in place (numpy's dot: BLAS, each entry a chain of fused multiply-adds over F's
    # row in order, zeros adding nothing): rows 0 and 1 read the old rows 2-5, then 2 and 3
    for j in range(10):
        p2, p3 = S[i, P + 20 + j], S[i, P + 30 + j]
        p4, p5 = S[i, P + 40 + j], S[i, P + 50 + j]
        acc = _fma(f02, p2, S[i, P + j])
        S[i, P + j] = _fma(f05, p5, _fma(f04, p4, _fma(f03, p3, acc)))
        acc = _fma(f12, p2, S[i, P + 10 + j])
        S[i, P + 10 + j] = _fma(f15, p5, _fma(f14, p4, _fma(f13, p3, acc)))
        S[i, P + 20 + j] = _fma(T, p4, p2)
        S[i, P + 30 + j] = _fma(T, p5, p3)
    # (F P) F' in place, by columns alike
    for r in range(10):
        o = P + 10 * r
        q2, q3, q4, q5 = S[i, o + 2], S[i, o + 3], S[i, o + 4], S[i, o + 5]
        acc = _fma(q2, f02, S[i, o])
        S[i, o] = _fma(q5, f05, _fma(q4, f04, _fma(q3, f03, acc)))
        acc = _fma(q2, f12, S[i, o + 1])
        S[i, o + 1] = _fma(q5, f15, _fma(q4, f14, _fma(q3, f13, acc)))
        S[i, o + 2] = _fma(q4, T, q2)
        S[i, o + 3] = _fma(q5, T, q3)
    # + Q (ctra.ctra_process_noise at the heading before the step, and the sensor states)
    q = ctra_noise_entries(c, s, T, RP[i, JERK], RP[i, YAWACC], CF[POS_PSD])
    # Q_ENTRIES' places, written out: constant indices into the tuple
    S[i, P + 0] += q[0]
    S[i, P + 11] += q[1]
    S[i, P + 1] += q[2]
    S[i, P + 10] += q[3]
    S[i, P + 3] += q[4]
    S[i, P + 30] += q[5]
    S[i, P + 13] += q[6]
    S[i, P + 31] += q[7]
    S[i, P + 5] += q[8]
    S[i, P + 50] += q[9]
    S[i, P + 15] += q[10]
    S[i, P + 51] += q[11]
    S[i, P + 33] += q[12]
    S[i, P + 35] += q[13]
    S[i, P + 53] += q[14]
    S[i, P + 55] += q[15]
    S[i, P + 22] += q[16]
    S[i, P + 24] += q[17]
    S[i, P + 42] += q[18]
    S[i, P + 44] += q[19]
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
def _gain(S: np.ndarray, W: np.ndarray, i: int, s: float, innov: float) -> None:
    """Scalar update of row i given ph = P h' in W[0:10], s = h P h' + r and the innovation
    (``CtraEkf._gain``)."""
    w = 1.0 / s
    for r in range(10):
        W[10 + r] = W[r] * w
    for r in range(10):
        S[i, r] += W[10 + r] * innov
    for a in range(10):
        ka = W[10 + a]
        for b in range(10):
            S[i, P + 10 * a + b] -= ka * W[b]


@kernel
def _update_fix(S: np.ndarray, W: np.ndarray, i: int, zx: float, zy: float, r: float) -> None:
    """The 2-D fix update of row i with S^-1 in closed form (``CtraEkf._update_position``);
    stores the innovation and its covariance at :data:`INNOV`."""
    s00, s01, s11 = S[i, P] + r, S[i, P + 1], S[i, P + 11] + r
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    e0, e1 = zx - S[i, 0], zy - S[i, 1]
    S[i, INNOV] = e0
    S[i, INNOV + 1] = e1
    S[i, INNOV + 2] = s00
    S[i, INNOV + 3] = s01
    S[i, INNOV + 4] = s11
    for k in range(10):  # ph = P[:, :2], K = ph S^-1 (BLAS: fused, in order)
        p0, p1 = S[i, P + 10 * k], S[i, P + 10 * k + 1]
        W[k], W[10 + k] = p0, p1
        W[20 + k] = _fma(p1, i01, p0 * i00)
        W[30 + k] = _fma(p1, i11, p0 * i01)
    for k in range(10):  # x += K e (BLAS gemv: the second term first)
        S[i, k] += _fma(W[20 + k], e0, W[30 + k] * e1)
    for a in range(10):  # P -= K ph'
        k0, k1 = W[20 + a], W[30 + a]
        for b in range(10):
            S[i, P + 10 * a + b] -= _fma(k1, W[10 + b], k0 * W[b])


@kernel
def _update_imu(
    S: np.ndarray, RP: np.ndarray, W: np.ndarray, i: int, yaw_rate: float, ax: float, yaw: float
) -> None:
    """The finite ones of yaw rate, ax and yaw (innovation wrapped) for row i: one scalar
    update, or one joint update with S^-1 in closed form (``CtraEkf._update_imu``)."""
    z = (yaw_rate, ax, yaw)
    rr = (RP[i, R_W], RP[i, R_A], RP[i, R_YAW])
    sel = [0, 0, 0]
    m = 0
    for k in range(3):
        if math.isfinite(z[k]):
            sel[m] = k
            m += 1
    if m == 0:
        return
    if m == 1:  # _update_sum / _update_yaw_offset
        k = sel[0]
        j, b = IMU_J[k], IMU_B[k]
        for q in range(10):
            W[q] = S[i, P + 10 * q + j] + S[i, P + 10 * q + b]
        innov = z[k] - S[i, j] - S[i, b]
        innov = _wrap(innov) if k == 2 else innov
        _gain(S, W, i, W[j] + W[b] + rr[k], innov)
        if k == 2:
            S[i, 2] = _wrap(S[i, 2])
        return
    # PHt (10 x m) at W[10 l + q], S (m x m) with R on its diagonal, the innovations
    Sm = np.zeros((3, 3))
    e = [0.0, 0.0, 0.0]
    for col in range(m):
        j, b = IMU_J[sel[col]], IMU_B[sel[col]]
        for q in range(10):
            W[10 * col + q] = S[i, P + 10 * q + j] + S[i, P + 10 * q + b]
        e[col] = z[sel[col]] - S[i, j] - S[i, b]
    for row in range(m):
        j, b = IMU_J[sel[row]], IMU_B[sel[row]]
        for col in range(m):
            Sm[row, col] = W[10 * col + j] + W[10 * col + b]
        Sm[row, row] += rr[sel[row]]
    has_yaw = sel[m - 1] == 2
    if has_yaw:
        e[m - 1] = _wrap(e[m - 1])
    Si = np.zeros((3, 3))  # ekf._sym_inverse
    if m == 2:
        a, b, d = Sm[0, 0], Sm[0, 1], Sm[1, 1]
        det = a * d - b * b
        Si[0, 0], Si[0, 1], Si[1, 0], Si[1, 1] = d / det, -b / det, -b / det, a / det
    else:
        a, b, c = Sm[0, 0], Sm[0, 1], Sm[0, 2]
        d, ee, f = Sm[1, 1], Sm[1, 2], Sm[2, 2]
        A00, A01, A02 = d * f - ee * ee, c * ee - b * f, b * ee - c * d
        A11, A12, A22 = a * f - c * c, b * c - a * ee, a * d - b * b
        w = 1.0 / (a * A00 + b * A01 + c * A02)
        Si[0, 0], Si[0, 1], Si[0, 2] = A00 * w, A01 * w, A02 * w
        Si[1, 0], Si[1, 1], Si[1, 2] = A01 * w, A11 * w, A12 * w
        Si[2, 0], Si[2, 1], Si[2, 2] = A02 * w, A12 * w, A22 * w
    for q in range(10):  # K = PHt S^-1 at W[40 + 10 c + q] (BLAS: fused, in order)
        for c in range(m):
            acc = W[q] * Si[0, c]
            for k in range(1, m):
                acc = _fma(W[10 * k + q], Si[k, c], acc)
            W[40 + 10 * c + q] = acc
    for q in range(10):  # x += K e (BLAS gemv: the second term, the first, the third)
        acc = _fma(W[40 + q], e[0], W[50 + q] * e[1])
        if m == 3:
            acc = _fma(W[60 + q], e[2], acc)
        S[i, q] += acc
    for a in range(10):  # P -= K PHt'
        for b in range(10):
            acc = W[40 + a] * W[b]
            for c in range(1, m):
                acc = _fma(W[40 + 10 * c + a], W[10 * c + b], acc)
            S[i, P + 10 * a + b] -= acc
    if has_yaw:
        S[i, 2] = _wrap(S[i, 2])


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
    d = hypot(x - x0, y - y0)
    var_yaw = min(4.0 * r / (d * d), PI2) if d > 0 else PI2
    if not v_known:
        v0 = d / (t - t0)
        var_v = 2.0 * r / (t - t0) ** CF[TWO] + 1.0
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
        _predict(S, RP, CF, i, t)
        _update_fix(S, W, i, x, y, r)
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
        _predict(S, RP, CF, i, t)
        _update_imu(S, RP, W, i, yaw_rate, ax, yaw if use_yaw else math.nan)


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
        _predict(S, RP, CF, i, t)
        r = RP[i, R_V] + (RP[i, REL] * v) ** CF[TWO]
        vs, g = S[i, 3], 1.0 + S[i, 9]
        for q in range(10):
            W[q] = g * S[i, P + 10 * q + 3] + vs * S[i, P + 10 * q + 9]
        _gain(S, W, i, g * W[3] + vs * W[9] + r, v - g * vs)


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
    f0 = (f02, f03, f04, f05)
    f1 = (f12, f13, f14, f15)
    m0 = [0.0] * 6  # rows 0, 1 of Fp P[:6, :6] (numpy's matmul: BLAS, fused, in order)
    m1 = [0.0] * 6
    for col in range(6):
        a0 = S[i, P + col]
        a1 = S[i, P + 10 + col]
        for k in range(4):
            pk = S[i, P + 10 * (k + 2) + col]
            a0 = _fma(f0[k], pk, a0)
            a1 = _fma(f1[k], pk, a1)
        m0[col], m1[col] = a0, a1
    o00, o01, o10, o11 = m0[0], m0[1], m1[0], m1[1]
    for k in range(4):
        o00 = _fma(m0[k + 2], f0[k], o00)
        o01 = _fma(m0[k + 2], f1[k], o01)
        o10 = _fma(m1[k + 2], f0[k], o10)
        o11 = _fma(m1[k + 2], f1[k], o11)
    q = ctra_noise_entries(c, s, T, RP[i, JERK], RP[i, YAWACC], CF[POS_PSD])
    o00 += q[0]
    o11 += q[1]
    o01 += q[2]
    o10 += q[3]
    return 0.5 * (o00 + o00), 0.5 * (o01 + o10), 0.5 * (o11 + o11)


@kernel
def shadow_distances(S: np.ndarray, n: int, t: float, x: float, y: float, out: np.ndarray) -> bool:
    """Distances [m] of the shadows' (rows n..2n-1) answers for t [s] to (x, y) [m] into
    ``out``; whether every one is finite."""
    ok = True
    for j in range(n):
        px, py = position(S, n + j, t)
        out[j] = hypot(x - px, y - py)
        if not out[j] < math.inf:
            ok = False
    return ok
