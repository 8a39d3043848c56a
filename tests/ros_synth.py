"""Write ROS 1 / ROS 2 bags of a synthetic drive the way real robots record them (issue 18).

A reusable writer: :func:`write_bag` takes a :class:`SynthBag` of options and writes

- ``/fix``  ``sensor_msgs/NavSatFix`` at irregular 2-5 Hz, white noise ``gps_noise_m`` per axis,
  ``position_covariance`` diagonal = noise^2 (type 2, diagonal known);
- ``/imu``  ``sensor_msgs/Imu`` at ``imu_hz`` in frame ``imu_link``, mounted by ``mount_rpy_deg``
  (roll 90 deg: gravity on the sensor's +y): specific force f_s = R_bs^T (a_long, a_lat, g)
  (gravity included, REP 145), angular velocity in the sensor frame (``yaw_rate_sign`` -1
  flips it), orientation R_ws = Rz(yaw + ``yaw_ref_offset_deg`` + ``yaw_ref_drift_dps`` t) R_bs
  or absent (``orientation_covariance[0] = -1``);
- ``/tf_static`` ``tf2_msgs/TFMessage`` base_link -> imu_link (when ``tf_static``);
- ``/odom``  ``nav_msgs/Odometry`` wheel odometry in ``odom`` (child ``base_link``): speed and
  positions scaled by ``odom_scale`` (drift), heading rotated by ``odom_heading_deg`` and
  drifting by ``odom_yaw_drift_dps`` [deg/s];
- ``/ground_truth`` (when ``ground_truth``) ``nav_msgs/Odometry`` in ``map``: the exact path,
  rotated by ``truth_rot_deg`` and shifted by ``truth_shift_m``;
- ``/pose`` (when ``pose_truth`` names ``PoseStamped`` or ``PoseWithCovarianceStamped``) the same
  map-frame path at ``odom_hz`` (scaled by ``pose_scale`` to make it a bad truth; the
  PoseWithCovarianceStamped states ``pose_sigma_m``);
- ``/gnss/rtk`` (when ``rtk``) a second ``sensor_msgs/NavSatFix`` at ``rtk_hz``: the exact path
  plus ``rtk_noise_m`` white noise per axis, its covariance stated (``rtk_cov_type``); every
  ``rtk_no_fix_every``-th fix (0: none) has ``status = -1`` and a wild position;
- ``/vel`` (when ``twist`` names ``TwistStamped`` or ``TwistWithCovarianceStamped``) the speed
  at ``odom_hz`` (linear.x = v [m/s] in base_link).

``gps_topic`` renames ``/fix``, ``gps_bias_m`` shifts its fixes (east, north) [m];
``gps_interval_s = (0.1, 0.1)`` gives regular 10 Hz fixes.

The path is :func:`posbench.scenarios.synthetic.generate_drive`'s truth (turns, stops), cut to
``duration_s``; :func:`synth_truth` returns it (ENU about the first fix's origin) for asserts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore

from posbench.scenarios.degrade import enu_to_latlon
from posbench.scenarios.drive import TruthStream
from posbench.scenarios.imu_frames import G0, matrix_to_quat, rpy_to_matrix
from posbench.scenarios.loaders.ros_tf import register_tfmessage
from posbench.scenarios.synthetic import generate_drive
from posbench.scenarios.synthetic_sensors import ORIGIN_LAT, ORIGIN_LON

T0_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class SynthBag:
    """Options of one synthetic bag (see the module doc)."""

    kind: str = "ros1"  # "ros1" (.bag), "sqlite3" or "mcap" (ROS 2 folders)
    seed: int = 3
    route: str = "mixed"
    duration_s: float = 90.0
    mount_rpy_deg: tuple[float, float, float] = (90.0, 0.0, 0.0)
    orientation: bool = True
    yaw_ref_offset_deg: float = 0.0
    yaw_ref_drift_dps: float = 0.0
    tf_static: bool = True
    yaw_rate_sign: float = 1.0
    imu_hz: float = 40.0
    accel_noise: float = 0.05
    gyro_noise: float = 0.005
    odom: bool = True
    odom_scale: float = 1.02
    odom_heading_deg: float = 25.0
    odom_yaw_drift_dps: float = 0.0
    odom_hz: float = 20.0
    gps_noise_m: float = 1.0
    gps_interval_s: tuple[float, float] = (0.2, 0.5)
    ground_truth: bool = False
    truth_rot_deg: float = 40.0
    truth_shift_m: tuple[float, float] = (120.0, -35.0)
    gps_topic: str = "/fix"
    gps_bias_m: tuple[float, float] = (0.0, 0.0)
    pose_truth: str = ""  # "", "PoseStamped" or "PoseWithCovarianceStamped"
    pose_scale: float = 1.0
    pose_sigma_m: float = 0.05
    rtk: bool = False
    rtk_noise_m: float = 0.02
    rtk_hz: float = 10.0
    rtk_no_fix_every: int = 0
    rtk_cov_type: int = 2
    twist: str = ""  # "", "TwistStamped" or "TwistWithCovarianceStamped"


def synth_truth(opts: SynthBag) -> TruthStream:
    """The drive's exact path (100 Hz, ENU about :data:`ORIGIN_LAT`, :data:`ORIGIN_LON`)."""
    return generate_drive(seed=opts.seed, route=opts.route, duration_s=opts.duration_s).truth


