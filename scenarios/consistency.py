"""Consistency of a drive's streams with each other, from the data alone, before any figure.

Every motion stream is compared with the reference kinematics: the TRUTH's when the drive
has one (its x/y, and its ``yaw`` and ``v`` columns when present), else what the GPS fixes
imply; the GPS is compared with the truth, relative to the accuracy the fixes state. On a
common grid of :attr:`Tolerances.grid_hz`:

========================  =====================================================  ===========
stream                    check                                                  figures
========================  =====================================================  ===========
``imu.yaw_rate``          gyro yaw rate vs the truth's heading rate (its yaw)    sign, scale,
                          or the course rate of the positions above the speed    corr, lag_s
                          where their noise allows
``imu.ax``                longitudinal acceleration vs d(speed)/dt (the truth    scale, corr,
                          speed; without truth the speed stream's, else GPS)     bias_mps2
``imu.yaw``               IMU yaw vs the truth yaw or the course: circular mean  offset_deg,
                          offset and spread                                      spread_deg
``speed``                 wheel/CAN speed vs the truth (else GPS) speed          scale, corr
``gps``                   scatter of the fixes about their neighbours vs the     scatter_m,
                          accuracy the source states; distance from the truth    stated_m,
                          (a poor receiver warns here)                           truth_rms_m
``truth``                 GPS vs truth: offset, RMS, 2-D similarity fit (scale,  offset_m,
                          rotation), limits widened by the stated accuracy       scale, ...
========================  =====================================================  ===========

Each check gives a :class:`Check` with a verdict ``pass`` / ``warn`` / ``fail`` / ``n/a``
and a reason naming the figure that decided it and the reference it used ("vs truth heading
rate", "vs GPS course rate", ...). Every tolerance is in :class:`Tolerances` (units and the
physics behind each value). Frames: positions in the drive's local metres, yaw and course
ENU radians (0 = east, counter-clockwise), vehicle x forward. Signs: ``lag_s`` > 0 means
the IMU stream is late (its stamps trail the reference's by that many seconds).

A reference that is noise is no reference: a course from positions is used only above the
speed where the positions' white noise, amplified by differentiation after the
:attr:`Tolerances.smooth_s` smoothing, stays below :attr:`Tolerances.course_noise_deg`, and
a course rate only where that noise stays below :attr:`Tolerances.course_rate_noise_ratio`
x the turning it carries; with too few samples left the verdict is
``n/a`` with that reason (:mod:`posbench.scenarios.consistency_reference`). A truth that
fails its own check is no reference either: the motion streams are then judged against
the fixes.

Modules by role: :mod:`~posbench.scenarios.consistency_model` (verdicts, tolerances,
results), :mod:`~posbench.scenarios.consistency_stats` (scale, correlation, lag, scatter),
:mod:`~posbench.scenarios.consistency_reference` (reference kinematics and noise gates),
:mod:`~posbench.scenarios.consistency_motion` (IMU and speed checks),
:mod:`~posbench.scenarios.consistency_position` (gps and truth checks); this module joins
them (:func:`check_drive`) and re-exports their public names.
"""

from __future__ import annotations

from posbench.scenarios.consistency_model import (
    FAIL,
    NA,
    PASS,
    STREAMS,
    TOLERANCES,
    VERDICTS,
    WARN,
    Check,
    Consistency,
    Tolerances,
    worst,
)
from posbench.scenarios.consistency_motion import (
    check_ax,
    check_speed,
    check_yaw,
    check_yaw_rate,
)
from posbench.scenarios.consistency_position import (
    GpsVsTruth,
    check_gps,
    check_truth,
    gps_vs_truth,
)
from posbench.scenarios.consistency_reference import (
    GpsKinematics,
    Reference,
    course_gate_mps,
    derivative_noise_gains,
    gps_kinematics,
    position_noise_m,
    rate_gate_mps,
    truth_kinematics,
)
from posbench.scenarios.consistency_stats import best_lag, fix_scatter, slope_corr
from posbench.scenarios.drive import Drive

__all__ = [
    "FAIL",
    "NA",
    "PASS",
    "STREAMS",
    "TOLERANCES",
    "VERDICTS",
    "WARN",
    "Check",
    "Consistency",
    "GpsKinematics",
    "GpsVsTruth",
    "Reference",
    "Tolerances",
    "best_lag",
    "check_ax",
    "check_drive",
    "check_gps",
    "check_speed",
    "check_truth",
    "check_yaw",
    "check_yaw_rate",
    "derivative_noise_gains",
    "fix_scatter",
    "gps_kinematics",
    "gps_vs_truth",
    "course_gate_mps",
    "position_noise_m",
    "rate_gate_mps",
    "reference_kinematics",
    "slope_corr",
    "truth_kinematics",
    "worst",
]


def reference_kinematics(
    drive: Drive, tol: Tolerances = TOLERANCES, truth_check: Check | None = None
) -> Reference | None:
    """The reference the motion streams are judged against: the truth's kinematics when
    the drive has a truth that did not fail its check (``truth_check``), else the fixes';
    None when neither has enough samples."""
    if drive.truth is not None and (truth_check is None or truth_check.verdict != FAIL):
        ref = truth_kinematics(drive, tol)
        if ref is not None:
            return ref
    return gps_kinematics(drive, tol)


def check_drive(drive: Drive, tol: Tolerances = TOLERANCES) -> Consistency:
    """Every check of :data:`STREAMS` on one drive (pure: reads the drive only)."""
    cmp = gps_vs_truth(drive, tol)
    truth = check_truth(drive, tol, cmp)
    kin = reference_kinematics(drive, tol, truth)
    checks = [
        check_yaw_rate(drive, kin, tol),
        check_ax(drive, kin, tol),
        check_yaw(drive, kin, tol),
        check_speed(drive, kin, tol),
        check_gps(drive, tol, cmp),
        truth,
    ]
    return Consistency(drive.name, {c.stream: c for c in checks})
