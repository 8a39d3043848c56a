"""ROS truths and speeds as users record them: a second NavSatFix receiver (RTK), PoseStamped /
PoseWithCovarianceStamped / Odometry in a map frame, and TwistStamped /
TwistWithCovarianceStamped / Odometry as the speed.

Bags are written by :mod:`ros_synth` (tests/ros_synth.py) with rosbags' writers and read back;
positions are checked in metres against the synthetic drive's exact path (ENU about the drive's
first fix), times in seconds.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench
from ros_synth import T0_NS, SynthBag, synth_truth, write_bag

from posbench.cli.inspect import scored_fixes, topic_lines
from posbench.scenarios.degrade import enu_to_latlon
from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError
from posbench.scenarios.imu_frames import wrap
from posbench.scenarios.loaders.rosbag import load_rosbag
from posbench.scenarios.projection import to_local
from posbench.scenarios.synthetic_sensors import ORIGIN_LAT, ORIGIN_LON

SHORT = {"duration_s": 60.0, "gps_interval_s": (0.1, 0.1), "imu_hz": 20.0}
CASES = {
    # consumer fixes biased 3 m east, 2 m south: a fit would pull the RTK truth onto them
    "rtk_ros1": SynthBag(
        kind="ros1",
        gps_noise_m=1.5,
        gps_bias_m=(3.0, -2.0),
        rtk=True,
        rtk_no_fix_every=40,
        odom=False,
        twist="TwistStamped",
        **SHORT,
    ),
    "rtk_mcap": SynthBag(
        kind="mcap",
        gps_noise_m=1.5,
        gps_bias_m=(3.0, -2.0),
        rtk=True,
        odom=False,
        twist="TwistWithCovarianceStamped",
        **SHORT,
    ),
    "rtk_unknown_cov": SynthBag(kind="sqlite3", rtk=True, rtk_cov_type=0, odom=False, **SHORT),
    "pose_ros1": SynthBag(kind="ros1", gps_noise_m=0.1, pose_truth="PoseStamped", **SHORT),
    "posecov_sqlite": SynthBag(
        kind="sqlite3", gps_noise_m=0.1, pose_truth="PoseWithCovarianceStamped", **SHORT
    ),
    "pose_scaled": SynthBag(
        kind="mcap", pose_truth="PoseStamped", pose_scale=1.15, odom=False, **SHORT
    ),
    "odom_truth": SynthBag(kind="mcap", gps_noise_m=0.1, ground_truth=True, **SHORT),
    # the target: consumer NavSatFix (1.5 m, stated), RTK NavSatFix (2 cm) and a
    # PoseStamped truth in a map frame, 10 Hz fixes, 100 Hz IMU, wheel odometry
    "target": SynthBag(
        kind="mcap",
        duration_s=75.0,
        gps_topic="/gnss/fix",
        gps_noise_m=1.5,
        gps_interval_s=(0.1, 0.1),
        imu_hz=100.0,
        rtk=True,
        pose_truth="PoseStamped",
    ),
}


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, SynthBag]]:
    root = tmp_path_factory.mktemp("ros_truths")
    return {k: (write_bag(root / k, o), o) for k, o in CASES.items()}


def _offset_s(d: Drive) -> float:
    """Synthetic time [s] of the drive's t = 0."""
    return d.meta.epoch_s - T0_NS * 1e-9


def _expected(
    d: Drive, o: SynthBag, t: np.ndarray, projection: str = "enu"
) -> tuple[np.ndarray, np.ndarray]:
    """The exact path at drive times t [s], in the drive's local frame [m]."""
    tr = synth_truth(o)
    ex, ey = to_local(
        *enu_to_latlon(tr.x, tr.y, ORIGIN_LAT, ORIGIN_LON),
        d.meta.origin_lat,
        d.meta.origin_lon,
        projection,
    )
    ts = t + _offset_s(d)
    return np.interp(ts, tr.t, ex), np.interp(ts, tr.t, ey)


