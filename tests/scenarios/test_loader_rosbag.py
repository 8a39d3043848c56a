"""ROS 1 / ROS 2 bag loader: bags written here with rosbags' writers, read back."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from posbench.scenarios import loaders
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.rosbag import load_rosbag, quat_yaw
from posbench.scenarios.projection import to_local

T0_NS = 1_700_000_000_000_000_000  # Unix ns of the first sample
LAT0, LON0 = 45.8, 15.97


# --------------------------------------------------------------------------- trajectory


def _trajectory(n_gps: int = 20) -> dict[str, np.ndarray]:
    """A car on a 50 m circle at 5 m/s: GPS 5 Hz, IMU 50 Hz, speed and odometry 10 Hz."""
    r, v = 50.0, 5.0
    w = v / r

    def pose(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a = w * t
        return r * np.sin(a), r * (1 - np.cos(a)), a  # heading = a (ENU, CCW)

    tg = np.arange(n_gps) * 0.2
    xg, yg, _ = pose(tg)
    lat = LAT0 + np.degrees(yg / 6378137.0)
    lon = LON0 + np.degrees(xg / (6378137.0 * math.cos(math.radians(LAT0))))
    ti = np.arange(n_gps * 10) * 0.02 + 0.001
    _, _, yaw_i = pose(ti)
    tt = np.arange(n_gps * 2) * 0.1 + 0.005
    xt, yt, yaw_t = pose(tt)
    return {
        "tg": tg,
        "lat": lat,
        "lon": lon,
        "ti": ti,
        "yaw_i": yaw_i,
        "ax": np.full(ti.size, 0.1),
        "ay": np.full(ti.size, v * w),
        "tt": tt,
        "xt": xt,
        "yt": yt,
        "yaw_t": yaw_t,
        "v": np.full(tt.size, v),
        "yaw_rate": np.full(ti.size, w),
    }


def _latlon_of(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """lat/lon [deg] of local metres, the way _trajectory makes the GPS's."""
    return (
        LAT0 + np.degrees(y / 6378137.0),
        LON0 + np.degrees(x / (6378137.0 * math.cos(math.radians(LAT0)))),
    )


def _ns(t: float) -> int:
    return T0_NS + int(round(t * 1e9))


# --------------------------------------------------------------------------- message makers


