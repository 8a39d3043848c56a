"""``kf``: the constant-acceleration linear Kalman filter as a bank that adapts to its data.

Members: a linear constant-acceleration filter (:mod:`posbench.metrics.ca_model`) at
each white-jerk density of ``jerk_psds`` [m^2/s^5] (motorway-smooth to city manoeuvres), each once
*aided* (IMU acceleration and wheel speed) and once on fixes alone. The aided members treat the IMU
as the raw sensor it may be: vehicle-frame accelerometer bias estimated from the
innovations, noise adapted to the innovations, 99.9 % innovation gate, heading from fix
chords longer than their noise carried by the gyro (never from a velocity that is
mostly noise). Fixes that state no accuracy have their noise estimated from the fixes
themselves. The bank answers with the member whose predictions of the fixes have the highest recent
likelihood, so an input that does not help on a drive (a tilted, late or vibrating IMU, a
mis-scaled wheel speed) or a process noise that does not fit it is weighed down by the drive's own
innovations. By construction the fixes-only members keep the bank near the best fixes-only filter
wherever the aiding misleads.

Implementation: the members (and their shadows) are rows of one array stepped by
compiled kernels, :mod:`~posbench.predictors.kalman.ca_rows`: one call per observation for
the whole bank, about the cost of one filter object. A fix's answer comes first: what
only the next IMU and speed updates read (the heading tracker and the bias estimator
taking the fix) and the start of new shadows wait for the next observation, which does
them before anything else (the answers are the same; the work moves off the fix step).
The tests hold the rows to a bank of member objects (tests/reference_filters:
``LinearKalman`` under a ``ModelBank``; tests/predictors/test_kf_batched.py), and those
to filterpy.

Units: seconds, metres, local ENU.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from posbench.metrics.ca_model import ca_noise_entries, ca_predict_block, ca_predict_cross
from posbench.predictors._geometry import check_config
from posbench.predictors.kalman import ca_imu
from posbench.predictors.kalman import ca_rows as kb
from posbench.predictors.kalman.accel_bias import AccelBiasEstimator
from posbench.predictors.kalman.course_heading import CourseHeading
from posbench.predictors.kalman.inputs import (
    KF_FLAT,
    AccelInput,
    GnssInput,
    HeadingInput,
    SpeedInput,
    stopped,
)
from posbench.predictors.kalman.row_bank import HORIZONS_S, RowBank

NAN2 = (math.nan, math.nan)

#: white-jerk densities of the members [m^2/s^5]: from ~0.7 m/s^3 over a second (steady
#: motorway) to ~16 m/s^3 (hard city manoeuvres); a factor 8 apart
JERK_PSDS = (0.5, 4.0, 32.0, 256.0)


#: the aided members' inputs: the IMU as the raw sensor it may be (vehicle-frame bias
#: estimated over 30 s, noise adapted over 5 s, 99.9 % innovation gate), the heading from
#: fix chords where the IMU states no yaw, the fixes' noise estimated over 30 fixes
BANK_INPUTS: dict[str, Any] = {
    "gnss": GnssInput(noise_memory=30.0),
    "imu": AccelInput(bias_tau_s=30.0, gate=13.8, noise_tau_s=5.0),
    "heading": HeadingInput(from_fixes=True),
    "speed": SpeedInput(),
}


class KalmanBank(RowBank):
    """Linear CA Kalman filters, aided and fixes-only at several process noises, selected
    by the likelihood of their fix predictions (module docstring); the behaviour of
    ``ModelBank`` over
    ``LinearKalman`` members (:meth:`member_bank`), batched.

    Args:
        gnss, imu, heading, speed: the aided members' inputs
            (:mod:`~posbench.predictors.kalman.inputs`; defaults :data:`BANK_INPUTS`); a
            fixes-only member takes ``gnss`` alone. ``imu`` or ``speed`` None: the aided
            members go without it.
        init_vel_sigma, init_acc_sigma: every member's prior at its first fix.
        jerk_psds: the members' white-jerk densities [m^2/s^5].
        jerk_psd: one density instead of ``jerk_psds`` (a bank of one aided and one
            fixes-only member), e.g. ``--set kf.jerk_psd=4``.
        memory_fixes: exponential memory of the member scores, in fixes.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's own
            covariance (1: as its model says).
        horizons_s, horizon_memory: the horizons [s] members are also scored at and the
            memory of those scores (``ModelBank``); ``[]``:
            one fix ahead only.
        **flat: the inputs' fields by their flat names (``gps_sigma``, ``accel_sigma``,
            ``use_speed``, ...: ``KF_FLAT``), as ``--set kf.X``
            and tuning files give them.
    """

    name = "kf"
    flat_names = KF_FLAT
    bank_inputs = BANK_INPUTS
    _distances = staticmethod(kb.shadow_distances)

    def __init__(
        self,
        *,
        gnss: GnssInput = BANK_INPUTS["gnss"],
        imu: AccelInput | None = BANK_INPUTS["imu"],
        heading: HeadingInput = BANK_INPUTS["heading"],
        speed: SpeedInput | None = BANK_INPUTS["speed"],
        init_vel_sigma: float = 15.0,
        init_acc_sigma: float = 3.0,
        jerk_psds: Sequence[float] = JERK_PSDS,
        jerk_psd: float | None = None,
        memory_fixes: float = 20.0,
        cov_scale: float = 1.0,
        horizons_s: Sequence[float] = HORIZONS_S,
        horizon_memory: float = 10.0,
        **flat: Any,
    ) -> None:
        if jerk_psd is not None:
            check_config("kf", jerk_psd=(jerk_psd, 1e-9, 1e6))
            jerk_psds = (jerk_psd,)
        check_config(
            "kf",
            init_vel_sigma=(init_vel_sigma, 1e-3, 1e3),
            init_acc_sigma=(init_acc_sigma, 1e-3, 1e3),
            **{f"jerk_psds[{i}]": (j, 1e-9, 1e6) for i, j in enumerate(jerk_psds)},
        )
        self._set_selection(memory_fixes, cov_scale, horizons_s, horizon_memory)
        if not jerk_psds:
            raise ValueError("kf: jerk_psds must name at least one density")
        self.inputs = KF_FLAT.compose(
            "kf",
            {"gnss": gnss, "imu": imu, "heading": heading, "speed": speed},
            BANK_INPUTS,
            flat,
        )
        self.init_vel_sigma = float(init_vel_sigma)
        self.init_acc_sigma = float(init_acc_sigma)
        self.jerk_psds = tuple(float(j) for j in jerk_psds)
        self.labels = tuple(
            label for j in self.jerk_psds for label in (f"aided j{j:g}", f"fixes j{j:g}")
        )
        self._setup()
        self.reset()

    def _setup(self) -> None:
        """The rows' parameters, the options array and the inputs shared by the members."""
        imu, speed = self.inputs["imu"], self.inputs["speed"]
        heading: HeadingInput = self.inputs["heading"]
        n = self._n = 2 * len(self.jerk_psds)
        rp = np.zeros((2 * n, kb.NP))  # members, then their shadows
        for k, j in enumerate(self.jerk_psds):
            rp[2 * k, :] = (j, imu is not None, speed is not None)  # aided
            rp[2 * k + 1, :] = (j, 0.0, 0.0)  # fixes only
        rp[n:] = rp[:n]
        self._rp = rp
        self._r_acc = imu.sigma**2 if imu is not None else math.nan
        cf = {
            "r_acc": self._r_acc,
            "r_spd": speed.sigma**2 if speed is not None else math.nan,
            "rel_sigma": speed.rel_sigma if speed is not None else 0.0,
            "stop_speed": speed.stop_speed if speed is not None else 0.0,
            "min_speed": heading.min_speed,
            "gate": imu.gate if imu is not None else 0.0,
            "noise_tau_s": imu.noise_tau_s if imu is not None else 0.0,
            "robust": float(imu is not None and imu.robust),
            "course": float(heading.from_fixes),
            "huber_k": self.huber_k,
        }
        self._cf = np.array([cf[name] for name in kb.CF_NAMES])
        self._has_imu = imu is not None
        self._has_speed = speed is not None
        self._stop_speed = cf["stop_speed"]
        self._sigma_max = heading.sigma_max
        # one fix-noise model, heading tracker and bias estimator for all members: each
        # member's would see the same inputs and hold the same values
        self._gnss = self.inputs["gnss"].noise()
        self._course = CourseHeading() if heading.from_fixes else None
        tau = imu.bias_tau_s if imu is not None else 0.0
        self._bias = AccelBiasEstimator(tau) if tau > 0.0 else None
        # the IMU sample's kernel (ca_imu.imu_sample): the trackers' options, and a state
        # array that stands in for a tracker or estimator the bank does not have
        c = self._course or CourseHeading()
        self._course_options = (c.rate_psd, c.hold_psd, self._sigma_max)
        self._no_state = np.zeros(0)

    def reset(self) -> None:
        rows = kb.new_rows(2 * self._n)
        rows[:, kb.IMU_M2] = self._r_acc
        self._reset_bank(rows)
        if self._course is not None:
            self._course.reset()
        if self._bias is not None:
            self._bias.reset()
        self._ready = False
        self._imu_yaw = False  # whether the newest IMU sample stated a yaw
        #: the shadows' heading tracker and bias estimator (copies of the members')
        self._shadow_course: CourseHeading | None = None
        self._shadow_bias: AccelBiasEstimator | None = None
        #: a fix (t, x, y, its variance) the heading tracker and bias estimator take after
        #: its answer (:meth:`_after_fix_work`)
        self._after_fix: tuple[float, float, float, float] | None = None

    def _after_fix_work(self) -> None:
        """The heading tracker and the bias estimator take the newest fix (only IMU and
        speed updates read them)."""
        pending = self._after_fix
        if pending is not None:
            self._after_fix = None
            t, x, y, r = pending
            if self._course is not None:
                self._course.observe_fix(t, x, y, r)
            if self._bias is not None:
                self._bias.observe_fix(t, x, y, r)

    def _start_shadow_helpers(self) -> None:
        self._shadow_course = copy.deepcopy(self._course)
        self._shadow_bias = copy.deepcopy(self._bias)

    # -- observations ---------------------------------------------------------------------
    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        if self._due:
            self._catch_up()
        if not (math.isfinite(x) and math.isfinite(y)):
            return  # no member takes it, none is scored
        self._fix_begins(t, x, y)
        self._gnss.observe(t, x, y)
        r = self._gnss.weigh(sigma)
        if self._course is not None or self._bias is not None:
            self._after_fix = (t, x, y, r)
            self._due = True
        n = self._n
        if not self._ready:
            v, a = self.init_vel_sigma**2, self.init_acc_sigma**2
            kb.init_rows(self._S, n, t, x, y, r, v, a)
            self._ready = True
        else:
            best = kb.fix_rows(
                self._S, self._rp, n, t, x, y, r, self.huber_k, self.scores, self._keep
            )
            if best >= 0:
                self.best = best
        self._fix_ends(t)

    def _course_heading(self, course: CourseHeading | None, t: float) -> float:
        """A course tracker's heading [rad] at t, NaN while its standard deviation is not
        below ``heading_sigma_max`` (``LinearKalman._course_heading``)."""
        if course is None:
            return math.nan
        return float(ca_imu.course_heading(course.state, t, *self._course_options))

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        if self._due:
            self._catch_up()
        self._imu_yaw = math.isfinite(yaw)
        course, shadows = self._course, self._shadows_on
        if self._ready and self._has_imu:  # trackers, rows and bias: one compiled call
            sc, sb = self._shadow_course, self._shadow_bias
            bias = self._bias
            cm = course.state if course is not None else self._no_state
            bm = bias.state if bias is not None else self._no_state
            ca_imu.imu_sample(
                self._S,
                self._rp,
                self._cf,
                self._n,
                shadows,
                t,
                ax,
                ay,
                yaw,
                yaw_rate,
                course is not None,
                (cm, sc.state if sc is not None else cm),
                *self._course_options,
                bias is not None,
                (bm, sb.state if sb is not None else bm),
            )
            return
        if course is not None:
            course.observe_rate(t, yaw_rate)
            if shadows:
                self._shadow_course.observe_rate(t, yaw_rate)  # type: ignore[union-attr]
        if not self._ready and self._imu_yaw:
            self._S[:, kb.YAW] = yaw
            self._S[:, kb.YAW_T] = t

    def observe_speed(self, t: float, v: float) -> None:
        if self._due:
            self._catch_up()
        if not (self._ready and self._has_speed and math.isfinite(v)):
            return
        shadows = self._shadows_on
        hm = hs = math.nan
        if self._course is not None and not self._imu_yaw and not stopped(v, self._stop_speed):
            hm = self._course_heading(self._course, t)
            if shadows:
                hs = self._course_heading(self._shadow_course, t)
        n = self._n
        kb.speed_rows(
            self._S,
            self._rp,
            self._cf,
            2 * n if shadows else n,
            n,
            t,
            v,
            self._imu_yaw,
            (hm, hs),
        )

    # -- answers --------------------------------------------------------------------------
    def position_at(self, t: float) -> tuple[float, float]:
        if not self._ready:
            return NAN2
        i = self.answering(t)
        x, vx, ax, y, vy, ay = self._S[i, :6].tolist()
        ts = self._S.item(i, kb.TS)
        dt = t - ts
        h = 0.5 * dt * dt
        return x + vx * dt + ax * h, y + vy * dt + ay * h

    def positions_at(self, times: tuple[float, ...], out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`position_at` of each of ``times`` [s] (the same numbers) as the rows of
        ``out`` (len(times), 2) [m, ENU] (a new array where None), in one compiled call: the
        hybrid's prior at its four horizons."""
        if out is None:
            out = np.empty((len(times), 2))
        if not self._ready:
            out.fill(math.nan)
            return out
        kb.positions(self._S, tuple([self.answering(t) for t in times]), times, out)
        return out

    def covariance_at(self, t: float) -> np.ndarray | None:
        """The answering member's 2x2 ENU position covariance [m^2] at t
        (``LinearKalman.covariance_at``): its own part times ``cov_scale``, plus the slow
        part of the newest fix's stated error (:attr:`slow_variance`, not scaled). None
        before the first fix."""
        if not self._ready:
            return None
        i = self.answering(t)
        row = self._S[i].tolist()
        d = t - row[kb.TS]
        A = tuple(row[kb.A : kb.A + 6])
        B = tuple(row[kb.B : kb.B + 6])
        C = tuple(row[kb.C : kb.C + 9])
        if d > 0.0:
            h = 0.5 * d * d
            q = ca_noise_entries(d, self._rp.item(i, kb.PSD))
            pxx = ca_predict_block(A, d, h, q)[0]
            pyy = ca_predict_block(B, d, h, q)[0]
            pxy = ca_predict_cross(C, d, h)[0]
        else:
            pxx, pyy, pxy = A[0], B[0], C[0]
        return self._bank_covariance(pxx, pxy, pyy)

    def config(self) -> dict:
        return {
            **self._flat_config(),
            "init_vel_sigma": self.init_vel_sigma,
            "init_acc_sigma": self.init_acc_sigma,
            "jerk_psds": list(self.jerk_psds),
            **self._selection_config(),
        }
