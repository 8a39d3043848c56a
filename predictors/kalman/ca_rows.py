"""The kf bank's filters as rows of one array, stepped by compiled kernels (numba).

Why: a bank of 8 constant-acceleration filters (plus 8 shadows) as Python objects costs
8-16 Python calls per IMU sample, wheel speed and fix, ~40x constant velocity's step;
the arithmetic is ~200 flops per filter. Batched numpy does not help at this size (one
6x6 batched predict is ~7 us of numpy call overhead, against ~0.1 us compiled). So each
observation is one call to a compiled kernel that loops over the rows.

The motion model is :mod:`posbench.metrics.ca_model`'s (F and the white-jerk Q, written
once), compiled into these kernels; the updates are the tests' member objects
(tests/reference_filters: ``CaFilter2D``, ``LinearKalman``) written out per row, in the
same order of operations, so the rows answer as they do (the tests compare them on every
shared drive: tests/predictors/test_kf_batched.py).

Layout. Row state ``S[i]`` (float64): per-axis means ``mx = [x, vx, ax]`` at
:data:`MX`, ``my`` at :data:`MY` (m, m/s, m/s^2, ENU), the covariance blocks ``A``, ``B``
(six upper entries each) and ``C`` (nine, row-major) as in ``CaFilter2D``, the time of
the state :data:`TS` [s], the last heading used :data:`YAW` [rad] and its time, the time
of the previous IMU sample, the adapted IMU innovation power :data:`IMU_M2`
[m^2/s^4], and the newest fix's innovation ``(nu_x, nu_y, S_xx, S_xy, S_yy)`` at
:data:`INNOV` with its robust log-likelihood at :data:`LL`. Row parameters ``RP[i]``:
white-jerk density [m^2/s^5], whether the row takes the IMU, whether it takes the speed.
Options ``CF``: see :data:`CF_NAMES`.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.metrics.ca_model import ca_noise_entries, ca_predict_block, ca_predict_cross
from posbench.predictors._kernels import huber_log_likelihood, kernel, update_scores
from posbench.predictors.kalman.inputs import stopped

MX, MY, A, B, C = 0, 3, 6, 12, 18
TS, YAW, YAW_T, IMU_T, IMU_M2 = 27, 28, 29, 30, 31
INNOV, LL = 32, 37
#: columns of a row's state
NS = 38
PSD, HAS_IMU, HAS_SPEED = 0, 1, 2
#: columns of a row's parameters
NP = 3
#: the options array ``CF``, in order: IMU acceleration variance [m^2/s^4], wheel speed
#: variance [m^2/s^2] and relative sigma, stop speed [m/s], heading min speed [m/s],
#: IMU gate, IMU noise time constant [s], robust IMU update (0/1), course heading (0/1),
#: Huber k of the fix likelihood
CF_NAMES = (
    "r_acc",
    "r_spd",
    "rel_sigma",
    "stop_speed",
    "min_speed",
    "gate",
    "noise_tau_s",
    "robust",
    "course",
    "huber_k",
)
R_ACC, R_SPD, REL_SIGMA, STOP_SPEED, MIN_SPEED, GATE, NOISE_TAU, ROBUST, COURSE, HUBER_K = range(10)


def new_rows(n: int) -> np.ndarray:
    """State of ``n`` rows, none started (NaN times and headings)."""
    S = np.zeros((n, NS))
    S[:, TS] = S[:, YAW] = S[:, YAW_T] = S[:, IMU_T] = math.nan
    return S


@kernel
def _sym_entry(k: int, j: int) -> int:
    # entries of a symmetric 3x3 block in storage order (CaFilter2D._SYM)
    if k == 0:
        return j
    if k == 1:
        return (1, 3, 4)[j]
    return (2, 4, 5)[j]


#: the CA model's maths (:mod:`posbench.metrics.ca_model`), compiled
_noise = kernel(ca_noise_entries)
_predict_block = kernel(ca_predict_block)
_predict_cross = kernel(ca_predict_cross)
#: the standstill rule (:func:`~posbench.predictors.kalman.inputs.stopped`), compiled
_stopped = kernel(stopped)


@kernel
def predict(S: np.ndarray, i: int, t: float, psd: float) -> None:
    """Row i to time t [s] (``LinearKalman._predict_to``: only forward)."""
    d = t - S[i, TS]
    if not d > 0.0:
        return
    h = 0.5 * d * d
    p, v, a = S[i, 0], S[i, 1], S[i, 2]
    S[i, 0] = p + d * v + h * a
    S[i, 1] = v + d * a
    p, v, a = S[i, 3], S[i, 4], S[i, 5]
    S[i, 3] = p + d * v + h * a
    S[i, 4] = v + d * a
    q = _noise(d, psd)
    for o in (A, B):
        m = (S[i, o], S[i, o + 1], S[i, o + 2], S[i, o + 3], S[i, o + 4], S[i, o + 5])
        m = _predict_block(m, d, h, q)
        for k in range(6):
            S[i, o + k] = m[k]
    c = (
        S[i, C],
        S[i, C + 1],
        S[i, C + 2],
        S[i, C + 3],
        S[i, C + 4],
        S[i, C + 5],
        S[i, C + 6],
        S[i, C + 7],
        S[i, C + 8],
    )
    c = _predict_cross(c, d, h)
    for k in range(9):
        S[i, C + k] = c[k]
    S[i, TS] = t


@kernel
def _update(
    S: np.ndarray,
    i: int,
    x0: float,
    x1: float,
    x2: float,
    y0: float,
    y1: float,
    y2: float,
    s: float,
    innov: float,
) -> None:
    """Scalar update of row i given ph = P h per axis, s = h'Ph + r, z - h'x
    (``CaFilter2D._update``)."""
    w = 1.0 / s
    g = innov * w
    S[i, 0] += x0 * g
    S[i, 1] += x1 * g
    S[i, 2] += x2 * g
    S[i, 3] += y0 * g
    S[i, 4] += y1 * g
    S[i, 5] += y2 * g
    u0, u1, u2 = x0 * w, x1 * w, x2 * w
    v0, v1, v2 = y0 * w, y1 * w, y2 * w
    S[i, A] -= u0 * x0
    S[i, A + 1] -= u0 * x1
    S[i, A + 2] -= u0 * x2
    S[i, A + 3] -= u1 * x1
    S[i, A + 4] -= u1 * x2
    S[i, A + 5] -= u2 * x2
    S[i, B] -= v0 * y0
    S[i, B + 1] -= v0 * y1
    S[i, B + 2] -= v0 * y2
    S[i, B + 3] -= v1 * y1
    S[i, B + 4] -= v1 * y2
    S[i, B + 5] -= v2 * y2
    S[i, C] -= u0 * y0
    S[i, C + 1] -= u0 * y1
    S[i, C + 2] -= u0 * y2
    S[i, C + 3] -= u1 * y0
    S[i, C + 4] -= u1 * y1
    S[i, C + 5] -= u1 * y2
    S[i, C + 6] -= u2 * y0
    S[i, C + 7] -= u2 * y1
    S[i, C + 8] -= u2 * y2


@kernel
def update_pair(S: np.ndarray, i: int, k: int, zx: float, zy: float, r: float) -> None:
    """Component k (0 position, 1 velocity, 2 acceleration) of both axes, noise r I2
    (``CaFilter2D.update_pair``: x, then y)."""
    i0, i1, i2 = _sym_entry(k, 0), _sym_entry(k, 1), _sym_entry(k, 2)
    x0, x1, x2 = S[i, A + i0], S[i, A + i1], S[i, A + i2]
    y0, y1, y2 = S[i, C + 3 * k], S[i, C + 3 * k + 1], S[i, C + 3 * k + 2]
    px = (x0, x1, x2)
    _update(S, i, x0, x1, x2, y0, y1, y2, px[k] + r, zx - S[i, MX + k])
    x0, x1, x2 = S[i, C + k], S[i, C + 3 + k], S[i, C + 6 + k]
    y0, y1, y2 = S[i, B + i0], S[i, B + i1], S[i, B + i2]
    py = (y0, y1, y2)
    _update(S, i, x0, x1, x2, y0, y1, y2, py[k] + r, zy - S[i, MY + k])


@kernel
def update_speed(S: np.ndarray, i: int, c: float, s: float, z: float, r: float) -> None:
    """Speed z [m/s] along (c, s), noise r (``CaFilter2D.update_speed``)."""
    x0 = c * S[i, A + 1] + s * S[i, C + 1]
    x1 = c * S[i, A + 3] + s * S[i, C + 4]
    x2 = c * S[i, A + 4] + s * S[i, C + 7]
    y0 = c * S[i, C + 3] + s * S[i, B + 1]
    y1 = c * S[i, C + 4] + s * S[i, B + 3]
    y2 = c * S[i, C + 5] + s * S[i, B + 4]
    _update(S, i, x0, x1, x2, y0, y1, y2, c * x1 + s * y1 + r, z - c * S[i, 1] - s * S[i, 4])


@kernel
def init_rows(
    S: np.ndarray, n: int, t: float, x: float, y: float, r: float, vv: float, va: float
) -> None:
    """Rows 0..n-1 at rest at (x, y) [m], time t [s], covariance diagonal (r [m^2],
    vv [m^2/s^2], va [m^2/s^4] per axis) (``CaFilter2D.init``)."""
    for i in range(n):
        for j in range(TS):
            S[i, j] = 0.0
        S[i, 0] = x
        S[i, 3] = y
        for o in (A, B):
            S[i, o] = r
            S[i, o + 3] = vv
            S[i, o + 5] = va
        S[i, TS] = t


@kernel
def fix_one(
    S: np.ndarray, i: int, t: float, x: float, y: float, r: float, psd: float
) -> tuple[float, float]:
    """Row i, a fixes-only filter of white-jerk density psd [m^2/s^5], takes a fix (x, y)
    [m] at t [s] of variance r [m^2] per axis (predict, then ``update_pair`` of the
    position); returns its velocity (vx, vy) [m/s]."""
    predict(S, i, t, psd)
    update_pair(S, i, 0, x, y, r)
    return S[i, 1], S[i, 4]


@kernel
def fix_rows(
    S: np.ndarray,
    RP: np.ndarray,
    n: int,
    t: float,
    x: float,
    y: float,
    r: float,
    huber_k: float,
    scores: np.ndarray,
    keep: float,
) -> int:
    """A fix (x, y) [m] at t [s] weighed with r [m^2] per axis, for rows 0..n-1 (the
    members): predict, store the innovation and its robust log-likelihood
    (``ModelBank._log_likelihood``), update. Then the scores:
    ``keep`` x scores + likelihoods where every row scored; returns the best row, or -1
    when not every row scored (the scores stand)."""
    for i in range(n):
        predict(S, i, t, RP[i, PSD])
        ex = x - S[i, 0]
        ey = y - S[i, 3]
        a = S[i, A] + r
        b = S[i, C]
        d = S[i, B] + r
        S[i, INNOV] = ex
        S[i, INNOV + 1] = ey
        S[i, INNOV + 2] = a
        S[i, INNOV + 3] = b
        S[i, INNOV + 4] = d
        S[i, LL] = huber_log_likelihood(ex, ey, a, b, d, huber_k)
        update_pair(S, i, 0, x, y, r)
    return update_scores(S, n, LL, scores, keep)


@kernel
def _row_heading(
    S: np.ndarray, i: int, t: float, yaw: float, yaw_rate: float, min_speed: float
) -> float:
    """``LinearKalman._heading``: the IMU's yaw, else the velocity's direction above
    ``min_speed``, else the last heading advanced by the yaw rate, else the last."""
    if math.isfinite(yaw):
        return yaw
    vx, vy = S[i, 1], S[i, 4]
    if math.hypot(vx, vy) > min_speed:
        return math.atan2(vy, vx)
    if math.isfinite(S[i, YAW]) and math.isfinite(yaw_rate):
        return S[i, YAW] + yaw_rate * (t - S[i, YAW_T])
    return S[i, YAW]


@kernel
def update_accel(
    S: np.ndarray, CF: np.ndarray, i: int, t: float, h: float, ax: float, ay: float, bias: tuple
) -> None:
    """Row i takes the vehicle-frame acceleration (ax, ay) [m/s^2] turned to ENU by the
    heading h [rad] (``LinearKalman.observe_imu``). Robust (``CF[ROBUST]``): less the bias
    (bx, by) [m/s^2], its noise floored by the adapted innovation power (time constant
    ``CF[NOISE_TAU]``), skipped when its innovation is beyond the gate."""
    c, s = math.cos(h), math.sin(h)
    r = CF[R_ACC]
    if not CF[ROBUST] > 0.0:
        update_pair(S, i, 2, c * ax - s * ay, s * ax + c * ay, r)
        return
    mx, my = ax - bias[0], ay - bias[1]
    pax, pay = S[i, 2], S[i, 5]
    nx = mx - (c * pax + s * pay)
    ny = my - (-s * pax + c * pay)
    pa = 0.5 * (S[i, A + 5] + S[i, B + 5])
    dt = t - S[i, IMU_T]
    dt = min(dt, 0.5) if dt > 0.0 else 0.0
    m2 = 0.5 * (nx * nx + ny * ny)
    tau = CF[NOISE_TAU]
    if tau > 0.0:
        S[i, IMU_M2] += min(dt / tau, 1.0) * (m2 - S[i, IMU_M2])
        floor = S[i, IMU_M2] - pa
        if floor > r:
            r = floor
    gate = CF[GATE]
    if not (gate > 0.0 and 2.0 * m2 > gate * (pa + r)):
        update_pair(S, i, 2, c * mx - s * my, s * mx + c * my, r)


@kernel
def imu_rows(
    S: np.ndarray,
    RP: np.ndarray,
    CF: np.ndarray,
    hi: int,
    n: int,
    t: float,
    ax: float,
    ay: float,
    yaw: float,
    yaw_rate: float,
    courses: tuple,
    biases: tuple,
) -> tuple[float, float]:
    """An IMU sample (vehicle-frame ax, ay [m/s^2], yaw [rad], yaw rate [rad/s]) at t [s]
    for the rows 0..hi-1 that take the IMU (``LinearKalman.observe_imu`` after its first
    fix): predict, the heading (:func:`_row_heading`, or the course tracker's of
    ``courses`` when there is no yaw), :func:`update_accel`. ``courses`` (members',
    shadows') [rad] and ``biases`` ((bx, by) of each) [m/s^2]: rows at and above ``n``
    are shadows. Returns the heading used by the first IMU row of the members and of the
    shadows (NaN where none), for the bias estimators."""
    use_course = CF[COURSE] > 0.0 and not math.isfinite(yaw)
    accel = math.isfinite(ax) and math.isfinite(ay)
    used = [math.nan, math.nan]
    first = [True, True]
    for i in range(hi):
        if RP[i, HAS_IMU] == 0.0:
            continue
        predict(S, i, t, RP[i, PSD])
        group = 1 if i >= n else 0
        if use_course:
            h = courses[group]
        else:
            h = _row_heading(S, i, t, yaw, yaw_rate, CF[MIN_SPEED])
        S[i, YAW] = h
        S[i, YAW_T] = t
        if first[group]:
            used[group], first[group] = h, False
        if accel and math.isfinite(h):
            update_accel(S, CF, i, t, h, ax, ay, biases[group])
        S[i, IMU_T] = t
    return used[0], used[1]


@kernel
def speed_rows(
    S: np.ndarray,
    RP: np.ndarray,
    CF: np.ndarray,
    hi: int,
    n: int,
    t: float,
    v: float,
    imu_yaw: bool,
    courses: tuple,
) -> None:
    """A wheel speed v [m/s] at t [s] for the rows 0..hi-1 that take it
    (``LinearKalman.observe_speed`` after its first fix; shadows and ``courses`` as in
    :func:`imu_rows`): at a standstill zero velocity, else the speed along the heading
    (:func:`update_speed`) of variance ``r_spd + (rel_sigma v)^2`` [m^2/s^2]."""
    r_spd = CF[R_SPD]
    rel = CF[REL_SIGMA] * v
    r_v = r_spd + rel * rel
    for i in range(hi):
        if RP[i, HAS_SPEED] == 0.0:
            continue
        predict(S, i, t, RP[i, PSD])
        if _stopped(v, CF[STOP_SPEED]):
            update_pair(S, i, 1, 0.0, 0.0, r_spd)
            continue
        if CF[COURSE] > 0.0 and not imu_yaw:
            h = courses[1 if i >= n else 0]
        else:
            h = S[i, YAW]
            vx, vy = S[i, 1], S[i, 4]
            if not math.isfinite(h) and math.hypot(vx, vy) > CF[MIN_SPEED]:
                h = math.atan2(vy, vx)
        if math.isfinite(h):
            update_speed(S, i, math.cos(h), math.sin(h), v, r_v)


@kernel
def positions(S: np.ndarray, rows: tuple, times: tuple, out: np.ndarray) -> None:
    """Row ``rows[k]``'s position at ``times[k]`` [s] into ``out[k]`` [m, ENU], for each k:
    its constant-acceleration extrapolation (``KalmanBank.position_at``'s arithmetic)."""
    for k in range(len(times)):
        i = rows[k]
        dt = times[k] - S[i, TS]
        h = 0.5 * dt * dt
        out[k, 0] = S[i, 0] + S[i, 1] * dt + S[i, 2] * h
        out[k, 1] = S[i, 3] + S[i, 4] * dt + S[i, 5] * h


@kernel
def shadow_distances(S: np.ndarray, n: int, t: float, x: float, y: float, out: np.ndarray) -> bool:
    """Distances [m] of the shadows' (rows n..2n-1) answers for t [s] to (x, y) [m] into
    ``out``; whether every one is finite."""
    ok = True
    for j in range(n):
        i = n + j
        d = t - S[i, TS]
        h = 0.5 * d * d
        px = S[i, 0] + S[i, 1] * d + S[i, 2] * h
        py = S[i, 3] + S[i, 4] * d + S[i, 5] * h
        out[j] = math.hypot(x - px, y - py)
        if not out[j] < math.inf:
            ok = False
    return ok