class _Msgs:
    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        register_tfmessage(self.ts)
        self.T = self.ts.types

    def header(self, t_ns: int, frame: str) -> object:
        stamp = self.T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def vec(self, v: np.ndarray) -> object:
        return self.T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, q: np.ndarray) -> object:
        return self.T["geometry_msgs/msg/Quaternion"](
            w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3])
        )

    def odom(self, t_ns: int, frame: str, x: float, y: float, yaw: float, v: float) -> object:
        T = self.T
        q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=self.quat(q)
        )
        cov = np.zeros(36)
        cov[0] = cov[7] = 0.01
        tw = T["geometry_msgs/msg/Twist"](
            linear=self.vec([v, 0.0, 0.0]), angular=self.vec([0.0, 0.0, 0.0])
        )
        return T["nav_msgs/msg/Odometry"](
            header=self.header(t_ns, frame),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)),
        )


def _ns(t: float) -> int:
    return T0_NS + int(round(t * 1e9))


def _messages(opts: SynthBag, m: _Msgs) -> list[tuple[str, str, int, object]]:
    T = m.T
    tr = synth_truth(opts)
    rng = np.random.default_rng(opts.seed + 1000)
    t, yaw_u = tr.t, np.unwrap(tr.yaw)
    v = tr.v
    w = np.gradient(yaw_u, t)
    a_long = np.gradient(v, t)
    out: list[tuple[str, str, int, object]] = []

    # GPS, irregular 2-5 Hz
    lo, hi = opts.gps_interval_s
    tf = np.cumsum(rng.uniform(lo, hi, int(t[-1] / lo) + 2))
    tf = tf[tf < t[-1]]
    gx = np.interp(tf, t, tr.x) + rng.normal(0.0, opts.gps_noise_m, tf.size) + opts.gps_bias_m[0]
    gy = np.interp(tf, t, tr.y) + rng.normal(0.0, opts.gps_noise_m, tf.size) + opts.gps_bias_m[1]
    lat, lon = enu_to_latlon(gx, gy, ORIGIN_LAT, ORIGIN_LON)
    cov = np.zeros(9)
    cov[0] = cov[4] = opts.gps_noise_m**2
    cov[8] = (2 * opts.gps_noise_m) ** 2
    st = T["sensor_msgs/msg/NavSatStatus"](status=0, service=1)
    for k, tk in enumerate(tf):
        out.append(
            (
                opts.gps_topic,
                "sensor_msgs/msg/NavSatFix",
                _ns(tk) + 20_000_000,
                T["sensor_msgs/msg/NavSatFix"](
                    header=m.header(_ns(tk), "gps"),
                    status=st,
                    latitude=float(lat[k]),
                    longitude=float(lon[k]),
                    altitude=120.0,
                    position_covariance=cov,
                    position_covariance_type=2,
                ),
            )
        )

    # IMU in its own, rotated frame, gravity included
    r_bs = rpy_to_matrix(*np.radians(opts.mount_rpy_deg))
    ti = np.arange(0.013, t[-1], 1.0 / opts.imu_hz)
    vi, wi, ai = (np.interp(ti, t, a) for a in (v, w, a_long))
    yi = np.interp(ti, t, yaw_u)
    f_b = np.column_stack([ai, vi * wi, np.full(ti.size, G0)])
    f_b += rng.normal(0.0, opts.accel_noise, f_b.shape)
    w_b = np.column_stack([np.zeros(ti.size), np.zeros(ti.size), opts.yaw_rate_sign * wi])
    w_b += rng.normal(0.0, opts.gyro_noise, w_b.shape)
    f_s, w_s = f_b @ r_bs, w_b @ r_bs  # R_bs^T v, row-wise
    yr = yi + math.radians(opts.yaw_ref_offset_deg) + math.radians(opts.yaw_ref_drift_dps) * ti
    c, s = np.cos(yr), np.sin(yr)
    r_wb = np.zeros((ti.size, 3, 3))
    r_wb[:, 0, 0], r_wb[:, 0, 1], r_wb[:, 1, 0], r_wb[:, 1, 1], r_wb[:, 2, 2] = c, -s, s, c, 1
    q = matrix_to_quat(r_wb @ r_bs)
    ocov = np.zeros(9)
    ocov[0] = 1e-4 if opts.orientation else -1.0
    for k, tk in enumerate(ti):
        out.append(
            (
                "/imu",
                "sensor_msgs/msg/Imu",
                _ns(tk) + 2_000_000,
                T["sensor_msgs/msg/Imu"](
                    header=m.header(_ns(tk), "imu_link"),
                    orientation=m.quat(q[k] if opts.orientation else np.zeros(4)),
                    orientation_covariance=ocov,
                    angular_velocity=m.vec(w_s[k]),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=m.vec(f_s[k]),
                    linear_acceleration_covariance=np.zeros(9),
                ),
            )
        )

    if opts.tf_static:
        qm = matrix_to_quat(r_bs)[0]
        tfs = T["geometry_msgs/msg/TransformStamped"](
            header=m.header(_ns(0.0), "base_link"),
            child_frame_id="imu_link",
            transform=T["geometry_msgs/msg/Transform"](
                translation=m.vec([0.2, 0.0, 0.3]), rotation=m.quat(qm)
            ),
        )
        out.append(
            (
                "/tf_static",
                "tf2_msgs/msg/TFMessage",
                _ns(0.0),
                T["tf2_msgs/msg/TFMessage"](transforms=[tfs]),
            )
        )

    to = np.arange(0.007, t[-1], 1.0 / opts.odom_hz)
    if opts.odom:
        h = yaw_u + math.radians(opts.odom_heading_deg) + math.radians(opts.odom_yaw_drift_dps) * t
        vs = v * opts.odom_scale
        dt = np.diff(t, prepend=t[0])
        ox, oy = np.cumsum(vs * np.cos(h) * dt), np.cumsum(vs * np.sin(h) * dt)
        for tk in to:
            out.append(
                (
                    "/odom",
                    "nav_msgs/msg/Odometry",
                    _ns(tk) + 1_000_000,
                    m.odom(
                        _ns(tk),
                        "odom",
                        float(np.interp(tk, t, ox)),
                        float(np.interp(tk, t, oy)),
                        float(np.interp(tk, t, h)),
                        float(np.interp(tk, t, vs)),
                    ),
                )
            )
    if opts.ground_truth:
        a = math.radians(opts.truth_rot_deg)
        gx_ = math.cos(a) * tr.x - math.sin(a) * tr.y + opts.truth_shift_m[0]
        gy_ = math.sin(a) * tr.x + math.cos(a) * tr.y + opts.truth_shift_m[1]
        for tk in to:
            out.append(
                (
                    "/ground_truth",
                    "nav_msgs/msg/Odometry",
                    _ns(tk) + 1_000_000,
                    m.odom(
                        _ns(tk),
                        "map",
                        float(np.interp(tk, t, gx_)),
                        float(np.interp(tk, t, gy_)),
                        float(np.interp(tk, t, yaw_u)) + a,
                        float(np.interp(tk, t, v)),
                    ),
                )
            )
    out += _extras(opts, m, tr, rng)
    out.sort(key=lambda r: r[2])
    return out


