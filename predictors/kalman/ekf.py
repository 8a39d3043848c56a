"""``ekf``: the CTRA extended Kalman filter as a bank that adapts to its data.

Members: a CTRA EKF (:mod:`~posbench.predictors.kalman.ctra_model`) at each pair of
white-jerk and white-yaw-acceleration densities of ``noise_levels`` (steady motorway to city
manoeuvres), each once *aided* (IMU yaw rate, acceleration and yaw, wheel speed; the
filter estimates their biases, offset and scale) and once on fixes alone.
The bank answers with the member whose predictions
of the fixes have the highest recent likelihood, so an input that does not help on a
drive, or a process noise that does not fit it, is weighed down by the drive's own
innovations (see :mod:`posbench.predictors.kalman.kf`, the same idea for ``kf``). Fixes
that state no accuracy have their noise estimated from the fixes themselves
(``fix_noise_memory``, 30 fixes).

Implementation: the members (and their shadows) are rows of one array stepped by
compiled kernels, :mod:`~posbench.predictors.kalman.ctra_rows`: one call per observation for
the whole bank, about the cost of one filter object; the fix-noise model is one for all
members (each member's would see the same fixes and hold the same values). The tests
hold the rows to a bank of member objects (tests/reference_filters: ``CtraEkf`` under a
``ModelBank``; tests/predictors/test_ekf_batched.py), and those to filterpy.

Units: seconds, metres, radians, local ENU.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from posbench.predictors._geometry import check_config
from posbench.predictors.kalman import ctra_rows as cb
from posbench.predictors.kalman.inputs import (
    EKF_FLAT,
    EKF_INPUTS,
    CtraImuInput,
    CtraSpeedInput,
    GnssInput,
)
from posbench.predictors.kalman.row_bank import HORIZONS_S, RowBank

NAN2 = (math.nan, math.nan)

#: (jerk_psd [m^2/s^5], yaw_acc_psd [rad^2/s^3]) of the members, gentle to agile
NOISE_LEVELS = ((0.5, 0.03), (4.0, 0.3), (32.0, 3.0), (256.0, 10.0))


#: the aided members' inputs: as ``CtraEkf``'s, with the
#: fixes' noise estimated over 30 fixes
BANK_INPUTS: dict[str, Any] = {**EKF_INPUTS, "gnss": GnssInput(noise_memory=30.0)}


class EkfBank(RowBank):
    """CTRA EKFs, aided and fixes-only at several process noises, selected by the
    likelihood of their fix predictions (module docstring); the behaviour of
    ``ModelBank`` over
    ``CtraEkf`` members (:meth:`member_bank`), batched.

    Args:
        noise_levels: ``(jerk_psd, yaw_acc_psd)`` pairs, one pair of members each.
        jerk_psd, yaw_acc_psd: one level instead of ``noise_levels`` (a bank of one aided
            and one fixes-only member; the one not given takes
            ``CtraEkf``'s default), e.g. ``--set ekf.jerk_psd=4``.
        gnss, imu, speed: the aided members' inputs (:mod:`~posbench.predictors.kalman.inputs`;
            defaults :data:`BANK_INPUTS`); a fixes-only member takes ``gnss`` alone.
        pos_psd, init_vel_sigma, calib_psd: every member's
            (``CtraEkf``).
        memory_fixes: exponential memory of the member scores, in fixes.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's own
            covariance.
        horizons_s, horizon_memory: the horizons [s] members are also scored at and the
            memory of those scores (``ModelBank``); ``[]``:
            one fix ahead only.
        **flat: the inputs' fields by their flat names (``gps_sigma``, ``yaw_rate_sigma``,
            ``use_speed``, ...: ``EKF_FLAT``), as ``--set ekf.X``
            and tuning files give them.
    """

    name = "ekf"
    flat_names = EKF_FLAT
    bank_inputs = BANK_INPUTS
    _distances = staticmethod(cb.shadow_distances)

    def __init__(
        self,
        noise_levels: Sequence[Sequence[float]] = NOISE_LEVELS,
        jerk_psd: float | None = None,
        yaw_acc_psd: float | None = None,
        *,
        gnss: GnssInput = BANK_INPUTS["gnss"],
        imu: CtraImuInput | None = BANK_INPUTS["imu"],
        speed: CtraSpeedInput | None = BANK_INPUTS["speed"],
        pos_psd: float = 0.01,
        init_vel_sigma: float = 15.0,
        calib_psd: float = 1e-6,
        memory_fixes: float = 20.0,
        cov_scale: float = 1.0,
        horizons_s: Sequence[float] = HORIZONS_S,
        horizon_memory: float = 10.0,
        **flat: Any,
    ) -> None:
        if jerk_psd is not None or yaw_acc_psd is not None:
            noise_levels = (
                (
                    2.0 if jerk_psd is None else jerk_psd,
                    0.1 if yaw_acc_psd is None else yaw_acc_psd,
                ),
            )
        levels = tuple((float(j), float(w)) for j, w in noise_levels)
        check_config(
            "ekf", **{f"noise_levels[{i}]": (j, 1e-9, 1e6) for i, (j, _) in enumerate(levels)}
        )
        # what each member (CtraEkf) and the bank (ModelBank) would check
        check_config(
            "ekf",
            **{f"yaw_acc_psd[{i}]": (w, 1e-12, 1e6) for i, (_, w) in enumerate(levels)},
            pos_psd=(pos_psd, 0.0, 1e6),
            init_vel_sigma=(init_vel_sigma, 1e-3, 1e3),
            calib_psd=(calib_psd, 0.0, 1e6),
        )
        self._set_selection(memory_fixes, cov_scale, horizons_s, horizon_memory)
        if not levels:
            raise ValueError("ekf: noise_levels must name at least one pair")
        self.inputs = EKF_FLAT.compose(
            "ekf", {"gnss": gnss, "imu": imu, "speed": speed}, BANK_INPUTS, flat
        )
        self.noise_levels = levels
        self._member: dict[str, Any] = {
            "pos_psd": pos_psd,
            "init_vel_sigma": init_vel_sigma,
            "calib_psd": calib_psd,
        }
        self.labels = tuple(
            label for j, w in levels for label in (f"aided j{j:g} w{w:g}", f"fixes j{j:g} w{w:g}")
        )
        self._setup()
        self.reset()

    def _setup(self) -> None:
        """The rows' parameters and the options array (as each member's ``CtraEkf``
        holds them) and the fix-noise model shared by the members."""
        imu, speed = self.inputs["imu"], self.inputs["speed"]
        n = self._n = 2 * len(self.noise_levels)
        rp = np.zeros((2 * n, cb.NP))  # members, then their shadows
        for k, (j, w) in enumerate(self.noise_levels):
            rp[2 * k] = self._row_params(j, w, imu, speed)  # aided
            rp[2 * k + 1] = self._row_params(j, w, None, None)  # fixes only
        rp[n:] = rp[:n]
        self._rp = rp
        cf = {
            "pos_psd": float(self._member["pos_psd"]),
            "calib_psd": float(self._member["calib_psd"]),
            "var_v0": float(self._member["init_vel_sigma"]) ** 2,
            "huber_k": self.huber_k,
        }
        self._cf = np.array([cf[name] for name in cb.CF_NAMES])
        self._has_imu = imu is not None
        self._has_speed = speed is not None
        self._w = np.empty(cb.NW)
        # one fix-noise model for all members: each member's would hold the same values
        self._gnss = self.inputs["gnss"].noise()

    @staticmethod
    def _row_params(
        j: float, w: float, imu: CtraImuInput | None, speed: CtraSpeedInput | None
    ) -> list[float]:
        """One row's parameters (:data:`~posbench.predictors.kalman.ctra_rows.RP_NAMES`): a
        sensor not taken keeps its calibration states at the default priors, as
        ``CtraEkf`` does."""
        imu_c = imu if imu is not None else EKF_INPUTS["imu"]
        spd_c = speed if speed is not None else EKF_INPUTS["speed"]
        row = {
            "jerk_psd": float(j),
            "yaw_acc_psd": float(w),
            "accel_bias_psd": imu_c.accel_bias_psd,
            "gyro_bias_psd": imu_c.gyro_bias_psd,
            "var_ba0": imu_c.accel_bias_sigma0**2,
            "var_bw0": imu_c.gyro_bias_sigma0**2,
            "var_by0": imu_c.yaw_offset_sigma0**2,
            "var_kv0": spd_c.scale_sigma0**2,
            "r_w": imu_c.yaw_rate_sigma**2,
            "r_a": imu_c.accel_sigma**2,
            "r_yaw": imu_c.yaw_sigma**2,
            "r_v": spd_c.sigma**2,
            "rel_sigma": spd_c.rel_sigma,
            "has_imu": float(imu is not None),
            "use_yaw": float(imu is not None and imu.use_yaw),
            "has_speed": float(speed is not None),
        }
        return [row[name] for name in cb.RP_NAMES]

    def reset(self) -> None:
        self._reset_bank(cb.new_rows(2 * self._n))

    # -- observations ---------------------------------------------------------------------
    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        if self._due:
            self._catch_up()
        if not (math.isfinite(x) and math.isfinite(y)):
            return  # no member takes it, none is scored
        self._fix_begins(t, x, y)
        self._gnss.observe(t, x, y)
        r = self._gnss.weigh(sigma)
        best = cb.fix_rows(
            self._S, self._rp, self._cf, self._w, self._n, t, x, y, r, self.scores, self._keep
        )
        if best >= 0:
            self.best = best
        self._fix_ends(t)

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        if self._due:
            self._catch_up()
        if not self._has_imu:
            return
        n = self._n
        hi = 2 * n if self._shadows_on else n
        cb.imu_rows(self._S, self._rp, self._cf, self._w, hi, t, ax, yaw, yaw_rate)

    def observe_speed(self, t: float, v: float) -> None:
        if self._due:
            self._catch_up()
        if not (self._has_speed and math.isfinite(v)):
            return
        n = self._n
        hi = 2 * n if self._shadows_on else n
        cb.speed_rows(self._S, self._rp, self._cf, self._w, hi, t, v)

    # -- answers --------------------------------------------------------------------------
    def position_at(self, t: float) -> tuple[float, float]:
        return cb.position(self._S, self.answering(t), t)

    def covariance_at(self, t: float) -> np.ndarray | None:
        """The answering member's 2x2 ENU position covariance [m^2] at t
        (``CtraEkf.covariance_at``): its own part times ``cov_scale``, plus the slow part
        of the newest fix's stated error (:attr:`slow_variance`, not scaled). None before
        that member is initialised."""
        i = self.answering(t)
        if self._S.item(i, cb.READY) == 0.0:
            return None
        pxx, pxy, pyy = cb.covariance(self._S, self._rp, self._cf, i, t)
        return self._bank_covariance(pxx, pxy, pyy)

    def config(self) -> dict:
        return {
            **self._flat_config(),
            **self._member,
            "noise_levels": [list(p) for p in self.noise_levels],
            **self._selection_config(),
        }