def _rms(d: Drive, o: SynthBag, projection: str = "enu") -> float:
    assert d.truth is not None
    ex, ey = _expected(d, o, d.truth.t, projection)
    return float(np.sqrt(np.mean((d.truth.x - ex) ** 2 + (d.truth.y - ey) ** 2)))


# --------------------------------------------------------------------------- NavSatFix truth


@pytest.mark.slow
@pytest.mark.parametrize("case", ["rtk_ros1", "rtk_mcap"])
def test_navsatfix_truth_in_the_fixes_frame_without_fit(bags, case: str) -> None:
    path, o = bags[case]
    d = load_rosbag(path, topics={"truth": "/gnss/rtk"})
    roles = d.meta.extra["topics"]
    assert roles["gps"]["topic"] == "/fix" and roles["gps"]["why"] == (
        "only NavSatFix besides the truth"
    )
    assert (
        roles["truth"]["type"] == "sensor_msgs/msg/NavSatFix" and "no fit" in roles["truth"]["why"]
    )
    assert d.meta.extra["truth_alignment"]["fit"] == "none"
    assert not any("aligned to the GPS" in w for w in d.meta.warnings)
    # 2 cm per axis: ~3 cm RMS; the consumer fixes' 3 m / 2 m bias is not fitted away
    assert _rms(d, o) < 0.05
    dx = d.gps.x - np.interp(d.gps.t, d.truth.t, d.truth.x)
    dy = d.gps.y - np.interp(d.gps.t, d.truth.t, d.truth.y)
    assert np.mean(dx) == pytest.approx(3.0, abs=0.2) and np.mean(dy) == pytest.approx(
        -2.0, abs=0.2
    )
    np.testing.assert_allclose(d.truth.accuracy, 0.02)
    assert d.truth.yaw is None and d.truth.v is None
    assert d.meta.fix_source == "receiver" and not d.fixes_from_truth
    assert scored_fixes(d) == "own receiver"
    if o.rtk_no_fix_every:
        (w,) = [w for w in d.meta.warnings if w.startswith("truth: skipped")]
        skipped, total = map(
            int,
            re.search(
                r"skipped (\d+) of (\d+) NavSatFix messages on "
                r"/gnss/rtk",
                w,
            ).groups(),
        )
        assert skipped == total // o.rtk_no_fix_every and len(d.truth) == total - skipped


def test_navsatfix_truth_same_projection_and_unknown_covariance(bags) -> None:
    path, o = bags["rtk_ros1"]
    d = load_rosbag(path, projection="mercator", topics={"truth": "/gnss/rtk"})
    assert d.meta.projection == "mercator" and _rms(d, o, "mercator") < 0.05
    path, o = bags["rtk_unknown_cov"]
    d = load_rosbag(path, topics={"truth": "/gnss/rtk"})
    assert d.truth is not None and d.truth.accuracy is None and _rms(d, o) < 0.05
    assert d.gps.accuracy is not None  # the fixes' own covariance is stated


def test_same_navsatfix_as_fixes_and_truth_is_simulated(bags) -> None:
    path, _ = bags["rtk_mcap"]
    d = load_rosbag(path, topics={"gps": "/gnss/rtk", "truth": "/gnss/rtk"})
    assert d.meta.fix_source == "truth" and d.fixes_from_truth
    assert scored_fixes(d) == "simulated from truth"
    assert scored_fixes(load_rosbag(path, topics={"gps": "/fix"})) == "own (no truth)"


