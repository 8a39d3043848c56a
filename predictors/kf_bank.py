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
from typing import TypedDict

from posbench.predictors._accel_bias import AccelBiasEstimator
from posbench.predictors._geometry import check_config
from posbench.predictors._heading import CourseHeading
from posbench.predictors.bank import ModelBank
from posbench.predictors.kf import KMH, LinearKalman

#: white-jerk densities of the members [m^2/s^5]: from ~0.7 m/s^3 over a second (steady
#: motorway) to ~16 m/s^3 (hard city manoeuvres); a factor 8 apart
JERK_PSDS = (0.5, 4.0, 32.0, 256.0)

#: horizons [s] the members are also scored at, for queries that far after the newest fix
#: (outages; :class:`~posbench.predictors.bank.ModelBank`)
HORIZONS_S = (1.0, 3.0)


class _FixesOnlyOptions(TypedDict):
    """The options a fixes-only member takes (it has no IMU or speed to weigh), passed to
    :class:`~posbench.predictors.kf.LinearKalman`."""

    gps_sigma: float
    gps_sigma_scale: float
    init_vel_sigma: float
    init_acc_sigma: float
    fix_noise_memory: float
    gps_split: bool


class _MemberOptions(_FixesOnlyOptions):
    """The options every aided member takes: a fixes-only member's and those of the IMU,
    the wheel speed and the heading."""

    accel_sigma: float
    speed_sigma: float
    speed_rel_sigma: float
    stop_speed: float
    heading_sigma_max: float
    accel_bias_tau_s: float
    imu_gate: float
    imu_noise_tau_s: float


class KalmanBank(ModelBank):
    """Linear CA Kalman filters, aided and fixes-only at several process noises, selected
    by the likelihood of their fix predictions (module docstring).

    Args:
        gps_sigma, gps_sigma_scale, accel_sigma, speed_sigma, speed_rel_sigma, use_speed,
            stop_speed, init_vel_sigma, init_acc_sigma, heading_sigma_max,
            accel_bias_tau_s, imu_gate, imu_noise_tau_s, fix_noise_memory, gps_split: passed to
            every member
            (:class:`~posbench.predictors.kf.LinearKalman`); ``accel_sigma`` is the floor
            of the adapted IMU noise.
        jerk_psds: the members' white-jerk densities [m^2/s^5].
        jerk_psd: one density instead of ``jerk_psds`` (a bank of one aided and one
            fixes-only member), e.g. ``--set kf.jerk_psd=4``.
        memory_fixes: exponential memory of the member scores, in fixes.
        horizons_s, horizon_memory: the horizons [s] members are also scored at and the
            memory of those scores (:class:`~posbench.predictors.bank.ModelBank`); ``[]``:
            one fix ahead only.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's
            covariance (1: as its model says).
    """

    name = "kf"

    def __init__(
        self,
        gps_sigma: float = 0.3,
        gps_sigma_scale: float = 1.0,
        accel_sigma: float = 0.3,
        speed_sigma: float = 0.2,
        speed_rel_sigma: float = 0.03,
        use_speed: bool = True,
        stop_speed: float = 0.15 * KMH,
        init_vel_sigma: float = 15.0,
        init_acc_sigma: float = 3.0,
        heading_sigma_max: float = 0.15,
        accel_bias_tau_s: float = 30.0,
        imu_gate: float = 13.8,
        imu_noise_tau_s: float = 5.0,
        fix_noise_memory: float = 30.0,
        gps_split: bool = True,
        jerk_psds: Sequence[float] = JERK_PSDS,
        jerk_psd: float | None = None,
        memory_fixes: float = 20.0,
        cov_scale: float = 1.0,
        horizons_s: Sequence[float] = HORIZONS_S,
        horizon_memory: float = 10.0,
    ) -> None:
        if jerk_psd is not None:
            check_config("kf", jerk_psd=(jerk_psd, 1e-9, 1e6))
            jerk_psds = (jerk_psd,)
        check_config("kf", **{f"jerk_psds[{i}]": (j, 1e-9, 1e6) for i, j in enumerate(jerk_psds)})
        jerks = tuple(float(j) for j in jerk_psds)
        self._options: _MemberOptions = {
            "gps_sigma": gps_sigma,
            "gps_sigma_scale": gps_sigma_scale,
            "accel_sigma": accel_sigma,
            "speed_sigma": speed_sigma,
            "speed_rel_sigma": speed_rel_sigma,
            "stop_speed": stop_speed,
            "init_vel_sigma": init_vel_sigma,
            "init_acc_sigma": init_acc_sigma,
            "heading_sigma_max": heading_sigma_max,
            "accel_bias_tau_s": accel_bias_tau_s,
            "imu_gate": imu_gate,
            "imu_noise_tau_s": imu_noise_tau_s,
            "fix_noise_memory": fix_noise_memory,
            "gps_split": gps_split,
        }
        self.use_speed = bool(use_speed)
        self.jerk_psds = jerks
        members, labels = [], []
        o = self._options
        course = CourseHeading()  # one heading tracker and bias estimator for the aided
        bias = AccelBiasEstimator(accel_bias_tau_s) if accel_bias_tau_s > 0.0 else None
        fixes_only: _FixesOnlyOptions = {
            "gps_sigma": o["gps_sigma"],
            "gps_sigma_scale": o["gps_sigma_scale"],
            "init_vel_sigma": o["init_vel_sigma"],
            "init_acc_sigma": o["init_acc_sigma"],
            "fix_noise_memory": o["fix_noise_memory"],
            "gps_split": o["gps_split"],
        }
        for j in jerks:
            members.append(
                LinearKalman(
                    jerk_psd=j,
                    use_speed=self.use_speed,
                    heading_from_fixes=True,
                    course=course,
                    bias_estimator=bias,
                    **o,
                )
            )
            labels.append(f"aided j{j:g}")
            members.append(LinearKalman(jerk_psd=j, use_imu=False, use_speed=False, **fixes_only))
            labels.append(f"fixes j{j:g}")
        super().__init__(
            members,
            labels,
            memory_fixes=memory_fixes,
            cov_scale=cov_scale,
            horizons_s=horizons_s,
            horizon_memory=horizon_memory,
        )

    def config(self) -> dict:
        return {
            **self._options,
            "use_speed": self.use_speed,
            "jerk_psds": list(self.jerk_psds),
            "memory_fixes": self.memory_fixes,
            "cov_scale": self.cov_scale,
            "horizons_s": list(self.horizons_s),
            "horizon_memory": self.horizon_memory,
        }
