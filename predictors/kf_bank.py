"""``kf``: the constant-acceleration linear Kalman filter as a bank that adapts to its data.

Members: :class:`~posbench.predictors.kf.LinearKalman` at each white-jerk density of
``jerk_psds`` [m^2/s^5] (motorway-smooth to city manoeuvres), each once *aided* (IMU
acceleration and wheel speed) and once on fixes alone. The aided members treat the IMU
as the raw sensor it may be: vehicle-frame accelerometer bias estimated from the
innovations, noise adapted to the innovations, 99.9 % innovation gate, heading from fix
chords longer than their noise carried by the gyro (never from a velocity that is
mostly noise). Fixes that state no accuracy have their noise estimated from the fixes
themselves. :class:`~posbench.predictors.bank.ModelBank` answers with the member
whose predictions of the fixes have the highest recent likelihood, so an input that
does not help on a drive (a tilted, late or vibrating IMU, a mis-scaled wheel speed) or
a process noise that does not fit it is weighed down by the drive's own innovations.
By construction the fixes-only members keep the bank near the best fixes-only filter
wherever the aiding misleads.

Units: seconds, metres, local ENU.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from posbench.predictors._accel_bias import AccelBiasEstimator
from posbench.predictors._geometry import check_config
from posbench.predictors._heading import CourseHeading
from posbench.predictors.bank import ModelBank
from posbench.predictors.filter_inputs import AccelInput, GnssInput, HeadingInput, SpeedInput
from posbench.predictors.kf import KF_FLAT, LinearKalman

#: white-jerk densities of the members [m^2/s^5]: from ~0.7 m/s^3 over a second (steady
#: motorway) to ~16 m/s^3 (hard city manoeuvres); a factor 8 apart
JERK_PSDS = (0.5, 4.0, 32.0, 256.0)

#: horizons [s] the members are also scored at, for queries that far after the newest fix
#: (outages; :class:`~posbench.predictors.bank.ModelBank`)
HORIZONS_S = (1.0, 3.0)


#: the aided members' inputs: the IMU as the raw sensor it may be (vehicle-frame bias
#: estimated over 30 s, noise adapted over 5 s, 99.9 % innovation gate), the heading from
#: fix chords where the IMU states no yaw, the fixes' noise estimated over 30 fixes
BANK_INPUTS: dict[str, Any] = {
    "gnss": GnssInput(noise_memory=30.0),
    "imu": AccelInput(bias_tau_s=30.0, gate=13.8, noise_tau_s=5.0),
    "heading": HeadingInput(from_fixes=True),
    "speed": SpeedInput(),
}


class KalmanBank(ModelBank):
    """Linear CA Kalman filters, aided and fixes-only at several process noises, selected
    by the likelihood of their fix predictions (module docstring).

    Args:
        gnss, imu, heading, speed: the aided members' inputs
            (:mod:`~posbench.predictors.filter_inputs`; defaults :data:`BANK_INPUTS`); a
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
            memory of those scores (:class:`~posbench.predictors.bank.ModelBank`); ``[]``:
            one fix ahead only.
        **flat: the inputs' fields by their flat names (``gps_sigma``, ``accel_sigma``,
            ``use_speed``, ...: :data:`~posbench.predictors.kf.KF_FLAT`), as ``--set kf.X``
            and tuning files give them.
    """

    name = "kf"

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
        check_config("kf", **{f"jerk_psds[{i}]": (j, 1e-9, 1e6) for i, j in enumerate(jerk_psds)})
        inputs = KF_FLAT.compose(
            "kf",
            {"gnss": gnss, "imu": imu, "heading": heading, "speed": speed},
            BANK_INPUTS,
            flat,
        )
        self.inputs = inputs
        self.init_vel_sigma = float(init_vel_sigma)
        self.init_acc_sigma = float(init_acc_sigma)
        self.jerk_psds = tuple(float(j) for j in jerk_psds)
        prior: dict[str, Any] = {
            "init_vel_sigma": self.init_vel_sigma,
            "init_acc_sigma": self.init_acc_sigma,
        }
        imu_in = inputs["imu"]
        course = CourseHeading()  # one heading tracker and bias estimator for the aided
        tau = imu_in.bias_tau_s if imu_in is not None else 0.0
        bias = AccelBiasEstimator(tau) if tau > 0.0 else None
        members, labels = [], []
        for j in self.jerk_psds:
            members.append(LinearKalman(j, **inputs, **prior, course=course, bias_estimator=bias))
            labels.append(f"aided j{j:g}")
            members.append(LinearKalman(j, gnss=inputs["gnss"], imu=None, speed=None, **prior))
            labels.append(f"fixes j{j:g}")
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
        return KF_FLAT.flatten(BANK_INPUTS, BANK_INPUTS)

    def config(self) -> dict:
        return {
            **KF_FLAT.flatten(self.inputs, BANK_INPUTS),
            "init_vel_sigma": self.init_vel_sigma,
            "init_acc_sigma": self.init_acc_sigma,
            "jerk_psds": list(self.jerk_psds),
            "memory_fixes": self.memory_fixes,
            "cov_scale": self.cov_scale,
            "horizons_s": list(self.horizons_s),
            "horizon_memory": self.horizon_memory,
        }
