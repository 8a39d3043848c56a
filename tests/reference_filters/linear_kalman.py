"""Linear Kalman filter with a constant-acceleration state, run continuously over a drive.

State ``[x, y, vx, vy, ax, ay]`` in local ENU (m, m/s, m/s^2); kinematics per axis
``p' = p + v dt + a dt^2/2, v' = v + a dt, a' = a`` driven by white jerk of spectral
density ``jerk_psd`` [m^2/s^5] (the standard discretised Wiener-jerk Q).

IMU acceleration is an *observation* of (ax, ay), not a control input. Why: with a
constant-acceleration state the acceleration is already part of the state; a control
input is treated as exact, so IMU noise, vibration and gravity leakage from pitch would
enter the position unfiltered (one would have to hand-fold them into Q, and the (ax, ay)
states would be redundant). As a measurement with variance ``accel_sigma^2`` the filter
weighs each IMU sample against the jerk model and the GNSS fixes, and a missing (NaN)
sample simply skips the update. The vehicle-frame sample is rotated to ENU with the IMU
yaw; when yaw is NaN (e.g. comma2k19) with the heading of the velocity state (above
``heading_min_speed``), else with the last heading advanced by the IMU yaw rate; with no
heading at all the sample is skipped.

Cycle: predict at every observation's time (variable dt), then update: fixes
(x, y; per-axis sigma ``gps_sigma_scale`` x the fix's stated accuracy when
``observe_gps`` is given one, else ``gps_sigma``), IMU world acceleration, wheel speed along the
heading (sigma ``speed_sigma``); a speed below ``stop_speed`` is a zero-velocity update of both
components. ``position_at`` extrapolates the current mean in closed form
(``p + v dt + a dt^2/2``) without touching the filter; ``covariance_at`` gives the position
block of the same prediction's covariance (``F P F' + Q(dt)``, ENU, m^2).

Defaults chosen by physics, not tuned: comfortable car jerk stays within ~1-2 m/s^3 and
changes over ~1 s, so ``jerk_psd`` ~ 1.5^2 * 1 = 2; fix-to-fix GNSS noise (what matters
over 0.2 s; absolute errors are strongly time-correlated) ~0.3 m; accelerometer noise is
small but road vibration and pitch (1 deg -> 0.17 m/s^2 of gravity) give ~0.3 m/s^2;
wheel speed ~0.2 m/s plus a 3 % scale error (tyre radius; KITTI drive 0005's speed
reads 2.5 % above its position-derived speed).

Implementation: :class:`reference_filters.ca_filter.CaFilter2D`, the same filter as
``filterpy.kalman.KalmanFilter`` with F = :func:`ca_transition`, Q = :func:`ca_process_noise`
written out in plain floats for the fixed 6-state size (fix step p50 ~23 -> ~5 us); the
tests run filterpy beside it (``filter_core``) and check mean, covariance and every answer.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from posbench.metrics.ca_model import (
    ca_noise_entries,
    ca_noise_matrix,
    ca_predict_block,
    ca_predict_cross,
)
from posbench.predictors._geometry import COV_SCALE_RANGE, check_config
from posbench.predictors._kernels import warm_up_once
from posbench.predictors.base import Predictor
from posbench.predictors.kalman.accel_bias import AccelBiasEstimator
from posbench.predictors.kalman.copying import copy_attrs
from posbench.predictors.kalman.course_heading import CourseHeading
from posbench.predictors.kalman.inputs import (
    KF_FLAT,
    KF_INPUTS,
    AccelInput,
    GnssInput,
    HeadingInput,
    SpeedInput,
    stopped,
)
from reference_filters.ca_filter import CaFilter2D

NAN2 = (math.nan, math.nan)

#: per-axis component of a measurement (CaFilter2D.update_pair): position, velocity, accel
POS, VEL, ACC = 0, 1, 2


def ca_transition(dt: float, out: np.ndarray) -> np.ndarray:
    """Fill ``out`` (6x6, preset to identity) with the constant-acceleration F(dt) (the
    model's matrix form; :class:`CaFilter2D` applies it per axis)."""
    h = 0.5 * dt * dt
    out[0, 2] = out[1, 3] = out[2, 4] = out[3, 5] = dt
    out[0, 4] = out[1, 5] = h
    return out


def ca_process_noise(dt: float, jerk_psd: float, out: np.ndarray) -> np.ndarray:
    """Fill ``out`` (6x6, zeros elsewhere) with Q of white jerk (psd [m^2/s^5]) over dt [s]
    (:func:`~posbench.metrics.ca_model.ca_noise_matrix` per axis)."""
    blk = ca_noise_matrix(dt, jerk_psd)
    for i in range(3):
        for j in range(3):
            out[2 * i, 2 * j] = out[2 * i + 1, 2 * j + 1] = blk[i, j]
    return out


class LinearKalman(Predictor):
    """Constant-acceleration linear KF fed by GNSS fixes, IMU acceleration and wheel speed.

    Composed of the CA motion model and its sensor inputs
    (:mod:`~posbench.predictors.kalman.inputs`); a fixes-only filter is ``imu=None,
    speed=None``.

    Args:
        jerk_psd: process noise, white-jerk spectral density [m^2/s^5].
        gnss: the fixes (:class:`~posbench.predictors.kalman.inputs.GnssInput`: noise for
            fixes that state none, scale of a statement, white/slow split).
        imu: IMU acceleration as an observation
            (:class:`~posbench.predictors.kalman.inputs.AccelInput`: noise, bias estimate,
            adapted noise, gate); None: no IMU updates.
        heading: where the IMU states no yaw, the heading it and the speed are taken along
            (:class:`~posbench.predictors.kalman.inputs.HeadingInput`).
        speed: wheel speed (:class:`~posbench.predictors.kalman.inputs.SpeedInput`); None:
            no speed updates.
        init_vel_sigma: prior velocity uncertainty [m/s] at the first fix.
        init_acc_sigma: prior acceleration uncertainty [m/s^2] at the first fix.
        cov_scale: calibration: ``covariance_at`` reports ``cov_scale`` x the filter's own
            covariance (1: as the model says); fitted on development drives by
            ``bench tune`` so that 95 % of the 95 % ellipses cover the truth. It never
            changes a position.
        course, bias_estimator: a heading tracker / bias estimator to use instead of the
            filter's own (filters of a bank share theirs; their inputs are idempotent).
        **flat: the inputs' fields by their flat names (:data:`KF_FLAT`: ``gps_sigma``,
            ``accel_sigma``, ``use_imu``, ``heading_from_fixes``, ``stop_speed``, ...), as
            ``--set kf.X``, tuning files and the hybrid's saved prior give them.
    """

    name = "kf"

    def __init__(
        self,
        jerk_psd: float = 2.0,
        *,
        gnss: GnssInput = KF_INPUTS["gnss"],
        imu: AccelInput | None = KF_INPUTS["imu"],
        heading: HeadingInput = KF_INPUTS["heading"],
        speed: SpeedInput | None = KF_INPUTS["speed"],
        init_vel_sigma: float = 15.0,
        init_acc_sigma: float = 3.0,
        cov_scale: float = 1.0,
        course: CourseHeading | None = None,
        bias_estimator: AccelBiasEstimator | None = None,
        **flat: Any,
    ) -> None:
        check_config(
            "kf",
            jerk_psd=(jerk_psd, 1e-9, 1e6),
            init_vel_sigma=(init_vel_sigma, 1e-3, 1e3),
            init_acc_sigma=(init_acc_sigma, 1e-3, 1e3),
            cov_scale=(cov_scale, *COV_SCALE_RANGE),
        )
        inputs = KF_FLAT.compose(
            "kf", {"gnss": gnss, "imu": imu, "heading": heading, "speed": speed}, KF_INPUTS, flat
        )
        #: the sensor inputs (:mod:`~posbench.predictors.kalman.inputs`); None: not used
        self.gnss: GnssInput = inputs["gnss"]
        self.imu: AccelInput | None = inputs["imu"]
        self.heading: HeadingInput = inputs["heading"]
        self.speed: SpeedInput | None = inputs["speed"]
        self.jerk_psd = float(jerk_psd)
        self.init_vel_sigma = float(init_vel_sigma)
        self.init_acc_sigma = float(init_acc_sigma)
        self.cov_scale = float(cov_scale)
        # heading tracker and bias estimator: shared ones where a bank passes them
        self._course = (course or CourseHeading()) if self.heading.from_fixes else None
        self._gnss = self.gnss.noise()
        tau = self.imu.bias_tau_s if self.imu is not None else 0.0
        self._bias_est = (bias_estimator or AccelBiasEstimator(tau)) if tau > 0.0 else None
        self._r_acc = self.imu.sigma**2 if self.imu is not None else math.nan
        self._r_spd = self.speed.sigma**2 if self.speed is not None else math.nan
        self.kf = self.filter_core()
        self.reset()

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = (
        "gnss",
        "imu",
        "heading",
        "speed",
        "jerk_psd",
        "init_vel_sigma",
        "init_acc_sigma",
        "cov_scale",
        "_course",
        "_gnss",
        "_bias_est",
        "_r_acc",
        "_r_spd",
        "kf",
        "_ready",
        "_ts",
        "_s",
        "_yaw",
        "_yaw_t",
        "_imu_t",
        "_imu_yaw",
        "_imu_m2",
        "fix_innovation",
    )

    def __deepcopy__(self, memo: dict) -> LinearKalman:
        """An independent copy (a bank's shadows, :class:`~reference_filters.model_bank.ModelBank`):
        its own filter state; the heading tracker and bias estimator copied once per
        ``memo``, so copies of a bank's members share them as the members do."""
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new.kf = copy.deepcopy(self.kf, memo)
        new._s = list(self._s)
        new._gnss = copy.deepcopy(self._gnss, memo)
        new._course = copy.deepcopy(self._course, memo)
        new._bias_est = copy.deepcopy(self._bias_est, memo)
        return new

    def warm_up(self) -> None:
        """Load the kernels of its inputs (the fix-noise estimate, the heading tracker)
        before a run's clock starts (:func:`~posbench.predictors._kernels.warm_up_once`)."""
        warm_up_once(lambda: LinearKalman(**self.config()))

    #: the filter's mean / covariance algebra (the tests put a filterpy twin here)
    filter_core: type = CaFilter2D

    @classmethod
    def flat_options(cls) -> dict[str, Any]:
        """The flat option names and their defaults (for ``bench predictors`` and
        ``--set`` checks)."""
        return KF_FLAT.flatten(KF_INPUTS, KF_INPUTS)

    @classmethod
    def flat_option_types(cls) -> dict[str, Any]:
        """The flat option names and their declared types (``--set`` parses by them)."""
        return KF_FLAT.types(KF_INPUTS)

    def config(self) -> dict:
        """The options in flat names (:data:`KF_FLAT`), as ``LinearKalman(**config())``
        takes them."""
        return {
            "jerk_psd": self.jerk_psd,
            "init_vel_sigma": self.init_vel_sigma,
            "init_acc_sigma": self.init_acc_sigma,
            "cov_scale": self.cov_scale,
            **KF_FLAT.flatten(
                {"gnss": self.gnss, "imu": self.imu, "heading": self.heading, "speed": self.speed},
                KF_INPUTS,
            ),
        }

    # -- state -------------------------------------------------------------------------
    def reset(self) -> None:
        self._ready = False
        self._ts = math.nan  # time of the filter's state
        self._s = [math.nan] * 6  # plain-float copy of the mean
        self._yaw = math.nan  # last heading used for rotation [rad]
        self._yaw_t = math.nan
        if self._bias_est is not None:
            self._bias_est.reset()
        self._gnss.reset()
        self._imu_t = math.nan  # time of the previous IMU sample [s]
        self._imu_yaw = False  # whether the newest IMU sample stated a yaw
        self._imu_m2 = self._r_acc  # mean squared IMU innovation per axis [m^2/s^4]
        if self._course is not None:
            self._course.reset()

    def _sync(self) -> None:
        self._s = self.kf.state()

    def _predict_to(self, t: float) -> None:
        dt = t - self._ts
        if dt > 0.0:
            self.kf.predict(dt, self.jerk_psd)
            self._ts = t

    # -- observations -----------------------------------------------------------------
    def fix_variance(self, sigma: float | None) -> float:
        """R per axis [m^2] a fix stating per-axis 1-sigma ``sigma`` [m] is weighed with:
        its white part (:class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`); without
        ``fix_noise_memory`` ``(gps_sigma_scale * sigma)^2``, or ``gps_sigma^2`` when it
        states none (None, not finite, or <= 0)."""
        return self._gnss.parts(sigma)[0]

    #: the newest fix's innovation and its covariance before the update, ``(nu_x, nu_y,
    #: S_xx, S_xy, S_yy)`` [m, m^2]; None before the filter's second fix (read by
    #: :class:`~reference_filters.model_bank.ModelBank`)
    fix_innovation: tuple[float, float, float, float, float] | None = None

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        self.fix_innovation = None
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        self._gnss.observe(t, x, y)
        r = self._gnss.weigh(sigma)
        if self._course is not None:
            self._course.observe_fix(t, x, y, r)
        if self._bias_est is not None:
            self._bias_est.observe_fix(t, x, y, r)
        if not self._ready:
            self.kf.init(x, y, r, self.init_vel_sigma**2, self.init_acc_sigma**2)
            self._ts = t
            self._ready = True
            self._sync()
            return
        self._predict_to(t)
        kf = self.kf
        px, py = kf.state()[:2]
        pxx, pxy, pyy = kf.position_block()
        self.fix_innovation = (x - px, y - py, pxx + r, pxy, pyy + r)
        self.kf.update_pair(POS, x, y, r)
        self._sync()

    def _heading(self, t: float, yaw: float, yaw_rate: float) -> float:
        if math.isfinite(yaw):
            h = yaw
        else:
            vx, vy = self.kf.velocity()  # predicted to t (self._s may be older)
            if math.hypot(vx, vy) > self.heading.min_speed:
                h = math.atan2(vy, vx)
            elif math.isfinite(self._yaw) and math.isfinite(yaw_rate):
                h = self._yaw + yaw_rate * (t - self._yaw_t)
            else:
                h = self._yaw
        self._yaw, self._yaw_t = h, t
        return h

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        course = self._course
        if course is not None:
            course.observe_rate(t, yaw_rate)
        self._imu_yaw = math.isfinite(yaw)
        if not self._ready:
            if math.isfinite(yaw):
                self._yaw, self._yaw_t = yaw, t
            return
        imu = self.imu
        if imu is None:
            return
        self._predict_to(t)
        if course is not None and not math.isfinite(yaw):
            h = self._course_heading(t)
            self._yaw, self._yaw_t = h, t
        else:
            h = self._heading(t, yaw, yaw_rate)
        if self._bias_est is not None:
            self._bias_est.observe_imu(t, ax, ay, h)
        if math.isfinite(ax) and math.isfinite(ay) and math.isfinite(h):
            c, s = math.cos(h), math.sin(h)
            if imu.robust:
                self._robust_accel_update(t, ax, ay, c, s, imu)
            else:
                self.kf.update_pair(ACC, c * ax - s * ay, s * ax + c * ay, self._r_acc)
        self._imu_t = t
        self._sync()

    def _course_heading(self, t: float) -> float:
        """The course tracker's heading [rad] at t, NaN while its standard deviation is not
        below ``heading_sigma_max``."""
        h, h_sd = self._course.heading(t)  # type: ignore[union-attr]
        return h if h_sd < self.heading.sigma_max else math.nan

    def _robust_accel_update(
        self, t: float, ax: float, ay: float, c: float, s: float, imu: AccelInput
    ) -> None:
        """The IMU acceleration update with the bias estimate removed, its noise adapted to
        the innovations and the update gated (``imu``'s ``bias_tau_s``, ``noise_tau_s``,
        ``gate``). Innovations in the vehicle frame [m/s^2]."""
        kf = self.kf
        bx, by = self.accel_bias
        mx, my = ax - bx, ay - by
        pax, pay = kf.state()[4:]  # predicted world acceleration
        nx = mx - (c * pax + s * pay)
        ny = my - (-s * pax + c * pay)
        vax, vay = kf.acceleration_variances()
        pa = 0.5 * (vax + vay)
        dt = t - self._imu_t
        dt = min(dt, 0.5) if dt > 0.0 else 0.0
        m2 = 0.5 * (nx * nx + ny * ny)
        r = self._r_acc
        if imu.noise_tau_s > 0.0:
            self._imu_m2 += min(dt / imu.noise_tau_s, 1.0) * (m2 - self._imu_m2)
            r = max(r, self._imu_m2 - pa)
        if imu.gate > 0.0 and 2.0 * m2 > imu.gate * (pa + r):
            return
        kf.update_pair(ACC, c * mx - s * my, s * mx + c * my, r)

    def observe_speed(self, t: float, v: float) -> None:
        speed = self.speed
        if not (self._ready and speed is not None and math.isfinite(v)):
            return
        self._predict_to(t)
        if stopped(v, speed.stop_speed):
            self.kf.update_pair(VEL, 0.0, 0.0, self._r_spd)
        else:
            h = self._speed_heading(t)
            if math.isfinite(h):  # no heading: no update, but the prediction stands
                self.kf.update_speed(
                    math.cos(h), math.sin(h), v, self._r_spd + (speed.rel_sigma * v) ** 2
                )
        self._sync()  # the mean was predicted to t: answers must start from it

    def _speed_heading(self, t: float) -> float:
        """The heading [rad] a wheel speed at t is taken along: the course tracker's where
        the IMU states no yaw, else the last heading used, else the velocity's direction
        above ``heading_min_speed``; NaN when none is known."""
        if self._course is not None and not self._imu_yaw:
            return self._course_heading(t)
        h = self._yaw
        vx, vy = self.kf.velocity()
        if not math.isfinite(h) and math.hypot(vx, vy) > self.heading.min_speed:
            h = math.atan2(vy, vx)
        return h

    @property
    def accel_bias(self) -> tuple[float, float]:
        """The accelerometer bias estimate (x forward, y left) [m/s^2]; (0, 0) unless
        ``accel_bias_tau_s`` > 0."""
        return self._bias_est.bias if self._bias_est is not None else (0.0, 0.0)

    def state(self) -> tuple[float, list[float], np.ndarray]:
        """(time [s], mean ``[x, y, vx, vy, ax, ay]``, 6x6 covariance) of the filter, NaN
        time before the first fix. A copy: changing it does not change the filter."""
        return self._ts, self.kf.state(), self.kf.covariance()

    @property
    def slow_variance(self) -> float:
        """The slow part [m^2] per axis of the newest fix's stated error, which
        ``covariance_at`` adds to the filter's own covariance (0 for a white receiver or
        one that states nothing; :class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`)."""
        return self._gnss.slow_var

    # -- query ------------------------------------------------------------------------
    def position_at(self, t: float) -> tuple[float, float]:
        if not self._ready:
            return NAN2
        x, y, vx, vy, ax, ay = self._s
        dt = t - self._ts
        h = 0.5 * dt * dt
        return x + vx * dt + ax * h, y + vy * dt + ay * h

    def covariance_at(self, t: float) -> np.ndarray | None:
        """2x2 ENU position covariance [m^2] of ``position_at(t)``: the filter's covariance
        propagated over dt = t - (time of the state) exactly as a predict step would
        (``F P F' + Q(dt)`` with the white-jerk Q), without changing the filter, times
        ``cov_scale``, plus the slow part of the newest fix's stated error (a consider
        term: :class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`). None before the first
        fix."""
        if not self._ready:
            return None
        kf = self.kf
        d = t - self._ts
        if d > 0.0:
            h = 0.5 * d * d
            q = ca_noise_entries(d, self.jerk_psd)
            pxx = ca_predict_block(kf.A, d, h, q)[0]
            pyy = ca_predict_block(kf.B, d, h, q)[0]
            pxy = ca_predict_cross(kf.C, d, h)[0]
        else:
            pxx, pyy, pxy = kf.A[0], kf.B[0], kf.C[0]
        k = self.cov_scale
        s = self._gnss.slow_var
        return np.array(((k * pxx + s, k * pxy), (k * pxy, k * pyy + s)))
