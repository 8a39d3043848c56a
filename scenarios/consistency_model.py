"""The data consistency check's vocabulary: verdicts, every tolerance (:class:`Tolerances`),
one stream's :class:`Check` and a drive's :class:`Consistency` (the checks themselves are
:mod:`posbench.scenarios.consistency`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

PASS, WARN, FAIL, NA = "pass", "warn", "fail", "n/a"
VERDICTS = (PASS, WARN, FAIL, NA)
STREAMS = ("imu.yaw_rate", "imu.ax", "imu.yaw", "speed", "gps", "truth")
_RANK = {NA: 0, PASS: 1, WARN: 2, FAIL: 3}


@dataclass(frozen=True)
class Tolerances:
    """Every threshold of the check, with its unit and why (one place; see the README).

    Grid and reference:
        grid_hz: common grid [Hz]; 10 Hz resolves vehicle dynamics (yaw, speed change
            over >= 0.5 s) and is the fastest GPS rate in the shared data.
        smooth_s: sigma [s] of the Gaussian applied to both sides of a comparison; 0.5 s
            turns metre-scale fix noise into usable velocity, course and their rates
            without touching turns (2-10 s) more than the IMU side, which gets the same.
        max_fix_gap_s: no kinematics across a gap between fixes (or truth samples) longer
            than this [s].
        moving_mps: lowest speed [m/s] at which a course from positions stands for the
            vehicle's heading: below it the point tracked (antenna, INS) slips sideways by
            atan(l yaw_rate / v) (l ~ 1.5 m from the rear axle: 8 deg at 3 m/s in a
            0.3 rad/s turn), and its rate leads the yaw rate. The noise gates below can
            only raise it.
        rolling_mps: reference speed [m/s] above which the vehicle rolls: the samples of
            the ax bias, of a heading-rate (INS yaw) comparison and of a speed compared
            with a truth speed column (below it a wheel speed is quantised and a gyro sees
            only its bias).
        min_position_noise_m: floor [m, per axis] of the white position noise of a
            reference: a 1e-7 deg lat/lon step is 1.1 cm (sd 3 mm), so a noise-free or
            rounded track still gets a finite noise gate.
        course_rate_noise_ratio: largest ratio N / S of a course-rate reference's noise to
            its signal on the samples used. White position noise sigma [m per axis],
            sampled every T [s] and smoothed by :attr:`smooth_s` = s, gives a lateral
            acceleration noise g_a sigma, g_a = sqrt(3 T / (8 sqrt(pi) s^5)) (0.82 /s^2 at
            T = 0.1 s), so a course-rate noise g_a sigma / v [rad/s] at speed v [m/s]: N is
            its RMS over the samples, S the sd of the reference there less that noise.
            Samples are used from the lowest speed at which N / S <= 0.5: a perfect gyro
            then reads a scale and correlation >= 1 / sqrt(1 + 0.5^2) = 0.89 (the reduced
            major axis slope is S / sqrt(S^2 + N^2)), inside the 25 % scale and 0.7
            correlation warnings, so a reference that is noise cannot fail or warn a
            gyro (0.3 m of noise at 3 m/s, N / S ~ 1.5, read a scale of 0.5); a sign flip
            still reads a correlation <= -0.89.
        sign_noise_ratio: the same ratio up to which the course rate still judges a
            gyro's sign alone (where too few samples meet the ratio above): at N / S = 2
            a correct gyro reads a correlation >= 1 / sqrt(1 + 2^2) = 0.45, so a clear
            negative correlation (<= -:attr:`corr_fail`) is a flipped gyro, not noise;
            scale and correlation are then not judged.
        course_noise_deg: largest 1-sigma noise [deg] of a course reference sample
            (velocity noise sqrt(T / (4 sqrt(pi) s^3)) sigma, 0.34 sigma at T = 0.1 s,
            over the speed): 3 deg is a third of the 10 deg yaw offset that warns.
        min_samples_s: at least this much usable, moving data [s] for a verdict.
        min_turn_rad_s: standard deviation of the reference's course (or heading) rate
            [rad/s] needed to judge a gyro (a straight highway has none: sign and scale
            are then unknowable); a truth yaw whose differentiated noise exceeds it is
            no heading-rate reference.
        min_accel_mps2: standard deviation of d(speed)/dt [m/s^2] needed to judge ax.
        max_lag_s: cross-correlation searched within +- this [s].
        min_extent_m: RMS distance of the fixes from their centroid [m] needed to fit a
            scale and rotation between GPS and truth.

    Verdicts (warn / fail):
        corr_warn, corr_fail: correlation with the reference below which the
            stream is doubtful / unrelated to the motion (sign is judged only if
            |corr| >= corr_fail).
        scale_warn, scale_fail: |log(scale)| above log(1 + x): x = 0.25 / 1.0 for a
            gyro or accelerometer (a least-squares slope against a noisy position-derived
            signal reads low by the noise share, so 25 % is a real error; x2 a unit or
            axis mix-up).
        speed_scale_warn, speed_scale_fail: the same for wheel speed vs the reference
            speed: tyre wear and pressure give 1-3 %, so 5 % is suspicious and 15 % wrong
            (a wheel speed in km/h read as m/s is 260 %).
        bias_warn_mps2, bias_fail_mps2: |mean(ax - dv/dt)| [m/s^2]. A road's slope puts
            g sin(grade) into an accelerometer: a whole drive averaging 4 deg of climb
            gives 0.7, and no drivable route averages 9 deg (1.5); gravity left in by a
            tilted or sideways mount gives 1.5-9.8.
        lag_warn_s: |lag| [s] above which time stamps of the stream are suspect (0.2 s is
            one prediction horizon).
        lag_min_corr: the lag is judged only where the cross-correlation peak reaches
            this (a broad, low peak places its maximum anywhere within +-0.5 s).
        max_fix_accuracy_m: fixes stating a worse accuracy [m] are no reference for the
            other streams (5 m over the 0.5 s smoothing is metres per second of noise);
            a source whose median is worse gets a ``gps`` warning (a poor receiver).
        yaw_offset_warn_deg, yaw_offset_fail_deg: |circular mean(yaw - reference)| [deg]:
            side slip and magnetic declination stay below 10 deg; 30 deg is a yaw in
            another frame (magnetic north far from here, or relative to power-on). A
            truth yaw column whose offset or spread about the truth's own course exceeds
            the fail value is no heading (another frame or sign) and is not used.
        yaw_spread_warn_deg: circular standard deviation [deg] of yaw - reference while
            moving above which the yaw does not follow it.
        gps_truth_offset_warn_m, gps_truth_offset_fail_m: |mean(gps - truth)| [m] when
            the fixes state no accuracy: consumer receivers sit within 1-3 m of the
            truth; 10 m is another frame or datum. Where an accuracy is stated these are
            floors of the limits below; a receiver beyond the warn value whose stated
            accuracy explains it is a ``gps`` warning (poor receiver), not the truth's.
        gps_truth_rms_warn_m, gps_truth_rms_fail_m: the same for the RMS of gps - truth.
        gps_truth_sigma_warn, gps_truth_sigma_fail: offset and RMS of gps - truth, in units
            of the stated horizontal 1-sigma sqrt(2 (acc_gps^2 + acc_truth^2)) [m], that
            the stated accuracy cannot explain: a fix's horizontal error has that RMS,
            and a drive's mean of slowly varying (multipath) errors is at most about it;
            3x is a source understating its error, 10x (as :attr:`scatter_ratio_fail`)
            no receiver's error but a truth in another frame or datum.
        fit_explained_k: rotation [rad] and |scale - 1| of the GPS-to-truth fit that the
            stated accuracy explains: k sqrt(2) acc / extent (biases of k x the stated
            horizontal 1-sigma in opposite directions at the two ends of a drive of that
            RMS extent tilt or stretch the fit by as much); added to the limits below.
        rot_warn_deg, rot_fail_deg: rotation [deg] of the fit (frames should agree).
        truth_scale_warn, truth_scale_fail: |scale - 1| of the fit (1 %: a local
            projection error over a few km; 5 %: a different projection).
        scatter_ratio_warn, scatter_ratio_fail: fix scatter / stated median accuracy:
            the source understates its own error 3x / 10x (what it says cannot be the
            noise it has).
    """

    grid_hz: float = 10.0
    smooth_s: float = 0.5
    max_fix_gap_s: float = 1.0
    moving_mps: float = 3.0
    rolling_mps: float = 1.0
    min_position_noise_m: float = 0.005
    course_rate_noise_ratio: float = 0.5
    sign_noise_ratio: float = 2.0
    course_noise_deg: float = 3.0
    min_samples_s: float = 10.0
    min_turn_rad_s: float = 0.03
    min_accel_mps2: float = 0.15
    max_lag_s: float = 1.0
    min_extent_m: float = 30.0

    corr_warn: float = 0.7
    corr_fail: float = 0.3
    scale_warn: float = 0.25
    scale_fail: float = 1.0
    speed_scale_warn: float = 0.05
    speed_scale_fail: float = 0.15
    bias_warn_mps2: float = 0.7
    bias_fail_mps2: float = 1.5
    lag_warn_s: float = 0.2
    lag_min_corr: float = 0.9
    max_fix_accuracy_m: float = 5.0
    yaw_offset_warn_deg: float = 10.0
    yaw_offset_fail_deg: float = 30.0
    yaw_spread_warn_deg: float = 15.0
    gps_truth_offset_warn_m: float = 3.0
    gps_truth_offset_fail_m: float = 10.0
    gps_truth_rms_warn_m: float = 3.0
    gps_truth_rms_fail_m: float = 10.0
    gps_truth_sigma_warn: float = 3.0
    gps_truth_sigma_fail: float = 10.0
    fit_explained_k: float = 3.0
    rot_warn_deg: float = 1.0
    rot_fail_deg: float = 5.0
    truth_scale_warn: float = 0.01
    truth_scale_fail: float = 0.05
    scatter_ratio_warn: float = 3.0
    scatter_ratio_fail: float = 10.0


TOLERANCES = Tolerances()


@dataclass
class Check:
    """One stream's verdict: ``figures`` (named numbers, units in the names), the
    ``verdict`` and ``reason`` (the figure that decided it and the reference it was
    judged against, or why it is n/a)."""

    stream: str
    verdict: str
    reason: str = ""
    figures: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """As plain JSON values (a non-finite figure as None)."""
        d = asdict(self)
        d["figures"] = {k: (float(v) if np.isfinite(v) else None) for k, v in self.figures.items()}
        return d


@dataclass
class Consistency:
    """All checks of one drive, by stream (:data:`STREAMS` order)."""

    drive: str
    checks: dict[str, Check]

    def failures(self) -> list[Check]:
        return [c for c in self.checks.values() if c.verdict == FAIL]

    def warnings(self) -> list[Check]:
        return [c for c in self.checks.values() if c.verdict == WARN]

    def to_dict(self) -> dict[str, Any]:
        return {s: c.to_dict() for s, c in self.checks.items()}


def worst(verdicts: list[str]) -> str:
    """The worst of several verdicts (fail > warn > pass > n/a)."""
    return max(verdicts, key=_RANK.__getitem__) if verdicts else NA


def na(stream: str, reason: str, **figures: float) -> Check:
    """An ``n/a`` check with its reason."""
    return Check(stream, NA, reason, dict(figures))
