"""Issue 18 part A: IMU frames and gravity, yaw reference, and what counts as truth in bags.

Bags are written by :mod:`ros_synth` (tests/ros_synth.py) (rotated IMU, tf_static, drifting
wheel odometry, 1 m-noise NavSatFix at 2-5 Hz) and read back through the loader and the harness.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench
from ros_synth import SynthBag, synth_truth, write_bag

from posbench.config import RunConfig
from posbench.replay.reference import FIX_CUBIC, TRUTH
from posbench.replay.runner import run_drive
from posbench.scenarios import imu_frames as fr
from posbench.scenarios.align import ALIGN_MIN_LIMIT_M, alignment_limit_m, umeyama_2d
from posbench.scenarios.degrade import enu_to_latlon
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.ros_tf import chain_rotation, find_mount
from posbench.scenarios.loaders.rosbag import load_rosbag
from posbench.scenarios.projection import to_local
from posbench.scenarios.synthetic_sensors import ORIGIN_LAT, ORIGIN_LON

# --------------------------------------------------------------------------- pure maths


def test_umeyama_recovers_rotation_and_translation() -> None:
    rng = np.random.default_rng(0)
    src = rng.uniform(-100, 100, (200, 2))
    a = math.radians(-37.0)
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    dst = src @ r.T + [12.0, -5.0]
    got_r, got_t, rms = umeyama_2d(src, dst)
    np.testing.assert_allclose(got_r, r, atol=1e-12)
    np.testing.assert_allclose(got_t, [12.0, -5.0], atol=1e-10)
    assert rms < 1e-9
    noisy = dst + rng.normal(0, 1.0, dst.shape)
    _, _, rms = umeyama_2d(src, noisy)
    assert 1.2 < rms < 1.6  # sqrt(2) x 1 m per axis
    # a mirror image is not a rotation: the fit stays proper and leaves a large residual
    got_r, _, rms = umeyama_2d(src, src * [1, -1])
    assert np.linalg.det(got_r) == pytest.approx(1.0) and rms > 30
    with pytest.raises(ValueError):
        umeyama_2d(src[:1], dst[:1])


def test_alignment_limit_one_place() -> None:
    assert alignment_limit_m(None) == ALIGN_MIN_LIMIT_M
    assert alignment_limit_m(0.5) == ALIGN_MIN_LIMIT_M
    assert alignment_limit_m(4.0) == pytest.approx(12.0)


def test_yaw_offset_against_course() -> None:
    rng = np.random.default_rng(1)
    t = np.linspace(0, 100, 4001)
    heading = 0.02 * t + 0.5 * np.sin(0.1 * t)
    x = np.cumsum(10 * np.cos(heading)) * (t[1] - t[0])
    y = np.cumsum(10 * np.sin(heading)) * (t[1] - t[0])
    tf = t[::10]
    ct, course = fr.gps_course(
        tf, x[::10] + rng.normal(0, 1, tf.size), y[::10] + rng.normal(0, 1, tf.size)
    )
    off, spread, n = fr.yaw_offset(t, fr.wrap(heading - 1.2), ct, course)
    assert n > 100 and off == pytest.approx(1.2, abs=math.radians(1.5))
    assert math.degrees(spread) < fr.YAW_MAX_SPREAD_DEG
    # a yaw unrelated to the motion spreads widely
    _, spread, _ = fr.yaw_offset(t, rng.uniform(-np.pi, np.pi, t.size), ct, course)
    assert math.degrees(spread) > fr.YAW_MAX_SPREAD_DEG
    assert fr.yaw_offset(t, heading, ct[:0], course[:0]) == (
        pytest.approx(np.nan, nan_ok=True),
        pytest.approx(np.nan, nan_ok=True),
        0,
    )


def test_level_vehicle_accel_rolled_sensor_and_yaw_reference_cancels() -> None:
    r_bs = fr.rpy_to_matrix(math.radians(90), 0, 0)
    f_b = np.array([[1.0, -0.5, fr.G0]])
    f_s = f_b @ r_bs  # R_bs^T f_b
    assert f_s[0, 1] == pytest.approx(fr.G0)  # gravity shows on the sensor's +y
    for ref in (0.0, 1.0, -2.5):  # the orientation's yaw reference does not matter for ax, ay
        r_ws = (fr.rpy_to_matrix(0, 0, 0.3 + ref) @ r_bs)[None]
        ax, ay, yaw_b = fr.level_vehicle_accel(f_s, r_ws, r_bs)
        np.testing.assert_allclose([ax[0], ay[0]], [1.0, -0.5], atol=1e-12)
        assert float(yaw_b[0]) == pytest.approx(fr.wrap(np.array(0.3 + ref)))
    q = fr.matrix_to_quat(r_bs)
    np.testing.assert_allclose(fr.quat_to_matrix(*q.T)[0], r_bs, atol=1e-12)


def test_estimate_mount_from_data() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(0, 60, 0.02)
    v = np.clip(5 + 5 * np.sin(0.2 * t), 0, None)
    v[t < 5] = 0.0
    a = np.gradient(v, t)
    r_bs = fr.rpy_to_matrix(math.radians(90), 0, math.radians(30))
    f_b = np.column_stack([a, 0.3 * np.sin(0.5 * t), np.full(t.size, fr.G0)])
    f_s = f_b @ r_bs + rng.normal(0, 0.05, f_b.shape)
    est, info = fr.estimate_mount(t, f_s, t, v)
    assert info["up_from"] == "standstill" and info["forward_from"] == "d(speed)/dt"
    ang = math.degrees(math.acos((np.trace(est @ r_bs.T) - 1) / 2))
    assert ang < 3.0 and info["forward_corr"] > 0.9


def test_tf_chain_both_ways() -> None:
    a = fr.rpy_to_matrix(0, 0, 0.5)
    b = fr.rpy_to_matrix(1.0, 0, 0)
    edges = {("base_link", "mast"): a, ("imu_link", "mast"): b.T}  # second edge stored reversed
    np.testing.assert_allclose(chain_rotation(edges, "base_link", "/imu_link"), a @ b, atol=1e-12)
    assert chain_rotation(edges, "base_link", "camera") is None
    r, base = find_mount(edges, "imu_link")
    assert base == "base_link" and r is not None
    assert find_mount(edges, "base_link") == (None, None)


# --------------------------------------------------------------------------- bags


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, SynthBag]]:
    root = tmp_path_factory.mktemp("ros_frames")
    cases = {
        "orient_tf": SynthBag(kind="ros1"),
        "orient_tf_ros2": SynthBag(kind="mcap"),
        "orient_magnetic": SynthBag(kind="sqlite3", tf_static=False, yaw_ref_offset_deg=70.0),
        "noorient_tf": SynthBag(kind="ros1", orientation=False),
        "noorient_notf": SynthBag(kind="ros1", orientation=False, tf_static=False),
        "truth": SynthBag(kind="mcap", ground_truth=True, odom_yaw_drift_dps=0.2),
        "flip": SynthBag(kind="ros1", yaw_rate_sign=-1.0),
    }
    return {k: (write_bag(root / k, o), o) for k, o in cases.items()}


def _truth_at(o: SynthBag, t: np.ndarray) -> dict[str, np.ndarray]:
    tr = synth_truth(o)
    yaw = np.unwrap(tr.yaw)
    return {
        "dv": np.interp(t, tr.t, np.gradient(tr.v, tr.t)),
        "lat": np.interp(t, tr.t, tr.v * np.gradient(yaw, tr.t)),
        "yaw": np.interp(t, tr.t, yaw),
        "w": np.interp(t, tr.t, np.gradient(yaw, tr.t)),
    }


@pytest.mark.slow
@pytest.mark.parametrize(
    ("case", "method", "yaw"),
    [
        ("orient_tf", "orientation+tf_static", "enu"),
        ("orient_tf_ros2", "orientation+tf_static", "enu"),
        ("orient_magnetic", "orientation", "offset-corrected"),
        ("noorient_tf", "tf_static", "none"),
        ("noorient_notf", "estimated", "none"),
    ],
)
def test_gravity_removed_in_vehicle_frame(bags, case: str, method: str, yaw: str) -> None:
    path, o = bags[case]
    d = load_rosbag(path)
    info = d.meta.extra["imu_frame"]
    assert info["method"] == method and info["gravity_removed"] is True and info["yaw"] == yaw
    json.dumps(d.meta.extra)  # JSON-serialisable (plain floats, lists, str)
    assert d.imu is not None
    ref = _truth_at(o, d.imu.t)
    # gravity (9.8 m/s^2 on the sensor's y) is gone: horizontal means are the motion's own
    assert abs(d.imu.ax.mean()) < 0.3 and abs(d.imu.ay.mean()) < 0.3
    assert abs((d.imu.ax - ref["dv"]).mean()) < 0.1 and abs((d.imu.ay - ref["lat"]).mean()) < 0.1
    # ax follows d(speed)/dt, ay the lateral acceleration, yaw rate the heading rate
    assert np.corrcoef(d.imu.ax, ref["dv"])[0, 1] > 0.95
    assert np.corrcoef(d.imu.ay, ref["lat"])[0, 1] > 0.95
    assert np.corrcoef(d.imu.yaw_rate, ref["w"])[0, 1] > 0.99
    if yaw == "none":
        assert d.imu.yaw is None
    else:
        err = np.degrees(np.abs(fr.wrap(d.imu.yaw - ref["yaw"])))
        assert np.percentile(err, 95) < 3.0
    if method == "estimated":
        np.testing.assert_allclose(info["mount_rpy_deg"][:2], [90.0, 0.0], atol=3.0)
        assert any("mount estimated from the data" in w for w in d.meta.warnings)
    if yaw == "offset-corrected":
        assert info["yaw_offset_deg"] == pytest.approx(-70.0, abs=2.0)
        assert any("yaw is not ENU" in w for w in d.meta.warnings)


def test_wandering_yaw_dropped(tmp_path: Path) -> None:
    # an orientation whose yaw reference drifts 1 deg/s (gyro-integrated, no magnetometer):
    # no single offset fits, so the yaw is not used; ax, ay stay right (the reference cancels)
    o = SynthBag(kind="mcap", duration_s=60.0, odom=False, yaw_ref_drift_dps=1.0)
    d = load_rosbag(write_bag(tmp_path / "wander", o))
    info = d.meta.extra["imu_frame"]
    assert info["yaw"] == "dropped" and info["yaw_spread_deg"] > fr.YAW_MAX_SPREAD_DEG
    assert d.imu is not None and d.imu.yaw is None
    assert any("yaw not used" in w for w in d.meta.warnings)
    ref = _truth_at(o, d.imu.t)
    assert np.corrcoef(d.imu.ax, ref["dv"])[0, 1] > 0.95


def test_odometry_is_speed_not_truth_and_scored_against_fixes(bags) -> None:
    path, _ = bags["orient_tf"]
    d = load_rosbag(path)
    assert d.truth is None and d.meta.extra["truth_kind"] == "gps-fixes"
    assert d.meta.extra["topics"]["speed"]["topic"] == "/odom" and d.speed is not None
    np.testing.assert_allclose(
        np.median(d.speed.v[d.speed.v > 1])
        / np.median(synth_truth(SynthBag()).v[synth_truth(SynthBag()).v > 1]),
        1.02,
        atol=0.01,
    )
    assert sum("/odom is not used as truth" in w for w in d.meta.warnings) == 1
    # default profile (rtk) on a drive without truth: its own fixes, reference from the fixes
    run = run_drive(d, RunConfig(predictors=("cv", "kf")))
    assert run.reference == FIX_CUBIC and len(run.notes) == 1 and "own" in run.notes[0]
    fut = run.traces[run.traces.kind == "future"].groupby("predictor").error_m.mean()
    assert fut["kf"] <= fut["cv"]
    # errors of the order of the 1 m GPS noise, not 150 m
    assert fut.max() < 3.0 and fut["kf"] < 1.5


def test_named_local_truth_aligned(bags) -> None:
    path, o = bags["truth"]
    d = load_rosbag(path, topics={"truth": "/ground_truth"})
    al = d.meta.extra["truth_alignment"]
    assert d.meta.extra["truth_kind"] == "named" and d.meta.extra["truth_frame"] == "map"
    assert al["rotation_deg"] == pytest.approx(-o.truth_rot_deg, abs=0.5)
    assert 0.8 < al["residual_rms_m"] < 2.0 and al["limit_m"] == pytest.approx(5.0)
    tr = synth_truth(o)  # ENU about the synthetic origin; the drive's is its first fix
    ex, ey = to_local(
        *enu_to_latlon(tr.x, tr.y, ORIGIN_LAT, ORIGIN_LON), d.meta.origin_lat, d.meta.origin_lon
    )
    err = np.hypot(
        d.truth.x - np.interp(d.truth.t, tr.t, ex), d.truth.y - np.interp(d.truth.t, tr.t, ey)
    )
    assert np.sqrt(np.mean(err**2)) < 0.5  # back in the GPS's ENU frame
    assert any("aligned to the GPS ENU frame" in w for w in d.meta.warnings)
    run = run_drive(d, RunConfig(predictors=("cv", "kf"), gps_profile="native"))
    assert run.reference == TRUTH
    fut = run.traces[run.traces.kind == "future"].groupby("predictor").error_m.mean()
    assert fut.max() < 3.0


def test_drifting_odometry_named_as_truth_refused(bags) -> None:
    path, _ = bags["truth"]
    with pytest.raises(DataError, match=r"residual RMS \d+\.\d\d m .* exceeds the limit 5\.00 m"):
        load_rosbag(path, topics={"truth": "/odom"})
    r = bench("data", "inspect", path, "--topic", "truth=/odom", columns=200)
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "residual RMS" in lines[0]
    assert "Traceback" not in r.stderr


def test_yaw_rate_sign_flip_is_written(bags) -> None:
    # the writer's flip option (for the consistency check of part B) reaches the loaded stream
    path, o = bags["flip"]
    d = load_rosbag(path)
    ref = _truth_at(o, d.imu.t)
    assert np.corrcoef(d.imu.yaw_rate, ref["w"])[0, 1] < -0.99


def test_consistency_check_flags_the_flipped_gyro_of_a_bag(bags) -> None:
    # the bag's gyro sign flip is caught by the check before any figure (issue 18)
    from posbench.scenarios.consistency import FAIL, PASS, check_drive

    by = check_drive(load_rosbag(bags["flip"][0])).checks
    good = check_drive(load_rosbag(bags["orient_tf"][0])).checks
    assert by["imu.yaw_rate"].verdict == FAIL and by["imu.yaw_rate"].figures["sign"] == -1
    assert good["imu.yaw_rate"].verdict == PASS
    # gravity removed: the longitudinal acceleration passes its bias check on both
    assert by["imu.ax"].verdict == PASS
    r = bench(
        "run",
        "--data",
        str(bags["flip"][0]),
        "-p",
        "cv,kf",
        "--strict",
        "--out",
        str(bags["flip"][0].parent / "strict-out"),
        timeout=300,
    )
    assert_one_error_line(r, "--strict", "imu.yaw_rate", "sign -1")


@pytest.mark.slow
def test_run_records_sensor_frames_in_results(bags, tmp_path: Path) -> None:
    out = tmp_path / "out"
    r = bench(
        "run",
        "--data",
        str(bags["orient_tf"][0]),
        "-p",
        "cv,kf",
        "--out",
        str(out),
        "--plot-format",
        "none",
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    res = json.loads((out / "results.json").read_text())
    (drive,) = res["drives"]
    frames = drive["sensor_frames"]
    assert frames["imu_frame"]["method"] == "orientation+tf_static"
    assert frames["truth_kind"] == "gps-fixes" and drive["reference"] == FIX_CUBIC
    report = (out / "report.md").read_text()
    assert "levelled by its orientation, gravity removed" in report
    assert "is not used as truth" in report
