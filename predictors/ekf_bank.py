"""``ekf``: the CTRA extended Kalman filter as a bank that adapts to its data.

Members: :class:`~posbench.predictors.ekf.CtraEkf` at each pair of white-jerk and
white-yaw-acceleration densities of ``noise_levels`` (steady motorway to city
manoeuvres), each once *aided* (IMU yaw rate, acceleration and yaw, wheel speed; the
filter estimates their biases, offset and scale) and once on fixes alone.
:class:`~posbench.predictors.bank.ModelBank` answers with the member whose predictions
of the fixes have the highest recent likelihood, so an input that does not help on a
drive, or a process noise that does not fit it, is weighed down by the drive's own
innovations (see :mod:`posbench.predictors.kf_bank`, the same idea for ``kf``). Fixes
that state no accuracy have their noise estimated from the fixes themselves
(``fix_noise_memory``, 30 fixes).

Units: seconds, metres, radians, local ENU.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from posbench.predictors._geometry import check_config
from posbench.predictors.bank import ModelBank
from posbench.predictors.ekf import EKF_FLAT, EKF_INPUTS, CtraEkf
from posbench.predictors.filter_inputs import CtraImuInput, CtraSpeedInput, GnssInput
from posbench.predictors.kf_bank import HORIZONS_S

#: (jerk_psd [m^2/s^5], yaw_acc_psd [rad^2/s^3]) of the members, gentle to agile
NOISE_LEVELS = ((0.5, 0.03), (4.0, 0.3), (32.0, 3.0), (256.0, 10.0))


#: the aided members' inputs: as :class:`~posbench.predictors.ekf.CtraEkf`'s, with the
#: fixes' noise estimated over 30 fixes
BANK_INPUTS: dict[str, Any] = {**EKF_INPUTS, "gnss": GnssInput(noise_memory=30.0)}


class EkfBank(ModelBank):
    """CTRA EKFs, aided and fixes-only at several process noises, selected by the
    likelihood of their fix predictions (module docstring).

    Args:
        noise_levels: ``(jerk_psd, yaw_acc_psd)`` pairs, one pair of members each.
        jerk_psd, yaw_acc_psd: one level instead of ``noise_levels`` (a bank of one aided
            and one fixes-only member; the one not given takes
            :class:`~posbench.predictors.ekf.CtraEkf`'s default), e.g. ``--set ekf.jerk_psd=4``.
        gnss, imu, speed: the aided members' inputs (:mod:`~posbench.predictors.filter_inputs`;
            defaults :data:`BANK_INPUTS`); a fixes-only member takes ``gnss`` alone.
        pos_psd, init_vel_sigma, calib_psd: every member's
            (:class:`~posbench.predictors.ekf.CtraEkf`).
        memory_fixes: exponential memory of the member scores, in fixes.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's own
            covariance.
        horizons_s, horizon_memory: the horizons [s] members are also scored at and the
            memory of those scores (:class:`~posbench.predictors.bank.ModelBank`); ``[]``:
            one fix ahead only.
        **flat: the inputs' fields by their flat names (``gps_sigma``, ``yaw_rate_sigma``,
            ``use_speed``, ...: :data:`~posbench.predictors.ekf.EKF_FLAT`), as ``--set ekf.X``
            and tuning files give them.
    """

    name = "ekf"

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
        inputs = EKF_FLAT.compose(
            "ekf", {"gnss": gnss, "imu": imu, "speed": speed}, BANK_INPUTS, flat
        )
        self.inputs = inputs
        self.noise_levels = levels
        self._member: dict[str, Any] = {
            "pos_psd": pos_psd,
            "init_vel_sigma": init_vel_sigma,
            "calib_psd": calib_psd,
        }
        members, labels = [], []
        for j, w in levels:
            members.append(CtraEkf(j, w, **inputs, **self._member))
            labels.append(f"aided j{j:g} w{w:g}")
            # a fixes-only member takes no sensor input at all
            members.append(CtraEkf(j, w, gnss=inputs["gnss"], imu=None, speed=None, **self._member))
            labels.append(f"fixes j{j:g} w{w:g}")
        super().__init__(
            members,
            labels,
            memory_fixes=memory_fixes,
            cov_scale=cov_scale,
            horizons_s=horizons_s,
            horizon_memory=horizon_memory,
        )

    @classmethod
    def flat_options(cls) -> dict[str, Any]:
        """The flat option names and their defaults (for ``bench predictors`` and
        ``--set`` checks)."""
        return EKF_FLAT.flatten(BANK_INPUTS, BANK_INPUTS)

    def config(self) -> dict:
        return {
            **EKF_FLAT.flatten(self.inputs, BANK_INPUTS),
            **self._member,
            "noise_levels": [list(p) for p in self.noise_levels],
            "memory_fixes": self.memory_fixes,
            "cov_scale": self.cov_scale,
            "horizons_s": list(self.horizons_s),
            "horizon_memory": self.horizon_memory,
        }
