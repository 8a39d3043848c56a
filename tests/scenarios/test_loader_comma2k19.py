"""comma2k19 segment loader on the shared 60 s segment (and a damaged copy of it)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders import load
from posbench.scenarios.loaders.comma2k19 import load_comma_segment

pytestmark = pytest.mark.shared

NAME = "b0c9d2329ad1606b_2018-08-02--08-34-47/40"


@pytest.fixture(scope="module")
def seg(comma_dir: Path) -> Path:
    return comma_dir / NAME


@pytest.fixture(scope="module")
def drive(comma_dir: Path) -> Drive:
    (d,) = load(comma_dir)
    return d


def _truth_at(d: Drive, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.interp(t, d.truth.t, d.truth.x), np.interp(t, d.truth.t, d.truth.y)


def _smooth(a: np.ndarray, n: int = 20) -> np.ndarray:
    return np.convolve(a, np.ones(n) / n, mode="same")[n:-n]


def test_identity_and_streams(drive: Drive):
    assert drive.name == NAME
    assert drive.meta.format == "comma2k19"
    assert drive.duration_s == pytest.approx(60.0, abs=1.0)
    starts = [s.t[0] for s in (drive.gps, drive.imu, drive.speed, drive.truth)]
    assert min(starts) == 0.0
    assert len(drive.gps) == 579 and len(drive.truth) == 1200
    assert 95 < len(drive.imu) / drive.duration_s < 110  # ~104 Hz
    assert drive.imu.yaw is None and drive.imu.yaw_rate is not None
    assert drive.gps.accuracy is None
    # 2018-08-02 16:14:48 UTC (route 08:34:47 PDT + 40 min)
    assert drive.meta.epoch_s == pytest.approx(1533226488.4, abs=1.0)
    assert drive.meta.warnings == []


def test_speeds(drive: Drive):
    assert 7.5 < drive.speed.v.min() and drive.speed.v.max() < 20.5
    assert 7.5 < drive.truth.v.min() and drive.truth.v.max() < 20.5
    v_truth = np.interp(drive.speed.t, drive.truth.t, drive.truth.v)
    assert np.median(np.abs(drive.speed.v - v_truth)) < 0.3


def test_gnss_close_to_truth_after_lag(drive: Drive):
    g = drive.gps
    tx, ty = _truth_at(drive, g.t)
    err = np.hypot(g.x - tx, g.y - ty)
    assert np.median(err) < 1.0 and err.max() < 2.0
    lag = drive.meta.extra["gnss_lag_measured_s"]
    assert 0.03 < lag < 0.15  # README: ~0.1 s; measured 0.082 s
    assert drive.meta.extra["gnss_lag_applied_s"] == 0.1


def test_uncorrected_fixes_lag_the_truth(seg: Path, drive: Drive):
    raw = load_comma_segment(seg, gnss_lag_s=0.0)
    tx, ty = _truth_at(raw, raw.gps.t)
    err_raw = np.median(np.hypot(raw.gps.x - tx, raw.gps.y - ty))
    tx, ty = _truth_at(drive, drive.gps.t)
    err = np.median(np.hypot(drive.gps.x - tx, drive.gps.y - ty))
    assert err_raw > err + 0.5  # 1.43 m vs 0.53 m at 8-20 m/s


def test_truth_yaw_matches_direction_of_travel(drive: Drive):
    tr = drive.truth
    heading = np.arctan2(np.gradient(tr.y, tr.t), np.gradient(tr.x, tr.t))
    diff = np.degrees(np.abs(np.angle(np.exp(1j * (heading - tr.yaw)))))
    assert np.median(diff) < 3.0


def test_imu_axes_converted(drive: Drive):
    tr, imu = drive.truth, drive.imu
    yaw_rate_truth = np.gradient(np.unwrap(tr.yaw), tr.t)
    yr = np.interp(tr.t, imu.t, imu.yaw_rate)
    assert np.corrcoef(yaw_rate_truth, yr)[0, 1] > 0.6  # measured 0.82; flipped sign < 0
    ax = np.interp(tr.t, imu.t, imu.ax)
    assert np.corrcoef(_smooth(np.gradient(tr.v, tr.t)), _smooth(ax))[0, 1] > 0.5
    ay = np.interp(tr.t, imu.t, imu.ay)
    lateral = tr.v * yaw_rate_truth  # centripetal, left positive
    assert np.corrcoef(_smooth(lateral), _smooth(ay))[0, 1] > 0.3  # measured 0.64
    # gravity does not leak into the horizontal axes much
    assert abs(np.median(imu.ax)) < 1.5 and abs(np.median(imu.ay)) < 1.5


def test_mercator_projects_both_streams(seg: Path, drive: Drive):
    m = load_comma_segment(seg, projection="mercator")
    assert m.meta.projection == "mercator"
    scale = 1 / np.cos(np.radians(m.meta.origin_lat))
    span_enu = np.hypot(drive.truth.x[-1], drive.truth.y[-1])
    assert np.hypot(m.truth.x[-1], m.truth.y[-1]) == pytest.approx(span_enu * scale, rel=0.01)
    tx, ty = _truth_at(m, m.gps.t)
    assert np.median(np.hypot(m.gps.x - tx, m.gps.y - ty)) < 1.0 * scale


def test_missing_gnss_is_an_error(seg: Path, tmp_path: Path):
    dst = tmp_path / "route" / "7"
    shutil.copytree(seg, dst)
    (dst / "processed_log" / "GNSS" / "live_gnss_ublox" / "value").unlink()
    with pytest.raises(DataError, match=r"live_gnss_ublox/value: file missing"):
        load_comma_segment(dst)


def test_damaged_array_is_an_error(seg: Path, tmp_path: Path):
    dst = tmp_path / "route" / "7"
    shutil.copytree(seg, dst)
    (dst / "global_pose" / "frame_times").write_bytes(b"not numpy")
    with pytest.raises(DataError, match=r"frame_times: not a NumPy array file"):
        load_comma_segment(dst)


def test_unsorted_gnss_warns(seg: Path, tmp_path: Path):
    dst = tmp_path / "route" / "7"
    shutil.copytree(seg, dst)
    tf = dst / "processed_log" / "GNSS" / "live_gnss_ublox" / "t"
    t = np.load(tf)
    t[[5, 6]] = t[[6, 5]]
    with open(tf, "wb") as fh:
        np.save(fh, t)
    d = load_comma_segment(dst)
    assert d.name == "route/7"
    assert any("gnss: re-sorted 1" in w for w in d.meta.warnings)
