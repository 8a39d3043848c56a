"""Extended Kalman filter with the CTRA model (constant turn rate and acceleration).

State ``[x, y, yaw, v, yaw_rate, a]``: ENU position [m], heading [rad, ENU], speed
along the heading [m/s], yaw rate [rad/s], longitudinal acceleration [m/s^2].

Prediction over T seconds (the CTRA closed form and its analytic Jacobian) and the process
noise (white jerk ``jerk_psd`` [m^2/s^5], white yaw acceleration ``yaw_acc_psd``
[rad^2/s^3], a position random walk ``pos_psd`` [m^2/s]) are
:mod:`posbench.predictors.kalman.ctra_model`.

Sensor biases: two more states, the accelerometer's longitudinal bias ``b_a`` [m/s^2]
(mounting pitch and gravity leakage: the comma2k19 segment's accelerometer reads about
-0.57 m/s^2 on average while the truth accelerates at +0.06) and the gyro's yaw-rate
bias ``b_w`` [rad/s], each a slow random walk (``accel_bias_psd``, ``gyro_bias_psd``).
Two more calibrate the absolute sensors against the GNSS track: an IMU yaw offset ``b_y``
[rad] (heading sensors disagree with the track by up to ~0.1 rad on KITTI) and a wheel-
speed scale error ``k_v`` (KITTI's vf reads ~2.5 % high), with IMU yaw = yaw + b_y and
wheel speed = (1 + k_v) v. All four are observable through the GNSS updates.

Updates (all scalar, sequential; R diagonal): GNSS x and y; IMU yaw rate (= yaw_rate +
b_w); IMU longitudinal acceleration ax (= a + b_a); IMU yaw when finite (innovation wrapped to
[-pi, pi)); wheel/CAN speed (= v). Missing values (NaN) skip their update.

Initialisation: at a fix when an IMU yaw is known (speed from the wheel speed when
given), otherwise at the second fix with the heading of the two fixes and the speed of
their distance; before that the newest fix is held.

Implementation: a compact numpy/float implementation rather than a filterpy
``ExtendedKalmanFilter`` subclass. filterpy's ``update`` takes Jacobian callables,
inverts S as a matrix and copies priors/posteriors on every call; with IMU samples at
up to 100 Hz carrying three scalar measurements each, the scalar sequential updates
here cost a fraction of that (figures in tests/predictors/test_predictors_baselines.py timing).
The fix is one 2-D update with S^-1 in closed form, products go into preallocated
buffers and F, Q are written with one ``put`` each (a fix step ~20 -> ~12 us p50);
tests/predictors/test_filter_fastpath.py checks every state against filterpy's
``ExtendedKalmanFilter`` fed the same model.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from posbench.predictors._geometry import COV_SCALE_RANGE, check_config, wrap_angle
from posbench.predictors.base import Predictor
from posbench.predictors.kalman.copying import copy_attrs
from posbench.predictors.kalman.ctra_model import (
    IA,
    IBA,
    IBW,
    IBY,
    IKV,
    IV,
    IW,
    IX,
    IY,
    IYAW,
    N_STATE,
    ctra_displacement,
    ctra_process_noise,
    ctra_step,
)
from posbench.predictors.kalman.inputs import (
    EKF_FLAT,
    EKF_INPUTS,
    CtraImuInput,
    CtraSpeedInput,
    GnssInput,
)

NAN2 = (math.nan, math.nan)
#: the IMU's measurements as sums of two states: yaw rate, longitudinal accel, yaw
_IMU_SUMS = ((IW, IBW), (IA, IBA), (IYAW, IBY))


def _sym_inverse(S: list[list[float]]) -> list[list[float]]:
    """Inverse of a symmetric positive definite 2x2 or 3x3 matrix (nested lists), closed form."""
    if len(S) == 2:
        (a, b), (_, d) = S
        det = a * d - b * b
        return [[d / det, -b / det], [-b / det, a / det]]
    (a, b, c), (_, d, e), (_, _, f) = S
    A00, A01, A02 = d * f - e * e, c * e - b * f, b * e - c * d
    A11, A12, A22 = a * f - c * c, b * c - a * e, a * d - b * b
    w = 1.0 / (a * A00 + b * A01 + c * A02)
    return [[A00 * w, A01 * w, A02 * w], [A01 * w, A11 * w, A12 * w], [A02 * w, A12 * w, A22 * w]]


class CtraEkf(Predictor):
    """CTRA extended Kalman filter over GNSS, IMU yaw rate / accel / yaw and wheel speed.

    Composed of the CTRA motion model and its sensor inputs
    (:mod:`~posbench.predictors.kalman.inputs`); a fixes-only filter is ``imu=None,
    speed=None``.

    Args:
        jerk_psd: white-jerk spectral density [m^2/s^5].
        yaw_acc_psd: white yaw-acceleration spectral density [rad^2/s^3].
        pos_psd: position random-walk density [m^2/s].
        gnss: the fixes (:class:`~posbench.predictors.kalman.inputs.GnssInput`).
        imu: yaw rate, longitudinal acceleration and yaw with their biases
            (:class:`~posbench.predictors.kalman.inputs.CtraImuInput`); None: no IMU.
        speed: wheel speed with its scale error
            (:class:`~posbench.predictors.kalman.inputs.CtraSpeedInput`); None: no speed.
        init_vel_sigma: prior speed uncertainty [m/s] when initialised from IMU yaw only.
        calib_psd: random-walk density of the IMU yaw offset and the speed scale.
        cov_scale: calibration: ``covariance_at`` reports ``cov_scale`` x the filter's own
            covariance (1: as the model says); fitted on development drives by
            ``bench tune`` so that 95 % of the 95 % ellipses cover the truth. It never
            changes a position.
        **flat: the inputs' fields by their flat names (:data:`EKF_FLAT`: ``gps_sigma``,
            ``yaw_rate_sigma``, ``use_imu_yaw``, ``use_speed``, ...), as ``--set ekf.X``
            and tuning files give them.
    """

    name = "ekf"

    def __init__(
        self,
        jerk_psd: float = 2.0,
        yaw_acc_psd: float = 0.1,
        pos_psd: float = 0.01,
        *,
        gnss: GnssInput = EKF_INPUTS["gnss"],
        imu: CtraImuInput | None = EKF_INPUTS["imu"],
        speed: CtraSpeedInput | None = EKF_INPUTS["speed"],
        init_vel_sigma: float = 15.0,
        calib_psd: float = 1e-6,
        cov_scale: float = 1.0,
        **flat: Any,
    ) -> None:
        check_config(
            "ekf",
            jerk_psd=(jerk_psd, 1e-9, 1e6),
            yaw_acc_psd=(yaw_acc_psd, 1e-12, 1e6),
            pos_psd=(pos_psd, 0.0, 1e6),
            init_vel_sigma=(init_vel_sigma, 1e-3, 1e3),
            calib_psd=(calib_psd, 0.0, 1e6),
            cov_scale=(cov_scale, *COV_SCALE_RANGE),
        )
        inputs = EKF_FLAT.compose(
            "ekf", {"gnss": gnss, "imu": imu, "speed": speed}, EKF_INPUTS, flat
        )
        #: the sensor inputs (:mod:`~posbench.predictors.kalman.inputs`); None: not used
        self.gnss: GnssInput = inputs["gnss"]
        self.imu: CtraImuInput | None = inputs["imu"]
        self.speed: CtraSpeedInput | None = inputs["speed"]
        self._gnss = self.gnss.noise()
        self.jerk_psd = float(jerk_psd)
        self.yaw_acc_psd = float(yaw_acc_psd)
        self.pos_psd = float(pos_psd)
        self.init_vel_sigma = float(init_vel_sigma)
        self.calib_psd = float(calib_psd)
        self.cov_scale = float(cov_scale)
        # the calibration states exist without their sensor (unobserved): default priors
        imu_c = self.imu if self.imu is not None else EKF_INPUTS["imu"]
        spd_c = self.speed if self.speed is not None else EKF_INPUTS["speed"]
        self._imu_c: CtraImuInput = imu_c
        self._spd_c: CtraSpeedInput = spd_c
        self._r_fix = self.gnss.sigma**2  # R per axis [m^2] of the fix being observed
        self._r_w = imu_c.yaw_rate_sigma**2
        self._r_a = imu_c.accel_sigma**2
        self._r_yaw = imu_c.yaw_sigma**2
        self._r_v = spd_c.sigma**2
        self.x = np.zeros(N_STATE)
        self.P = np.eye(N_STATE)
        self._F = np.eye(N_STATE)
        self._Q = np.zeros((N_STATE, N_STATE))
        self._FP = np.empty((N_STATE, N_STATE))  # work buffers
        self._S2 = np.empty((2, 2))
        self._e2 = np.empty(2)
        r_imu = (self._r_w, self._r_a, self._r_yaw)
        # measurement rows and variances per set of finite IMU channels (their indices in z)
        self._H_imu: dict[tuple[int, ...], tuple[np.ndarray, tuple[float, ...]]] = {}
        for sel in ((0, 1), (0, 2), (1, 2), (0, 1, 2)):
            H = np.zeros((len(sel), N_STATE))
            for i, k in enumerate(sel):
                H[i, list(_IMU_SUMS[k])] = 1.0
            self._H_imu[sel] = (H, tuple(r_imu[k] for k in sel))
        self.reset()

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = (
        "gnss",
        "imu",
        "speed",
        "_gnss",
        "jerk_psd",
        "yaw_acc_psd",
        "pos_psd",
        "init_vel_sigma",
        "calib_psd",
        "cov_scale",
        "_imu_c",
        "_spd_c",
        "_r_fix",
        "_r_w",
        "_r_a",
        "_r_yaw",
        "_r_v",
        "x",
        "P",
        "_F",
        "_Q",
        "_FP",
        "_S2",
        "_e2",
        "_H_imu",
        "_ready",
        "_ts",
        "_s",
        "_fix",
        "_yaw_meas",
        "_speed_meas",
        "fix_innovation",
    )

    def __deepcopy__(self, memo: dict) -> CtraEkf:
        """An independent copy (a bank's shadows): its own mean, covariance and work
        buffers; the measurement rows (constant) shared."""
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        for name in ("x", "P", "_F", "_Q", "_FP", "_S2", "_e2"):
            setattr(new, name, getattr(self, name).copy())
        new._s = list(self._s)
        new._gnss = copy.deepcopy(self._gnss, memo)
        return new

    @classmethod
    def flat_options(cls) -> dict[str, Any]:
        """The flat option names and their defaults (for ``bench predictors`` and
        ``--set`` checks)."""
        return EKF_FLAT.flatten(EKF_INPUTS, EKF_INPUTS)

    @classmethod
    def flat_option_types(cls) -> dict[str, Any]:
        """The flat option names and their declared types (``--set`` parses by them)."""
        return EKF_FLAT.types(EKF_INPUTS)

    def config(self) -> dict:
        """The options in flat names (:data:`EKF_FLAT`), as ``CtraEkf(**config())`` takes
        them."""
        return {
            "jerk_psd": self.jerk_psd,
            "yaw_acc_psd": self.yaw_acc_psd,
            "pos_psd": self.pos_psd,
            "init_vel_sigma": self.init_vel_sigma,
            "calib_psd": self.calib_psd,
            "cov_scale": self.cov_scale,
            **EKF_FLAT.flatten(
                {"gnss": self.gnss, "imu": self.imu, "speed": self.speed}, EKF_INPUTS
            ),
        }

    def reset(self) -> None:
        self._ready = False
        self._ts = math.nan
        self._s = [math.nan] * N_STATE  # plain-float copy of the mean
        self._fix = (math.nan, math.nan, math.nan)  # newest fix before initialisation
        self._yaw_meas = math.nan  # latest IMU yaw before initialisation
        self._speed_meas = math.nan
        self.x.fill(0.0)
        self.P[:] = np.eye(N_STATE)
        self._gnss.reset()

    # -- filter core ---------------------------------------------------------------
    def _init(
        self, t: float, x: float, y: float, yaw: float, v: float, var_yaw: float, var_v: float
    ) -> None:
        self.x[:] = (x, y, wrap_angle(yaw), v, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        r = self._r_fix
        self.P[:] = np.diag(
            [
                r,
                r,
                var_yaw,
                var_v,
                0.3**2,
                2.0**2,
                self._imu_c.accel_bias_sigma0**2,
                self._imu_c.gyro_bias_sigma0**2,
                self._imu_c.yaw_offset_sigma0**2,
                self._spd_c.scale_sigma0**2,
            ]
        )
        self._ts = t
        self._ready = True
        self._s = self.x.tolist()

    def _predict_to(self, t: float) -> None:
        T = t - self._ts
        if not T > 0.0:
            return
        F = self._F
        ctra_step(self.x, T, F)
        Q = ctra_process_noise(
            self._s[IYAW], T, self.jerk_psd, self.yaw_acc_psd, self.pos_psd, self._Q
        )
        Q[IBA, IBA] = self._imu_c.accel_bias_psd * T
        Q[IBW, IBW] = self._imu_c.gyro_bias_psd * T
        Q[IBY, IBY] = Q[IKV, IKV] = self.calib_psd * T
        FP, P = self._FP, self.P
        np.dot(F, P, out=FP)
        np.dot(FP, F.T, out=P)
        P += Q
        np.add(P, P.T, out=FP)  # symmetrise: P = (P + P') / 2
        np.multiply(FP, 0.5, out=P)
        self._ts = t

    def _gain(self, ph: np.ndarray, s: float, innov: float) -> None:
        """Scalar update given ph = P h' (a new array or a view of P), s = h P h' + r and
        the innovation: x += K innov, P -= K ph' with the gain K = ph / s."""
        K = ph * (1.0 / s)
        self.x += K * innov
        self.P -= np.multiply.outer(K, ph)

    def _update_position(self, zx: float, zy: float) -> None:
        """GNSS fix (zx, zy) [m], noise r I2: the 2-D update with S^-1 in closed form
        (equal to the scalar updates of x then y)."""
        P, x, r = self.P, self.x, self._r_fix
        s00, s01, s11 = P.item(0, 0) + r, P.item(0, 1), P.item(1, 1) + r
        det = s00 * s11 - s01 * s01
        Si = self._S2
        Si[0, 0], Si[0, 1], Si[1, 0], Si[1, 1] = s11 / det, -s01 / det, -s01 / det, s00 / det
        ph = P[:, :2]
        K = np.dot(ph, Si)
        e = self._e2
        e[0], e[1] = zx - x.item(IX), zy - x.item(IY)
        self.fix_innovation = (e.item(0), e.item(1), s00, s01, s11)
        x += np.dot(K, e)
        P -= np.dot(K, ph.T)

    def _update_imu(self, yaw_rate: float, ax: float, yaw: float) -> None:
        """The IMU sample's measurements that are finite, yaw rate (= w + b_w), ax (= a + b_a)
        and yaw (= yaw + b_y, innovation wrapped), as one joint update with S^-1 in closed
        form (equal to the scalar updates in that order: H is linear, R diagonal)."""
        z = (yaw_rate, ax, yaw)
        sel = tuple(k for k in range(3) if math.isfinite(z[k]))
        if len(sel) < 2:
            if sel == (0,):
                self._update_sum(IW, IBW, yaw_rate, self._r_w)
            elif sel == (1,):
                self._update_sum(IA, IBA, ax, self._r_a)
            elif sel == (2,):
                self._update_yaw_offset(yaw)
            return
        H, r = self._H_imu[sel]
        P, x = self.P, self.x
        PHt = np.dot(P, H.T)  # (10, m)
        S = np.dot(H, PHt).tolist()
        xs = x.tolist()
        e = []
        for i, k in enumerate(sel):
            S[i][i] += r[i]
            j, b = _IMU_SUMS[k]
            e.append(z[k] - xs[j] - xs[b])
        if sel[-1] == 2:
            e[-1] = wrap_angle(e[-1])
        K = np.dot(PHt, np.array(_sym_inverse(S)))
        x += np.dot(K, e)
        P -= np.dot(K, PHt.T)
        if sel[-1] == 2:
            x[IYAW] = wrap_angle(x.item(IYAW))

    def _update_sum(self, j: int, k: int, z: float, r: float) -> None:
        """Scalar update with measurement z = x[j] + x[k] (a signal plus its sensor bias)."""
        P, x = self.P, self.x
        ph = P[:, j] + P[:, k]
        self._gain(ph, ph.item(j) + ph.item(k) + r, z - x.item(j) - x.item(k))

    def _update_yaw_offset(self, z: float) -> None:
        """IMU yaw z = yaw + b_y (innovation wrapped to [-pi, pi))."""
        P, x = self.P, self.x
        ph = P[:, IYAW] + P[:, IBY]
        self._gain(
            ph,
            ph.item(IYAW) + ph.item(IBY) + self._r_yaw,
            wrap_angle(z - x.item(IYAW) - x.item(IBY)),
        )
        x[IYAW] = wrap_angle(x.item(IYAW))

    def _update_speed(self, z: float, r: float) -> None:
        """Wheel speed z = (1 + k_v) v: linearised scalar update."""
        P, x = self.P, self.x
        v, g = x.item(IV), 1.0 + x.item(IKV)
        ph = g * P[:, IV] + v * P[:, IKV]
        self._gain(ph, g * ph.item(IV) + v * ph.item(IKV) + r, z - g * v)

    # -- observations ----------------------------------------------------------------
    def fix_variance(self, sigma: float | None) -> float:
        """R per axis [m^2] a fix stating per-axis 1-sigma ``sigma`` [m] is weighed with:
        its white part (:class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`); without
        ``fix_noise_memory`` ``(gps_sigma_scale * sigma)^2``, or ``gps_sigma^2`` when it
        states none (None, not finite, or <= 0)."""
        return self._gnss.parts(sigma)[0]

    #: the newest fix's innovation and its covariance before the update, ``(nu_x, nu_y,
    #: S_xx, S_xy, S_yy)`` [m, m^2]; None before the filter is initialised (read by
    #: :class:`~reference_filters.model_bank.ModelBank`)
    fix_innovation: tuple[float, float, float, float, float] | None = None

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        self.fix_innovation = None
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        self._gnss.observe(t, x, y)
        self._r_fix = self._gnss.weigh(sigma)  # this fix's R, read by _init / _update_position
        if not self._ready:
            self._try_init(t, x, y)
            return
        self._predict_to(t)
        self._update_position(x, y)
        self._s = self.x.tolist()

    def _try_init(self, t: float, x: float, y: float) -> None:
        v_known = math.isfinite(self._speed_meas)
        v0 = self._speed_meas if v_known else 0.0
        var_v = self._r_v if v_known else self.init_vel_sigma**2
        if math.isfinite(self._yaw_meas):
            self._init(t, x, y, self._yaw_meas, v0, self._r_yaw, var_v)
            return
        t0, x0, y0 = self._fix
        self._fix = (t, x, y)
        if not (t > t0):  # first fix (t0 NaN) or a repeated time stamp
            return
        d = math.hypot(x - x0, y - y0)
        r = self._r_fix
        var_yaw = min(4.0 * r / (d * d), math.pi**2) if d > 0 else math.pi**2
        if not v_known:
            v0 = d / (t - t0)
            var_v = 2.0 * r / (t - t0) ** 2 + 1.0
        self._init(t, x, y, math.atan2(y - y0, x - x0), v0, var_yaw, var_v)

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        imu = self.imu
        if imu is None:
            return
        if not self._ready:
            if imu.use_yaw and math.isfinite(yaw):
                self._yaw_meas = yaw
            return
        self._predict_to(t)
        self._update_imu(yaw_rate, ax, yaw if imu.use_yaw else math.nan)
        self._s = self.x.tolist()

    def observe_speed(self, t: float, v: float) -> None:
        speed = self.speed
        if not (speed is not None and math.isfinite(v)):
            return
        if not self._ready:
            self._speed_meas = v
            return
        self._predict_to(t)
        self._update_speed(v, self._r_v + (speed.rel_sigma * v) ** 2)
        self._s = self.x.tolist()

    def state(self) -> tuple[float, list[float], np.ndarray]:
        """(time [s], mean ``[x, y, yaw, v, yaw_rate, a, b_a, b_w, b_y, k_v]``, 10x10
        covariance) of the filter, NaN time before it is initialised. A copy."""
        return self._ts, self.x.tolist(), self.P.copy()

    @property
    def slow_variance(self) -> float:
        """The slow part [m^2] per axis of the newest fix's stated error, which
        ``covariance_at`` adds to the filter's own covariance (0 for a white receiver or
        one that states nothing; :class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`)."""
        return self._gnss.slow_var

    # -- query -------------------------------------------------------------------------
    def position_at(self, t: float) -> tuple[float, float]:
        if not self._ready:
            _, x, y = self._fix
            return (x, y) if x == x else NAN2
        x, y, yaw, v, w, a = self._s[:6]
        T = t - self._ts
        if not T > 0.0:
            return x, y
        dx, dy = ctra_displacement(yaw, v, w, a, T)
        return x + dx, y + dy

    def covariance_at(self, t: float) -> np.ndarray | None:
        """2x2 ENU position covariance [m^2] of ``position_at(t)``: the position rows of the
        predict step over T = t - (time of the state), ``F P F' + Q(T)`` with the CTRA
        Jacobian F at the current mean (the linearisation the filter itself uses), without
        changing the filter, times ``cov_scale``, plus the slow part of the newest fix's
        stated error (a consider term: :class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`).
        None before initialisation (``position_at`` then
        holds the newest fix with no motion model behind it)."""
        if not self._ready:
            return None
        T = t - self._ts
        P = self.P
        slow = self._gnss.slow_var * np.eye(2)
        if not T > 0.0:
            return self.cov_scale * P[:2, :2] + slow
        F = np.eye(N_STATE)
        ctra_step(np.array(self._s), T, F)  # the mean position_at extrapolates
        Q = ctra_process_noise(
            self._s[IYAW],
            T,
            self.jerk_psd,
            self.yaw_acc_psd,
            self.pos_psd,
            np.zeros((N_STATE, N_STATE)),
        )
        Fp = F[:2, : IA + 1]
        out = Fp @ P[: IA + 1, : IA + 1] @ Fp.T + Q[:2, :2]
        return (0.5 * self.cov_scale) * (out + out.T) + slow
