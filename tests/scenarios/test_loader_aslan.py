"""The paper's route pickles: synthetic windows (always) and the 15 real routes (shared data)."""

from __future__ import annotations

import math
import os
import pickle
from pathlib import Path

import numpy as np
import pytest

from posbench.scenarios import loaders
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.aslan import (
    ACCEL_GLITCH_MPS2,
    ASLAN_FIX_INTERVAL_QUANTILES_S,
    held_yaw,
    load_aslan_pickle,
)

T0 = 1_649_851_224_583_364_005  # ns, like the real routes' stamps


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


# --------------------------------------------------------------------------- synthetic


def _route(n_fix: int = 30, heading: float = 0.5, v: float = 5.0) -> dict[int, dict]:
    """Windows of 8 fixes (stride 1) of a straight drive, as the paper's pickles hold them."""
    tf = T0 + np.arange(n_fix, dtype=np.int64) * 200_000_000
    dist = v * (tf - tf[0]) * 1e-9
    pos = np.stack([dist * math.cos(heading), dist * math.sin(heading)], axis=1)
    ta = T0 + 5_000_000 + np.arange(n_fix * 10, dtype=np.int64) * 20_000_000
    windows = {}
    for k in range(n_fix - 7):
        sl = slice(k, k + 8)
        in_win = (ta >= tf[k]) & (ta <= tf[k + 7])
        windows[k] = {
            "ground_truth": pos[sl].copy(),
            "ground_truth_old": [] if k == 0 else pos[k - 1 : k + 7].copy(),
            "old_tstamps": [] if k == 0 else [int(t) for t in tf[k - 1 : k + 7]],
            "tstamps": [int(t) for t in tf[sl]],
            "X": [float(pos[k + 6, 0] + 0.3)],
            "Y": [float(pos[k + 6, 1] + 0.2)],
            "ACCEL": [(str(int(t)), 0.25, -0.05) for t in ta[in_win]],
            "theta": heading + 0.001 * k,
        }
    return windows


def _write(path: Path, obj: object) -> Path:
    path.write_bytes(pickle.dumps(obj, protocol=5))
    return path


def test_synthetic_route_reconstructed(tmp_path: Path) -> None:
    w = _route()
    d = loaders.load(_write(tmp_path / "aslan-synthetic.pickle", w))[0]
    assert d.name == "aslan-synthetic" and d.meta.format == "aslan"
    assert d.meta.projection == "source"
    assert math.isnan(d.meta.origin_lat) and math.isnan(d.meta.origin_lon)
    assert d.truth is None and d.speed is None
    assert d.meta.epoch_s == pytest.approx(T0 / 1e9)
    # 30 distinct fixes from 23 overlapping windows, t = 0 at the first fix
    assert len(d.gps) == 30
    np.testing.assert_allclose(d.gps.t, np.arange(30) * 0.2, atol=1e-9)
    np.testing.assert_allclose(np.hypot(d.gps.x, d.gps.y), 5.0 * d.gps.t, atol=1e-9)
    assert d.gps.x[0] == 0.0 and d.gps.y[0] == 0.0
    # IMU: union of ACCEL, every sample once
    assert d.imu is not None
    assert np.all(np.diff(d.imu.t) > 0.019)
    np.testing.assert_allclose(d.imu.ax, 0.25)
    np.testing.assert_allclose(d.imu.ay, -0.05)
    assert d.meta.warnings == []
    assert d.meta.extra["raw_xy_unused"] == len(w)


def test_yaw_is_held_not_interpolated(tmp_path: Path) -> None:
    """theta of window k is known at its last fix: IMU samples get the latest one."""
    w = _route()
    d = load_aslan_pickle(_write(tmp_path / "r.pickle", w))
    assert d.imu is not None and d.imu.yaw is not None
    t_end = np.array([(w[k]["tstamps"][-1] - T0) * 1e-9 for k in sorted(w)])
    theta = np.array([w[k]["theta"] for k in sorted(w)])
    before = d.imu.t < t_end[0]
    assert np.all(np.isnan(d.imu.yaw[before])) and before.any()
    after = ~before
    idx = np.searchsorted(t_end, d.imu.t[after], side="right") - 1
    np.testing.assert_array_equal(d.imu.yaw[after], theta[idx])


def test_held_yaw_helper() -> None:
    got = held_yaw(np.array([10, 20]), np.array([1.0, 2.0]), np.array([5, 10, 15, 20, 25]))
    np.testing.assert_array_equal(got, [np.nan, 1.0, 1.0, 2.0, 2.0])


def test_glitches_duplicates_and_conflicts_counted(tmp_path: Path) -> None:
    w = _route()
    # an acceleration glitch, repeated in every window that holds its stamp
    t_g = w[3]["ACCEL"][5][0]
    for k in w:
        w[k]["ACCEL"] = [
            (t, -164.0, 55.2) if t == t_g else (t, ax, ay) for t, ax, ay in w[k]["ACCEL"]
        ]
    # a duplicated IMU message 10 us after a real one
    t_d = int(w[6]["ACCEL"][2][0])
    w[6]["ACCEL"].append((str(t_d + 10_000), 0.25, -0.05))
    # a stale fix republished 8 us after a fix
    w[10]["tstamps"][-1] = w[10]["tstamps"][-2] + 8_000
    # the same stamp with another position in a later window
    w[12]["ground_truth"][0] += 0.5
    d = load_aslan_pickle(_write(tmp_path / "r.pickle", w))
    text = " | ".join(d.meta.warnings)
    assert "imu: dropped 1 acceleration glitches" in text
    assert "imu: dropped 1 samples < 1 ms" in text
    assert "gps: dropped 1 samples < 1 ms" in text
    assert "gps: 1 time stamps map to different values" in text
    assert len(d.meta.warnings) == 4
    assert d.imu is not None
    assert np.all(np.hypot(d.imu.ax, d.imu.ay) <= ACCEL_GLITCH_MPS2)
    assert np.all(np.diff(d.gps.t) > 1e-3) and np.all(np.diff(d.imu.t) > 1e-3)


