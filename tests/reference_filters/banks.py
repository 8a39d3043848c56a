"""A row bank's members as objects under a :class:`ModelBank`: the reference the rows of
``kf`` and ``ekf`` answer as (tests/predictors/test_kf_batched.py, test_ekf_batched.py)."""

from __future__ import annotations

from typing import Any

from posbench.predictors.kalman.accel_bias import AccelBiasEstimator
from posbench.predictors.kalman.course_heading import CourseHeading
from posbench.predictors.kalman.ekf import EkfBank
from posbench.predictors.kalman.kf import KalmanBank
from posbench.predictors.kalman.row_bank import RowBank
from posbench.scenarios.drive import Drive
from posbench.scenarios.synthetic import default_drives
from reference_filters.ctra_ekf import CtraEkf
from reference_filters.linear_kalman import LinearKalman
from reference_filters.model_bank import ModelBank

#: the parity tests' synthetic cases: the default drives (by index) each (GPS profile,
#: dropouts) pair replays; every drive under both profiles and both dropout settings, each
#: pair on half the drives (the member objects are slow Python)
SYNTHETIC_CASES = {
    ("rtk", "none"): (0, 1),
    ("native", "outages"): (0, 1),
    ("rtk", "outages"): (2, 3),
    ("native", "none"): (2, 3),
}
#: their test ids: ``rtk-none``, ...
SYNTHETIC_IDS = [f"{profile}-{dropouts}" for profile, dropouts in SYNTHETIC_CASES]


def synthetic_drives(profile: str, dropouts: str) -> list[Drive]:
    """The default drives the case ``(profile, dropouts)`` of :data:`SYNTHETIC_CASES` replays."""
    drives = default_drives()
    return [drives[i] for i in SYNTHETIC_CASES[profile, dropouts]]


def member_bank(bank: RowBank) -> ModelBank:
    """``bank`` (a :class:`KalmanBank` or :class:`EkfBank`) as member objects, in its rows'
    order, under a :class:`ModelBank` with its selection options."""
    if isinstance(bank, KalmanBank):
        members = _kf_members(bank)
    elif isinstance(bank, EkfBank):
        members = _ekf_members(bank)
    else:
        raise TypeError(f"no member objects for {type(bank).__name__}")
    return ModelBank(
        members,
        bank.labels,
        memory_fixes=bank.memory_fixes,
        huber_k=bank.huber_k,
        cov_scale=bank.cov_scale,
        horizons_s=bank.horizons_s,
        horizon_memory=bank.horizon_memory,
    )


def _kf_members(bank: KalmanBank) -> list[Any]:
    inputs = bank.inputs
    prior = {"init_vel_sigma": bank.init_vel_sigma, "init_acc_sigma": bank.init_acc_sigma}
    imu_in = inputs["imu"]
    course = CourseHeading()  # one heading tracker and bias estimator for the aided
    tau = imu_in.bias_tau_s if imu_in is not None else 0.0
    bias = AccelBiasEstimator(tau) if tau > 0.0 else None
    members: list[Any] = []
    for j in bank.jerk_psds:
        members.append(LinearKalman(j, **inputs, **prior, course=course, bias_estimator=bias))
        members.append(LinearKalman(j, gnss=inputs["gnss"], imu=None, speed=None, **prior))
    return members


def _ekf_members(bank: EkfBank) -> list[Any]:
    inputs = bank.inputs
    members: list[Any] = []
    for j, w in bank.noise_levels:
        members.append(CtraEkf(j, w, **inputs, **bank._member))
        # a fixes-only member takes no sensor input at all
        members.append(CtraEkf(j, w, gnss=inputs["gnss"], imu=None, speed=None, **bank._member))
    return members