def test_unnamed_candidates_are_no_truth(bags) -> None:
    path, _ = bags["target"]
    with pytest.raises(
        DataError,
        match=r"several gps topics \(NavSatFix\): /gnss/fix, "
        r"/gnss/rtk",
    ):
        load_rosbag(path)
    d = load_rosbag(path, topics={"gps": "/gnss/fix"})
    assert d.truth is None and d.meta.extra["truth_kind"] == "gps-fixes"
    unused = d.meta.extra["unused_topics"]
    assert set(unused) == {"/gnss/rtk", "/pose", "/tf_static"}
    assert unused["/pose"]["why"] == "a truth only when named: --topic truth=/pose"
    assert any(
        "/gnss/rtk (NavSatFix), /pose (PoseStamped) could be the truth" in w
        for w in d.meta.warnings
    )


# --------------------------------------------------------------------------- pose truths


@pytest.mark.parametrize(("case", "acc"), [("pose_ros1", None), ("posecov_sqlite", 0.05)])
def test_pose_truth_in_a_map_frame_recovered(bags, case: str, acc: float | None) -> None:
    path, o = bags[case]
    d = load_rosbag(path, topics={"truth": "/pose"})
    al = d.meta.extra["truth_alignment"]
    assert al["fit"] == "rigid-2d" and al["rotation_deg"] == pytest.approx(
        -o.truth_rot_deg, abs=0.05
    )
    assert d.meta.extra["truth_frame"] == "map"
    assert _rms(d, o) < 0.03  # rotated 40 deg and shifted (120, -35) m: back to ~cm
    assert d.truth is not None and d.truth.yaw is not None and d.truth.v is None
    tr = synth_truth(o)
    yaw = np.interp(d.truth.t + _offset_s(d), tr.t, np.unwrap(tr.yaw))
    assert np.degrees(np.abs(wrap(d.truth.yaw - yaw))).max() < 0.5
    if acc is None:
        assert d.truth.accuracy is None
    else:
        np.testing.assert_allclose(d.truth.accuracy, acc)
    assert "residual RMS" in d.meta.extra["topics"]["truth"]["why"]
    assert scored_fixes(d) == "own receiver"
    # no twist: the speed falls back on the wheel odometry (2 % scale), never the truth
    assert d.meta.extra["topics"]["speed"]["topic"] == "/odom"


def test_odometry_truth_in_map_has_speed_and_is_not_the_speed(bags) -> None:
    path, o = bags["odom_truth"]
    d = load_rosbag(path, topics={"truth": "/ground_truth"})
    assert d.meta.extra["topics"]["speed"]["topic"] == "/odom"  # two Odometry: not ambiguous
    assert _rms(d, o) < 0.03
    assert d.truth is not None and d.truth.v is not None
    tr = synth_truth(o)
    np.testing.assert_allclose(
        d.truth.v, np.interp(d.truth.t + _offset_s(d), tr.t, tr.v), atol=1e-6
    )
    np.testing.assert_allclose(d.truth.accuracy, 0.1)


def test_mis_scaled_pose_truth_refused_in_one_line(bags) -> None:
    path, _ = bags["pose_scaled"]
    with pytest.raises(DataError) as ei:
        load_rosbag(path, topics={"truth": "/pose"})
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith(str(path))
    assert re.search(
        r"--topic truth=/pose: residual RMS \d+\.\d\d m .* exceeds the limit "
        r"5\.00 m",
        msg,
    ), msg


# --------------------------------------------------------------------------- speeds


@pytest.mark.parametrize(
    ("case", "topic", "scale"),
    [
        ("rtk_ros1", "/vel", 1.0),  # TwistStamped
        ("rtk_mcap", "/vel", 1.0),  # TwistWithCovarianceStamped
        ("pose_ros1", "/odom", 1.02),  # Odometry, the fallback (wheel odometry, 2 % scale)
    ],
)
def test_speed_types(bags, case: str, topic: str, scale: float) -> None:
    path, o = bags[case]
    d = load_rosbag(path, topics={"gps": "/fix"})
    sp = d.meta.extra["topics"]["speed"]
    assert sp["topic"] == topic
    assert sp["why"] == (
        "only TwistStamped or TwistWithCovarianceStamped"
        if topic == "/vel"
        else "fallback: no TwistStamped or TwistWithCovarianceStamped"
    )
    assert d.speed is not None
    tr = synth_truth(o)
    np.testing.assert_allclose(
        d.speed.v, scale * np.interp(d.speed.t + _offset_s(d), tr.t, tr.v), atol=1e-3
    )