def test_numpy1_pickle_names(tmp_path: Path) -> None:
    """The real files name numpy.core.* (NumPy 1.x); same result either way."""
    w = _route(12)
    data = pickle.dumps(w, protocol=2)
    if b"numpy._core" in data:
        data = data.replace(b"numpy._core", b"numpy.core")
    d = load_aslan_pickle(_write(tmp_path / "old.pickle", w))
    p = tmp_path / "old1.pickle"
    p.write_bytes(data)
    d1 = load_aslan_pickle(p)
    np.testing.assert_array_equal(d.gps.x, d1.gps.x)
    np.testing.assert_array_equal(d.imu.yaw, d1.imu.yaw)


def test_code_in_pickle_is_refused(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self) -> tuple:
            return (os.system, (f"echo pwned > {marker}",))

    p = _write(tmp_path / "evil.pickle", {0: {"theta": Evil()}})
    with pytest.raises(DataError, match=r"refused to unpickle '(posix|nt|os)\.system'"):
        loaders.load(p)
    assert not marker.exists()


def test_bad_structure(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="expected a non-empty dict"):
        load_aslan_pickle(_write(tmp_path / "a.pickle", [1, 2]))
    w = _route(10)
    del w[1]["ACCEL"]
    with pytest.raises(DataError, match="window 1: missing key"):
        load_aslan_pickle(_write(tmp_path / "b.pickle", w))
    w = _route(10)
    w[0]["ground_truth"] = w[0]["ground_truth"][:5]
    with pytest.raises(DataError, match=r"window 0: ground_truth has shape \(5, 2\)"):
        load_aslan_pickle(_write(tmp_path / "c.pickle", w))
    w = _route(10)
    w[2]["ACCEL"][0] = ("not-a-time", 0.1, 0.2)
    with pytest.raises(DataError, match="window 2: ACCEL row 0"):
        load_aslan_pickle(_write(tmp_path / "d.pickle", w))


def test_interval_quantiles_constant_shape() -> None:
    q = ASLAN_FIX_INTERVAL_QUANTILES_S
    assert q.shape == (21,) and np.all(np.diff(q) >= 0)
    assert 0.19 < q[10] < 0.21 and q[-1] < 1.5 and q[0] > 0


# --------------------------------------------------------------------------- real routes


@pytest.fixture(scope="module")
def routes(aslan_dir: Path) -> list:
    return loaders.load(aslan_dir)


@pytest.mark.shared
def test_all_routes_load(routes: list) -> None:
    assert len(routes) == 15
    assert len({d.name for d in routes}) == 15
    total = sum(d.duration_s for d in routes)
    assert 34 * 60 < total < 38 * 60  # ~36 min
    for d in routes:
        assert d.meta.format == "aslan" and d.meta.projection == "source"
        assert d.truth is None and d.speed is None and d.imu is not None
        assert 1.641e9 < d.meta.epoch_s < 1.657e9  # Jan-Jun 2022
        assert min(d.gps.t[0], d.imu.t[0]) == 0.0
        dt = np.diff(d.gps.t)
        assert 0.19 < np.median(dt) < 0.21, d.name
        assert np.percentile(dt, 5) > 0.08 and dt.max() < 1.1, d.name
        assert np.all(dt > 1e-3)
        assert 0.018 < np.median(np.diff(d.imu.t)) < 0.022, d.name  # ~50 Hz
        assert np.all(np.hypot(d.imu.ax, d.imu.ay) <= ACCEL_GLITCH_MPS2)
        assert abs(d.gps.x[0]) < 1e-9 and abs(d.gps.y[0]) < 1e-9  # route origin
        assert any("acceleration glitches" in w for w in d.meta.warnings)


@pytest.mark.shared
def test_yaw_follows_track_direction(routes: list) -> None:
    for d in routes:
        g, imu = d.gps, d.imu
        # track direction from fixes +-0.4 s around each IMU time, while moving > 2 m/s
        t = imu.t
        dx = np.interp(t + 0.4, g.t, g.x) - np.interp(t - 0.4, g.t, g.x)
        dy = np.interp(t + 0.4, g.t, g.y) - np.interp(t - 0.4, g.t, g.y)
        moving = (np.hypot(dx, dy) / 0.8 > 2.0) & np.isfinite(imu.yaw)
        assert moving.sum() > 0.5 * t.size, d.name
        err = _wrap(imu.yaw[moving] - np.arctan2(dy, dx)[moving])
        assert abs(np.median(err)) < 0.02, d.name  # no offset: ENU convention, 0 = +x
        assert np.median(np.abs(err)) < 0.1, d.name


@pytest.mark.shared
def test_interval_quantiles_match_data(routes: list) -> None:
    dts = np.concatenate([np.diff(d.gps.t) for d in routes])
    q = np.quantile(dts, np.linspace(0, 1, 21))
    np.testing.assert_allclose(ASLAN_FIX_INTERVAL_QUANTILES_S, q, atol=1e-6)
