"""The ekf bank as rows of one array (predictors/kalman/ctra_rows.py) answers as its members do.

:class:`~posbench.predictors.kalman.ekf.EkfBank` steps all its filters (and their shadows)
in one compiled call per observation; :meth:`EkfBank.member_bank` builds the same bank
from :class:`~reference_filters.ctra_ekf.CtraEkf` objects under a
:class:`~reference_filters.model_bank.ModelBank`, the readable reference. Both replay the
same drives (synthetic, and one of each shared data set: aslan, KITTI, comma2k19), with
and without simulated outages, with the fixes' own accuracy and simulated RTK, and under
options that take other paths through the step (no IMU, no speed, no IMU yaw, a single
noise level, no horizons, a scaled covariance without the split of the fixes' noise);
every answer and covariance must agree to 1e-9 m (1e-8 m under the option sets) and the
member each query is answered by must be the same.

The rows are written as plain compiled arithmetic (no copy of the members' BLAS rounding),
so they agree with the members to rounding, not to the bit. Measured on the development
machine (2026-11-28): at most 2.3e-13 m on every drive above, and 2.2e-9 m under
``use_imu=False``, where a fixes-only member that loses its heading at a standstill
amplifies a rounding difference ~10x a second; hence the looser tolerance under the
option sets. The member chosen was the same everywhere.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from reference_filters.banks import SYNTHETIC_CASES, SYNTHETIC_IDS, member_bank, synthetic_drives

from posbench.config import RunConfig
from posbench.predictors.kalman.ekf import EkfBank
from posbench.replay.loop import replay
from posbench.replay.prepare import prepare_drive
from posbench.scenarios.drive import Drive
from posbench.scenarios.synthetic import generate_drive

TOL_M = 1e-9
#: under the option sets, where members lose their heading more often (module docstring)
TOL_OPTIONS_M = 1e-8


def assert_same_answers(
    drive: Drive, dropouts: str, profile: str, tol: float = TOL_M, **options: Any
) -> None:
    prep = prepare_drive(drive, RunConfig(dropouts=dropouts, gps_profile=profile))
    fast = EkfBank(**options)
    ref = member_bank(fast)
    a, b = replay(fast, prep, 0.2), replay(ref, prep, 0.2)
    assert np.isfinite(a.future_xy).any()
    for x, y in ((a.future_xy, b.future_xy), (a.now_xy, b.now_xy), (a.cov, b.cov)):
        assert x is not None and y is not None
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
        ok = np.isfinite(x)
        assert np.max(np.abs(x[ok] - y[ok]), initial=0.0) <= tol, (drive.name, options)
    assert fast.best == ref.best and fast.horizon_best == ref.horizon_best
    assert fast.selected == ref.selected
    assert fast.slow_variance == ref.members[ref.best].slow_variance  # type: ignore[attr-defined]
    assert fast.fix_variance(0.5) == ref.fix_variance(0.5)


@pytest.mark.parametrize(("profile", "dropouts"), SYNTHETIC_CASES, ids=SYNTHETIC_IDS)
def test_rows_answer_as_the_members_on_synthetic_drives(profile: str, dropouts: str) -> None:
    for d in synthetic_drives(profile, dropouts):
        assert_same_answers(d, dropouts, profile)


OPTIONS = [
    {"use_imu": False},
    {"use_speed": False},
    {"use_imu_yaw": False},
    {"jerk_psd": 4.0},
    {"horizons_s": []},
    {"cov_scale": 2.5, "gps_split": False},
]


@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: ",".join(o))
def test_rows_answer_as_the_members_under_other_options(options: dict[str, Any]) -> None:
    d = generate_drive(seed=3601, route="mixed", duration_s=90.0)
    assert_same_answers(d, "outages", "native", TOL_OPTIONS_M, **options)


def test_a_bank_reset_answers_as_a_new_one() -> None:
    d = generate_drive(seed=3602, route="turns", duration_s=40.0)
    prep = prepare_drive(d, RunConfig(dropouts="outages"))
    bank = EkfBank()
    first = replay(bank, prep, 0.2)
    again = replay(bank, prep, 0.2)  # replay resets it
    np.testing.assert_array_equal(first.future_xy, again.future_xy)
    np.testing.assert_array_equal(first.cov, again.cov)


@pytest.mark.parametrize("which", [0, 1, 2], ids=["aslan", "kitti", "comma2k19"])
@pytest.mark.parametrize("dropouts", ["none", "outages"])
def test_rows_answer_as_the_members_on_shared_drives(
    filter_parity_drives: list[Drive], which: int, dropouts: str
) -> None:
    for profile in ("native", "rtk"):
        assert_same_answers(filter_parity_drives[which], dropouts, profile)
