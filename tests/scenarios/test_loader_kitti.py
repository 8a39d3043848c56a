"""KITTI raw OXTS loader: all 46 shared drives, plus damaged copies of one small drive."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders import load
from posbench.scenarios.loaders.kitti import load_kitti_drive

pytestmark = pytest.mark.shared

SMALL = "2011_09_26/2011_09_26_drive_0001_sync"  # 108 samples, 11 s


@pytest.fixture(scope="module")
def drives(kitti_dir: Path):
    t0 = time.perf_counter()
    ds = load(kitti_dir)
    return ds, time.perf_counter() - t0


@pytest.fixture()
def small_copy(kitti_dir: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "2011_09_26_drive_0001_sync"
    shutil.copytree(kitti_dir / SMALL, dst)
    return dst


def _angdiff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (a - b))))


def test_all_46_drives_load_fast(drives, kitti_dir: Path):
    ds, elapsed = drives
    folders = sorted(p.name for p in kitti_dir.glob("*/*_sync"))
    assert len(ds) == 46
    assert sorted(d.name for d in ds) == folders
    assert all(d.meta.format == "kitti" for d in ds)
    # parsing ~33 000 small files; generous budget for a slow shared machine
    assert elapsed < 15.0, f"loading all KITTI drives took {elapsed:.1f} s"


def test_durations_distances_speeds_plausible(drives):
    ds, _ = drives
    total = 0.0
    for d in ds:
        tr = d.truth
        assert tr is not None and d.imu is not None and d.speed is not None
        assert tr.t[0] == 0.0 and d.gps.t[0] == 0.0
        assert 9.0 < d.duration_s < 600.0, d.name
        med_dt = d.meta.extra["median_dt_s"]
        assert 0.095 < med_dt < 0.105, d.name
        assert len(tr) == pytest.approx(d.duration_s / med_dt + 1, rel=0.05)  # jitter
        dist = float(np.sum(np.hypot(np.diff(tr.x), np.diff(tr.y))))
        assert 20.0 < dist < 6000.0, d.name
        assert np.all(tr.v >= 0) and tr.v.max() < 35.0, d.name
        assert np.all(np.abs(d.speed.v) < 35.0)
        # 2011-09-26 .. 2011-10-03 (read as UTC)
        assert 1316995200 < d.meta.epoch_s < 1317686400
        assert abs(d.meta.origin_lat - 49.0) < 0.1 and abs(d.meta.origin_lon - 8.4) < 0.1
        total += d.duration_s
    # the data README: ~55 min in all
    assert 45 * 60 < total < 65 * 60


def test_yaw_matches_direction_of_travel(drives):
    ds, _ = drives
    checked = 0
    for d in ds:
        if d.meta.extra["truth_poor"]:
            continue
        tr = d.truth
        heading = np.arctan2(np.gradient(tr.y, tr.t), np.gradient(tr.x, tr.t))
        moving = tr.v > 3.0
        if moving.sum() < 20:
            continue
        med = np.degrees(np.median(_angdiff(heading[moving], tr.yaw[moving])))
        assert med < 10.0, f"{d.name}: yaw vs track direction median {med:.1f} deg"
        checked += 1
    assert checked >= 40


def test_imu_integrated_speed_consistent(drives):
    ds, _ = drives
    for d in ds:
        if d.meta.extra["truth_poor"]:
            continue
        t, ax, v = d.imu.t, d.imu.ax, d.truth.v
        iv = np.concatenate([[0.0], np.cumsum(np.diff(t) * 0.5 * (ax[1:] + ax[:-1]))])
        w = 50  # ~5 s windows
        idx = np.arange(0, t.size - w, w)
        err = np.abs((v[idx + w] - v[idx]) - (iv[idx + w] - iv[idx]))
        assert np.median(err) < 0.3, f"{d.name}: median |dv - int(ax)| {np.median(err):.2f} m/s"


def test_speed_and_yaw_rate_consistent_with_truth(drives):
    ds, _ = drives
    d = next(x for x in ds if x.name == "2011_09_26_drive_0005_sync")
    assert np.allclose(d.speed.v, d.truth.v, atol=0.5)
    dyaw = np.gradient(np.unwrap(d.truth.yaw), d.truth.t)
    assert np.median(np.abs(dyaw - d.imu.yaw_rate)) < 0.02


def test_poor_truth_flagged(drives):
    ds, _ = drives
    poor = [d for d in ds if d.meta.extra["truth_poor"]]
    names = {d.name for d in poor}
    assert "2011_09_26_drive_0093_sync" in names  # median pos_accuracy ~21 m
    assert len(poor) <= 6
    for d in ds:
        flagged = any(w.startswith("poor truth accuracy") for w in d.meta.warnings)
        assert flagged == d.meta.extra["truth_poor"]
        assert flagged == (d.truth_median_accuracy_m > 1.0)


def test_time_jitter_counted(drives):
    ds, _ = drives
    assert sum(d.meta.extra["time_jitter"] for d in ds) > 100
    assert all(d.meta.extra["time_gaps"] == 0 for d in ds)  # none in the shared set


def test_oxts_folder_and_mercator(kitti_dir: Path):
    drive = kitti_dir / SMALL
    a = load_kitti_drive(drive)
    b = load_kitti_drive(drive / "oxts")
    assert b.name == a.name == "2011_09_26_drive_0001_sync"
    assert np.array_equal(a.gps.x, b.gps.x)
    m = load_kitti_drive(drive, projection="mercator")
    assert m.meta.projection == "mercator"
    ratio = np.hypot(m.truth.x[-1], m.truth.y[-1]) / np.hypot(a.truth.x[-1], a.truth.y[-1])
    assert ratio == pytest.approx(1 / np.cos(np.radians(49.015)), rel=0.01)


def _lines(p: Path) -> list[str]:
    return p.read_text().splitlines()


def test_shuffled_timestamps_warn(small_copy: Path):
    ts = small_copy / "oxts" / "timestamps.txt"
    lines = _lines(ts)
    lines[10], lines[11] = lines[11], lines[10]
    ts.write_text("\n".join(lines) + "\n")
    d = load_kitti_drive(small_copy)
    assert any("re-sorted 1 out-of-order" in w for w in d.meta.warnings), d.meta.warnings
    assert len(d.gps) == 108
    assert np.all(np.diff(d.gps.t) > 0)


def test_duplicated_timestamp_warns(small_copy: Path):
    ts = small_copy / "oxts" / "timestamps.txt"
    lines = _lines(ts)
    lines[20] = lines[19]
    ts.write_text("\n".join(lines) + "\n")
    d = load_kitti_drive(small_copy)
    assert any("dropped 1 samples with duplicate" in w for w in d.meta.warnings), d.meta.warnings
    assert len(d.gps) == 107


def test_missing_and_empty_data_files_warn_and_gap_counted(small_copy: Path):
    data = small_copy / "oxts" / "data"
    for i in range(30, 35):
        (data / f"{i:010d}.txt").unlink()
    (data / "0000000050.txt").write_text("")
    d = load_kitti_drive(small_copy)
    assert len(d.gps) == 108 - 6
    text = " | ".join(d.meta.warnings)
    assert "5 data files missing" in text and "1 empty data files" in text
    assert d.meta.extra["time_gaps"] == 2


def test_unparsable_timestamp_names_line(small_copy: Path):
    ts = small_copy / "oxts" / "timestamps.txt"
    lines = _lines(ts)
    lines[6] = "2011-09-26 13:02:xx.1"
    ts.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"timestamps\.txt: line 7: cannot parse"):
        load_kitti_drive(small_copy)


def test_unparsable_data_names_file_and_column(small_copy: Path):
    f = small_copy / "oxts" / "data" / "0000000042.txt"
    vals = f.read_text().split()
    vals[8] = "fast"
    f.write_text(" ".join(vals) + "\n")
    with pytest.raises(DataError, match=r"0000000042\.txt: line 1, column 9 \(vf\): not a number"):
        load_kitti_drive(small_copy)
    f.write_text(" ".join(vals[:12]) + "\n")  # truncated line
    with pytest.raises(DataError, match=r"0000000042\.txt: line 1: expected 30 numbers, found 12"):
        load_kitti_drive(small_copy)


def test_invalid_latlon_names_file(small_copy: Path):
    f = small_copy / "oxts" / "data" / "0000000007.txt"
    vals = f.read_text().split()
    vals[0] = "149.0"
    f.write_text(" ".join(vals) + "\n")
    with pytest.raises(DataError, match=r"0000000007\.txt: oxts sample 7: invalid lat/lon"):
        load_kitti_drive(small_copy)


def test_missing_or_empty_timestamps(small_copy: Path):
    ts = small_copy / "oxts" / "timestamps.txt"
    ts.write_text("\n")
    with pytest.raises(DataError, match="no time stamps"):
        load_kitti_drive(small_copy)
    ts.unlink()
    with pytest.raises(DataError, match=r"timestamps\.txt: file missing"):
        load_kitti_drive(small_copy)


def test_missing_dataformat_warns(small_copy: Path):
    (small_copy / "oxts" / "dataformat.txt").unlink()
    d = load_kitti_drive(small_copy)
    assert any("dataformat.txt missing" in w for w in d.meta.warnings)
    assert len(d.gps) == 108
