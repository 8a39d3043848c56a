"""The kf bank as rows of one array (predictors/kalman/ca_rows.py) answers as its members do.

:class:`~posbench.predictors.kalman.kf.KalmanBank` steps all its filters (and their
shadows) in one compiled call per observation; :meth:`KalmanBank.member_bank` builds the
same bank from :class:`~reference_filters.linear_kalman.LinearKalman` objects under a
:class:`~reference_filters.model_bank.ModelBank`, the readable reference. Both replay the
same drives (synthetic, and one of each shared data set: aslan, KITTI, comma2k19), with
and without simulated outages, with the fixes' own accuracy and simulated RTK, and under
options that take other paths through the step (no IMU, no speed, a single density, no
heading from fixes, no horizons); every answer, covariance and the member each query is
answered by must agree to 1e-9 m. The rows are plain compiled arithmetic, not a copy of the
members' rounding; measured (2026-11-28): every answer identical to the members', the
covariances within 2.2e-19 m^2.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from reference_filters.banks import SYNTHETIC_CASES, SYNTHETIC_IDS, member_bank, synthetic_drives

from posbench.config import RunConfig
from posbench.predictors.kalman.kf import KalmanBank
from posbench.replay.loop import replay
from posbench.replay.prepare import prepare_drive
from posbench.scenarios.drive import Drive
from posbench.scenarios.synthetic import generate_drive

TOL_M = 1e-9


def assert_same_answers(drive: Drive, dropouts: str, profile: str, **options: Any) -> None:
    prep = prepare_drive(drive, RunConfig(dropouts=dropouts, gps_profile=profile))
    fast = KalmanBank(**options)
    ref = member_bank(fast)
    a, b = replay(fast, prep, 0.2), replay(ref, prep, 0.2)
    assert np.isfinite(a.future_xy).any()
    for x, y in ((a.future_xy, b.future_xy), (a.now_xy, b.now_xy), (a.cov, b.cov)):
        assert x is not None and y is not None
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
        ok = np.isfinite(x)
        assert np.max(np.abs(x[ok] - y[ok]), initial=0.0) <= TOL_M, (drive.name, options)
    assert fast.scores.tolist() == pytest.approx(ref.scores, abs=1e-9)
    hs = np.asarray(ref.horizon_scores).reshape(fast.horizon_scores.shape)
    np.testing.assert_allclose(fast.horizon_scores, hs, rtol=0.0, atol=1e-9)
    assert fast.best == ref.best and fast.horizon_best == ref.horizon_best


@pytest.mark.parametrize(("profile", "dropouts"), SYNTHETIC_CASES, ids=SYNTHETIC_IDS)
def test_rows_answer_as_the_members_on_synthetic_drives(profile: str, dropouts: str) -> None:
    for d in synthetic_drives(profile, dropouts):
        assert_same_answers(d, dropouts, profile)


OPTIONS = [
    {"use_imu": False},
    {"use_speed": False},
    {"jerk_psd": 4.0},
    {"heading_from_fixes": False},
    {"horizons_s": []},
    {"imu_gate": 0.0, "accel_bias_tau_s": 0.0, "imu_noise_tau_s": 0.0},
    {"cov_scale": 2.5, "gps_split": False},
]


@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: ",".join(o))
def test_rows_answer_as_the_members_under_other_options(options: dict[str, Any]) -> None:
    d = generate_drive(seed=3601, route="mixed", duration_s=90.0)
    assert_same_answers(d, "outages", "native", **options)


@pytest.mark.parametrize("which", [0, 1, 2], ids=["aslan", "kitti", "comma2k19"])
@pytest.mark.parametrize("dropouts", ["none", "outages"])
def test_rows_answer_as_the_members_on_shared_drives(
    filter_parity_drives: list[Drive], which: int, dropouts: str
) -> None:
    for profile in ("native", "rtk"):
        assert_same_answers(filter_parity_drives[which], dropouts, profile)


def test_building_predictors_leaves_numba_unimported() -> None:
    """The kernels compile when a bank first steps (predictors/_kernels.py): a process that
    only builds predictors (bench run's planning) never pays numba's and LLVM's ~100 MB."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from posbench.predictors.registry import create\n"
        "for name in ('cv', 'kf', 'ekf', 'lstm', 'hybrid'):\n"
        "    create(name).reset()\n"
        "print('numba' in sys.modules, 'llvmlite' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.split() == ["False", "False"], out.stdout + out.stderr


def test_positions_at_answers_as_position_at() -> None:
    """The hybrid's prior at its horizons in one call: each position bit for bit what
    ``position_at`` answers for that time (members chosen per horizon), before the first
    fix (NaN) and after every observation of a drive with an outage."""
    from posbench.replay.loop import GPS, events, feed

    drive = generate_drive(seed=3, route="roundabout")
    evs = events(prepare_drive(drive, RunConfig(dropouts="outages", gps_profile="consumer")))
    kf = KalmanBank()
    assert np.isnan(kf.positions_at((0.0, 1.0))).all()
    offsets = (-0.1, 0.0, 0.2, 0.4, 0.6, 0.8, 1.7)
    checked = 0

    def check(i: int) -> None:
        nonlocal checked
        t = evs[i][1]
        if evs[i][0] != GPS:
            return
        got = kf.positions_at(tuple(t + h for h in offsets))
        assert got.tolist() == [list(kf.position_at(t + h)) for h in offsets]
        checked += 1

    feed(kf, evs, 0.2, after=check)
    assert checked > 100