def _map_frame(opts: SynthBag, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ENU [m] -> the map frame of the truths: rotated by truth_rot_deg, shifted, scaled."""
    a = math.radians(opts.truth_rot_deg)
    k = opts.pose_scale
    return (
        k * (math.cos(a) * x - math.sin(a) * y) + opts.truth_shift_m[0],
        k * (math.sin(a) * x + math.cos(a) * y) + opts.truth_shift_m[1],
    )


def _extras(
    opts: SynthBag, m: _Msgs, tr: TruthStream, rng: np.random.Generator
) -> list[tuple[str, str, int, object]]:
    """The optional pose truth, RTK receiver and twist topics (see the module doc)."""
    T = m.T
    out: list[tuple[str, str, int, object]] = []
    t, yaw_u = tr.t, np.unwrap(tr.yaw)
    to = np.arange(0.007, t[-1], 1.0 / opts.odom_hz)
    if opts.pose_truth:
        mt = f"geometry_msgs/msg/{opts.pose_truth}"
        px, py = _map_frame(opts, np.interp(to, t, tr.x), np.interp(to, t, tr.y))
        yaw = np.interp(to, t, yaw_u) + math.radians(opts.truth_rot_deg)
        cov = np.zeros(36)
        cov[0] = cov[7] = opts.pose_sigma_m**2
        for k, tk in enumerate(to):
            q = np.array([math.cos(yaw[k] / 2), 0.0, 0.0, math.sin(yaw[k] / 2)])
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(px[k]), y=float(py[k]), z=0.0),
                orientation=m.quat(q),
            )
            if opts.pose_truth == "PoseStamped":
                msg = T[mt](header=m.header(_ns(tk), "map"), pose=pose)
            else:
                msg = T[mt](
                    header=m.header(_ns(tk), "map"),
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                )
            out.append(("/pose", mt, _ns(tk) + 1_000_000, msg))
    if opts.rtk:
        tk_ = np.arange(0.05, t[-1], 1.0 / opts.rtk_hz)
        rx = np.interp(tk_, t, tr.x) + rng.normal(0.0, opts.rtk_noise_m, tk_.size)
        ry = np.interp(tk_, t, tr.y) + rng.normal(0.0, opts.rtk_noise_m, tk_.size)
        bad = (
            np.arange(tk_.size) % opts.rtk_no_fix_every == opts.rtk_no_fix_every - 1
            if opts.rtk_no_fix_every
            else np.zeros(tk_.size, bool)
        )
        rx[bad] += 500.0
        lat, lon = enu_to_latlon(rx, ry, ORIGIN_LAT, ORIGIN_LON)
        cov = np.zeros(9)
        cov[0] = cov[4] = opts.rtk_noise_m**2
        cov[8] = (2 * opts.rtk_noise_m) ** 2
        for k, tk in enumerate(tk_):
            st = T["sensor_msgs/msg/NavSatStatus"](status=-1 if bad[k] else 2, service=1)
            out.append(
                (
                    "/gnss/rtk",
                    "sensor_msgs/msg/NavSatFix",
                    _ns(tk) + 5_000_000,
                    T["sensor_msgs/msg/NavSatFix"](
                        header=m.header(_ns(tk), "gps_rtk"),
                        status=st,
                        latitude=float(lat[k]),
                        longitude=float(lon[k]),
                        altitude=120.0,
                        position_covariance=cov,
                        position_covariance_type=opts.rtk_cov_type,
                    ),
                )
            )
    if opts.twist:
        mt = f"geometry_msgs/msg/{opts.twist}"
        vv = np.interp(to, t, tr.v)
        for k, tk in enumerate(to):
            tw = T["geometry_msgs/msg/Twist"](
                linear=m.vec([vv[k], 0.0, 0.0]), angular=m.vec([0.0, 0.0, 0.0])
            )
            if opts.twist == "TwistStamped":
                msg = T[mt](header=m.header(_ns(tk), "base_link"), twist=tw)
            else:
                msg = T[mt](
                    header=m.header(_ns(tk), "base_link"),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](
                        twist=tw, covariance=np.zeros(36)
                    ),
                )
            out.append(("/vel", mt, _ns(tk) + 1_000_000, msg))
    return out


def write_bag(path: Path, opts: SynthBag = SynthBag()) -> Path:
    """Write the bag (``path`` gets ``.bag`` for ROS 1; a ROS 2 bag is a folder); returns
    the path to load."""
    path = Path(path)
    m = _Msgs(opts.kind == "ros1")
    msgs = _messages(opts, m)
    topics: dict[str, str] = {}
    for topic, msgtype, _, _ in msgs:
        topics.setdefault(topic, msgtype)
    if opts.kind == "ros1":
        from rosbags.rosbag1 import Writer

        path = path.with_suffix(".bag")
        with Writer(path) as w:
            conns = {tp: w.add_connection(tp, mt, typestore=m.ts) for tp, mt in topics.items()}
            for topic, msgtype, t_ns, msg in msgs:
                w.write(conns[topic], t_ns, m.ts.serialize_ros1(msg, msgtype))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if opts.kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {tp: w.add_connection(tp, mt, typestore=m.ts) for tp, mt in topics.items()}
        for topic, msgtype, t_ns, msg in msgs:
            w.write(conns[topic], t_ns, m.ts.serialize_cdr(msg, msgtype))
    return path