class _Msgs:
    """Message builders for one typestore (ROS 1 headers carry ``seq``)."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        self.T = self.ts.types

    def header(self, t_ns: int, frame: str = "base_link") -> object:
        stamp = self.T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def navsatfix(
        self,
        t_ns: int,
        lat: float,
        lon: float,
        status: int = 0,
        cov_type: int = 2,
        var: float = 4.0,
    ) -> object:
        st = self.T["sensor_msgs/msg/NavSatStatus"](status=status, service=1)
        cov = np.zeros(9)
        cov[0] = cov[4] = var
        cov[8] = 9.0
        return self.T["sensor_msgs/msg/NavSatFix"](
            header=self.header(t_ns, "gps"),
            status=st,
            latitude=lat,
            longitude=lon,
            altitude=100.0,
            position_covariance=cov,
            position_covariance_type=cov_type,
        )

    def vec(self, x: float, y: float, z: float = 0.0) -> object:
        return self.T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def quat(self, yaw: float) -> object:
        return self.T["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        )

    def imu(
        self,
        t_ns: int,
        ax: float,
        ay: float,
        yaw: float,
        yaw_rate: float,
        no_orientation: bool = False,
    ) -> object:
        ocov = np.zeros(9)
        if no_orientation:
            ocov[0] = -1.0
        return self.T["sensor_msgs/msg/Imu"](
            header=self.header(t_ns),
            orientation=self.quat(yaw),
            orientation_covariance=ocov,
            angular_velocity=self.vec(0.0, 0.0, yaw_rate),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=self.vec(ax, ay, 9.81),
            linear_acceleration_covariance=np.zeros(9),
        )

    def twist(self, t_ns: int, vx: float, vy: float) -> object:
        tw = self.T["geometry_msgs/msg/Twist"](linear=self.vec(vx, vy), angular=self.vec(0, 0, 0))
        return self.T["geometry_msgs/msg/TwistStamped"](header=self.header(t_ns), twist=tw)

    def odom(self, t_ns: int, x: float, y: float, yaw: float, v: float) -> object:
        T = self.T
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=self.quat(yaw)
        )
        cov = np.zeros(36)
        cov[0] = cov[7] = 0.01
        pwc = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov)
        tw = T["geometry_msgs/msg/Twist"](
            linear=self.vec(v * math.cos(yaw), v * math.sin(yaw)), angular=self.vec(0, 0, 0)
        )
        twc = T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36))
        return T["nav_msgs/msg/Odometry"](
            header=self.header(t_ns, "odom"), child_frame_id="base_link", pose=pwc, twist=twc
        )


# --------------------------------------------------------------------------- bag writers


def _write_bag(path: Path, kind: str, messages: list[tuple[str, str, int, object]]) -> Path:
    """Write ``(topic, msgtype, t_ns, msg)`` records; kind is ros1, sqlite3 or mcap.

    Returns the path to read: the ``.bag`` file or the ROS 2 bag folder.
    """
    m = _Msgs(kind == "ros1")
    topics: dict[str, str] = {}
    for topic, msgtype, _, _ in messages:
        topics.setdefault(topic, msgtype)
    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        with Writer(path) as w:
            conns = {t: w.add_connection(t, mt, typestore=m.ts) for t, mt in topics.items()}
            for topic, msgtype, t_ns, msg in messages:
                w.write(conns[topic], t_ns, m.ts.serialize_ros1(msg, msgtype))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {t: w.add_connection(t, mt, typestore=m.ts) for t, mt in topics.items()}
        for topic, msgtype, t_ns, msg in messages:
            w.write(conns[topic], t_ns, m.ts.serialize_cdr(msg, msgtype))
    return path


def _messages(
    kind: str,
    tr: dict[str, np.ndarray],
    *,
    gps_topics: tuple[str, ...] = ("/fix",),
    no_fix_at: tuple[int, ...] = (),
    nan_at: int | None = None,
    with_others: bool = True,
) -> list[tuple[str, str, int, object]]:
    m = _Msgs(kind == "ros1")
    out: list[tuple[str, str, int, object]] = []
    for topic in gps_topics:
        for i, t in enumerate(tr["tg"]):
            lat = math.nan if i == nan_at else float(tr["lat"][i])
            status = -1 if i in no_fix_at else 0
            out.append(
                (
                    topic,
                    "sensor_msgs/msg/NavSatFix",
                    _ns(t) + 3_000_000,
                    m.navsatfix(_ns(t), lat, float(tr["lon"][i]), status=status),
                )
            )
    if with_others:
        for i, t in enumerate(tr["ti"]):
            out.append(
                (
                    "/imu",
                    "sensor_msgs/msg/Imu",
                    _ns(t) + 1_000_000,
                    m.imu(_ns(t), tr["ax"][i], tr["ay"][i], tr["yaw_i"][i], tr["yaw_rate"][i]),
                )
            )
        for i, t in enumerate(tr["tt"]):
            yaw = float(tr["yaw_t"][i])
            out.append(
                (
                    "/vel",
                    "geometry_msgs/msg/TwistStamped",
                    _ns(t) + 1_000_000,
                    m.twist(_ns(t), 5.0 * math.cos(yaw), 5.0 * math.sin(yaw)),
                )
            )
            out.append(
                (
                    "/odom",
                    "nav_msgs/msg/Odometry",
                    _ns(t) + 1_000_000,
                    m.odom(_ns(t), tr["xt"][i], tr["yt"][i], yaw, 5.0),
                )
            )
    out.sort(key=lambda r: r[2])
    return out


_SUFFIX = {"ros1": ".bag", "sqlite3": "", "mcap": ""}


def _bag(tmp_path: Path, kind: str, name: str = "drive", **kw: object) -> Path:
    tr = _trajectory()
    return _write_bag(tmp_path / f"{name}{_SUFFIX[kind]}", kind, _messages(kind, tr, **kw))


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_round_trip_values_equal(tmp_path: Path, kind: str) -> None:
    tr = _trajectory()
    path = _bag(tmp_path, kind)
    drives = loaders.load(path)
    assert len(drives) == 1
    d = drives[0]
    assert d.meta.format == ("ros1" if kind == "ros1" else "ros2")
    assert d.name == "drive"
    # t = 0 at the earliest header stamp (the first GPS fix), epoch in meta
    assert d.meta.epoch_s == pytest.approx(T0_NS / 1e9)
    assert d.meta.time_source.startswith("gps=header")
    # GPS: times, lat/lon, ENU about the first fix, accuracy sqrt(mean(4, 4)) = 2 m
    np.testing.assert_allclose(d.gps.t, tr["tg"], atol=1e-9)
    np.testing.assert_allclose(d.gps.lat, tr["lat"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.gps.lon, tr["lon"], rtol=0, atol=1e-12)
    ex, ey = to_local(tr["lat"], tr["lon"], tr["lat"][0], tr["lon"][0])
    np.testing.assert_allclose(d.gps.x, ex, atol=1e-6)
    np.testing.assert_allclose(d.gps.y, ey, atol=1e-6)
    np.testing.assert_allclose(d.gps.accuracy, 2.0)
    assert d.meta.origin_lat == pytest.approx(LAT0) and d.meta.projection == "enu"
    # IMU
    assert d.imu is not None
    np.testing.assert_allclose(d.imu.t, tr["ti"], atol=1e-9)
    np.testing.assert_allclose(d.imu.ax, tr["ax"])
    np.testing.assert_allclose(d.imu.ay, tr["ay"])
    np.testing.assert_allclose(d.imu.yaw_rate, tr["yaw_rate"])
    np.testing.assert_allclose(np.unwrap(d.imu.yaw), tr["yaw_i"], atol=1e-12)
    # level IMU with an ENU orientation: levelled, yaw checked against the GPS course
    assert d.meta.extra["imu_frame"]["method"] == "orientation"
    assert d.meta.extra["imu_frame"]["yaw"] == "enu"
    # speed from TwistStamped; the odometry (frame odom) is NOT the truth by default (issue 18,
    # REP 105: it used to be, positions taken as-is): the drive is scored against its fixes
    assert d.speed is not None and d.truth is None
    np.testing.assert_allclose(d.speed.t, tr["tt"], atol=1e-9)
    np.testing.assert_allclose(d.speed.v, 5.0)
    assert d.meta.extra["truth_kind"] == "gps-fixes"
    assert any("/odom is not used as truth" in w for w in d.meta.warnings)
    # named, it is the truth, aligned to the GPS by a rigid fit (here the identity)
    d = loaders.load(path, topics={"truth": "/odom"})[0]
    assert d.truth is not None and d.meta.extra["truth_kind"] == "named"
    ex, ey = to_local(*_latlon_of(tr["xt"], tr["yt"]), tr["lat"][0], tr["lon"][0])
    np.testing.assert_allclose(d.truth.x, ex, atol=0.05)
    np.testing.assert_allclose(d.truth.y, ey, atol=0.05)
    np.testing.assert_allclose(d.truth.v, 5.0)
    np.testing.assert_allclose(d.truth.accuracy, 0.1)
    np.testing.assert_allclose(np.unwrap(d.truth.yaw), tr["yaw_t"], atol=1e-3)
    assert d.meta.extra["truth_frame"] == "odom"
    al = d.meta.extra["truth_alignment"]
    assert abs(al["rotation_deg"]) < 0.1 and al["residual_rms_m"] < 0.05
    assert any("aligned to the GPS" in w for w in d.meta.warnings)


def test_bare_db3_and_mcap_files(tmp_path: Path) -> None:
    tr = _trajectory()
    for kind, suffix in (("sqlite3", ".db3"), ("mcap", ".mcap")):
        folder = _bag(tmp_path, kind, name=f"f_{kind}")
        inner = next(folder.glob(f"*{suffix}"))
        bare = shutil.copy(inner, tmp_path / f"bare_{kind}{suffix}")
        d = load_rosbag(Path(bare))
        assert d.meta.format == "ros2" and d.name == f"bare_{kind}"
        np.testing.assert_allclose(d.gps.t, tr["tg"], atol=1e-9)
        # dispatcher: a .db3 inside a bag folder is read once, through its folder
        assert loaders.find_recordings(folder) == [(folder, "ros2")]


def test_quat_yaw_enu() -> None:
    yaw = np.array([0.0, 0.5, -2.0, 3.0])
    got = quat_yaw(np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2))
    np.testing.assert_allclose(got, yaw, atol=1e-12)
    assert np.isnan(quat_yaw(0.0, 0.0, 0.0, 0.0))


def test_no_fix_skipped_and_counted(tmp_path: Path) -> None:
    path = _bag(tmp_path, "mcap", no_fix_at=(3, 4, 5), with_others=False)
    d = load_rosbag(path)
    assert len(d.gps) == 17
    assert any("skipped 3 of 20" in w for w in d.meta.warnings)
    assert d.imu is None and d.speed is None and d.truth is None


def test_orientation_unknown_gives_no_yaw(tmp_path: Path) -> None:
    m = _Msgs(False)
    tr = _trajectory()
    msgs = _messages("sqlite3", tr, with_others=False)
    msgs += [
        (
            "/imu",
            "sensor_msgs/msg/Imu",
            _ns(t),
            m.imu(_ns(t), 0.1, 0.2, 1.0, 0.0, no_orientation=True),
        )
        for t in tr["ti"]
    ]
    d = load_rosbag(_write_bag(tmp_path / "b", "sqlite3", sorted(msgs, key=lambda r: r[2])))
    assert d.imu is not None and d.imu.yaw is None
    np.testing.assert_allclose(d.imu.ay, 0.2)


def test_zero_header_stamps_use_receive_time(tmp_path: Path) -> None:
    m = _Msgs(True)
    tr = _trajectory()
    msgs = [
        ("/fix", "sensor_msgs/msg/NavSatFix", _ns(t), m.navsatfix(0, la, lo))
        for t, la, lo in zip(tr["tg"], tr["lat"], tr["lon"], strict=True)
    ]
    d = load_rosbag(_write_bag(tmp_path / "z.bag", "ros1", msgs))
    assert d.meta.time_source == "gps=receive"
    np.testing.assert_allclose(d.gps.t, tr["tg"], atol=1e-9)


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_ambiguous_gps_topics_listed_then_resolved(tmp_path: Path, kind: str) -> None:
    path = _bag(tmp_path, kind, gps_topics=("/fix", "/gps/fix"))
    with pytest.raises(DataError) as ei:
        loaders.load(path)
    msg = str(ei.value)
    assert "/fix" in msg and "/gps/fix" in msg and "--topic gps=" in msg
    d = loaders.load(path, topics={"gps": "/gps/fix"})[0]
    assert len(d.gps) == 20 and d.meta.extra["topics"]["gps"]["topic"] == "/gps/fix"


def test_ambiguous_optional_role_can_be_skipped(tmp_path: Path) -> None:
    tr = _trajectory()
    msgs = _messages("mcap", tr)
    msgs += [("/odom2",) + r[1:] for r in msgs if r[0] == "/odom"]
    path = _write_bag(tmp_path / "two_odom", "mcap", sorted(msgs, key=lambda r: r[2]))
    # odometry is never the truth by default: two of them are only ambiguous if they would
    # feed the speed (here /vel does), and a named one is the truth
    d = load_rosbag(path)
    assert d.truth is None and d.meta.extra["topics"]["speed"]["topic"] == "/vel"
    d = load_rosbag(path, topics={"truth": "/odom2"})
    assert d.truth is not None and d.meta.extra["topics"]["truth"]["topic"] == "/odom2"
    path2 = _write_bag(
        tmp_path / "two_odom_no_vel",
        "mcap",
        sorted([r for r in msgs if r[0] != "/vel"], key=lambda r: r[2]),
    )
    with pytest.raises(DataError, match=r"several speed topics .*/odom, /odom2.*speed=none"):
        load_rosbag(path2)
    assert load_rosbag(path2, topics={"speed": "none"}).speed is None
    d = load_rosbag(path2, topics={"truth": "/odom2"})  # the other odometry feeds the speed
    assert {r: v["topic"] for r, v in d.meta.extra["topics"].items()} == {
        "gps": "/fix",
        "imu": "/imu",
        "speed": "/odom",
        "truth": "/odom2",
    }
    assert d.meta.extra["topics"]["speed"]["why"] == (
        "fallback: no TwistStamped or TwistWithCovarianceStamped"
    )


def test_named_topic_validated(tmp_path: Path) -> None:
    path = _bag(tmp_path, "sqlite3")
    with pytest.raises(DataError, match="no such topic"):
        load_rosbag(path, topics={"gps": "/nope"})
    with pytest.raises(DataError, match="expected sensor_msgs/msg/NavSatFix"):
        load_rosbag(path, topics={"gps": "/imu"})
    with pytest.raises(DataError, match="unknown topic role"):
        load_rosbag(path, topics={"lidar": "/imu"})
    # odometry named as speed, truth switched off
    d = load_rosbag(path, topics={"speed": "/odom", "truth": "none"})
    assert d.truth is None and d.speed is not None
    np.testing.assert_allclose(d.speed.v, 5.0)


def test_no_gps_topic_lists_what_is_there(tmp_path: Path) -> None:
    tr = _trajectory()
    msgs = [r for r in _messages("ros1", tr) if r[0] != "/fix"]
    path = _write_bag(tmp_path / "nogps.bag", "ros1", msgs)
    with pytest.raises(DataError) as ei:
        load_rosbag(path)
    msg = str(ei.value)
    assert "no GPS topic" in msg and "/imu (sensor_msgs/msg/Imu)" in msg
    assert "/odom (nav_msgs/msg/Odometry)" in msg and "nogps.bag" in msg


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_empty_bag(tmp_path: Path, kind: str) -> None:
    path = _write_bag(tmp_path / f"empty{_SUFFIX[kind]}", kind, [])
    with pytest.raises(DataError, match="empty bag"):
        load_rosbag(path)


@pytest.mark.parametrize(
    ("kind", "keep"), [("ros1", 0.5), ("mcap", 0.5), ("sqlite3", 0.5), ("sqlite3", 0.99)]
)
def test_truncated_bag(tmp_path: Path, kind: str, keep: float) -> None:
    path = _bag(tmp_path, kind)
    f = path if kind == "ros1" else next(p for p in path.iterdir() if p.suffix != ".yaml")
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(DataError, match="truncated or corrupt") as ei:
        load_rosbag(path)
    assert str(ei.value).startswith(str(path))


def test_corrupt_db3(tmp_path: Path) -> None:
    path = _bag(tmp_path, "sqlite3")
    f = next(path.glob("*.db3"))
    f.write_bytes(b"this is not a sqlite database" * 100)
    with pytest.raises(DataError, match="cannot read bag"):
        load_rosbag(path)


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_nan_latitude_names_topic_and_message(tmp_path: Path, kind: str) -> None:
    path = _bag(tmp_path, kind, nan_at=7, with_others=False)
    with pytest.raises(DataError, match=r"topic /fix message 7: invalid lat/lon \(nan"):
        load_rosbag(path)


def test_unknown_projection(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="unknown projection"):
        load_rosbag(_bag(tmp_path, "ros1", with_others=False), projection="utm")