# --------------------------------------------------------------------------- the bag


@pytest.mark.slow
def test_both_truths_score_alike(bags) -> None:
    import posbench

    path, o = bags["target"]
    rtk = load_rosbag(path, topics={"truth": "/gnss/rtk"})
    pose = load_rosbag(path, topics={"gps": "/gnss/fix", "truth": "/pose"})
    # RTK: its own 2 cm; the map-frame pose: fitted to 1.5 m-noise fixes, a decimetre or two
    assert _rms(rtk, o) < 0.05 and _rms(pose, o) < 0.3
    assert rtk.meta.extra["topics"]["gps"]["topic"] == "/gnss/fix"
    np.testing.assert_allclose(rtk.gps.accuracy, 1.5)
    means = {}
    for name, topics in (
        ("rtk", {"truth": "/gnss/rtk"}),
        ("pose", {"gps": "/gnss/fix", "truth": "/pose"}),
    ):
        run = posbench.run(
            data=path, predictors="kf", topics=topics, gps_profile="native", workers=1
        )
        means[name] = float(run.summary().loc[("kf", "future"), "mean_m"])
    print(f"kf future mean error [m]: {means}")
    # consumer fixes scored (1.5 m noise), against either truth alike
    assert 0.5 < means["rtk"] < 3.0
    assert abs(means["rtk"] - means["pose"]) <= 0.05 * min(means.values())


# --------------------------------------------------------------------------- inspect


def test_inspect_lists_roles_and_scored_fixes(bags) -> None:
    path, _ = bags["target"]
    r = bench(
        "data",
        "inspect",
        str(path),
        "--topic",
        "truth=/gnss/rtk",
        env={"COLUMNS": "250"},
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    lines = [ln.strip() for ln in r.stdout.splitlines()]
    assert any(
        re.fullmatch(
            r"gps\s+/gnss/fix\s+sensor_msgs/msg/NavSatFix\s+\(only NavSatFix "
            r"besides the truth\)",
            ln,
        )
        for ln in lines
    ), r.stdout
    assert any(
        re.match(r"truth\s+/gnss/rtk\s+sensor_msgs/msg/NavSatFix\s+\(named; .*no fit\)", ln)
        for ln in lines
    ), r.stdout
    assert any(
        re.match(r"speed\s+/odom\s+nav_msgs/msg/Odometry\s+\(fallback: no TwistStamped", ln)
        for ln in lines
    ), r.stdout
    assert any(
        re.match(r"-\s+/pose\s+geometry_msgs/msg/PoseStamped\s+\(a truth only when named", ln)
        for ln in lines
    ), r.stdout
    assert "own receiver" in r.stdout


def test_topic_lines_only_for_bags() -> None:
    assert topic_lines({}) == [] and topic_lines({"topics": {"gps": "/fix"}}) == []
    lines = topic_lines(
        {
            "topics": {
                "speed": {"topic": "/v", "type": "T", "why": "b"},
                "gps": {"topic": "/fix", "type": "N", "why": "a"},
            },
            "unused_topics": {"/x": {"type": "X", "why": "c"}},
        }
    )
    assert lines == ["gps    /fix  N  (a)", "speed  /v    T  (b)", "-      /x    X  (c)"]


def test_wrong_truth_type_is_one_error_line(bags) -> None:
    path, _ = bags["rtk_mcap"]
    r = bench("data", "inspect", str(path), "--topic", "truth=/imu", timeout=300)
    assert_one_error_line(
        r,
        str(path),
        "--topic truth=/imu",
        "sensor_msgs/msg/Imu",
        "expected sensor_msgs/msg/NavSatFix",
    )
