"""ROS message types the bag loader reads, and the numpy fields it takes from them.

Every reader takes ``items``: a list of ``(receive_ns, msg)`` of one topic, in log order, and
returns a dict of numpy arrays with ``t`` [ns, int64] and ``src`` (which time was used):
the header stamp where non-zero, the receive (log) time otherwise.

Units: positions [m] in the message's own frame (``header.frame_id``), lat/lon [deg],
yaw [rad] about z (ENU convention: 0 = x axis / east, counter-clockwise), speeds [m/s],
accuracies as per-axis 1-sigma [m].

Non-finite values (:func:`refuse_nonfinite`): a NaN or infinite position, orientation,
acceleration, rate or twist in a message is refused (:class:`DataError` naming the bag, the
topic and the message's index on it, 0-based), as the table loader refuses such a cell with
its line; only a field the message marks absent (REP 145: covariance[0] = -1; a zero
quaternion) is not read. A covariance may be NaN ("not stated", as an empty accuracy cell),
never infinite.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.errors import DataError

NAVSATFIX = "sensor_msgs/msg/NavSatFix"
IMU = "sensor_msgs/msg/Imu"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
TWIST_COV_STAMPED = "geometry_msgs/msg/TwistWithCovarianceStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
#: message types with a pose (``pose.position``/``orientation``, or ``pose.pose.*``)
POSE_TYPES = (POSE_STAMPED, POSE_COV_STAMPED, ODOMETRY)
#: message types with a twist (``twist.linear``, or ``twist.twist.linear``)
TWIST_TYPES = (TWIST_STAMPED, TWIST_COV_STAMPED, ODOMETRY)


def normalize_msgtype(msgtype: str) -> str:
    """``pkg/Type`` (ROS 1 spelling) -> ``pkg/msg/Type``; ROS 2 names pass through."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def short_type(msgtype: str) -> str:
    """``sensor_msgs/msg/NavSatFix`` -> ``NavSatFix``."""
    return msgtype.rsplit("/", 1)[-1]


def quat_yaw(w: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Yaw [rad] (rotation about z, ENU: 0 = east, CCW) of quaternions; NaN for zero norm."""
    w, x, y, z = (np.asarray(a, dtype=float) for a in (w, x, y, z))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    norm = w * w + x * x + y * y + z * z
    return np.where(norm > 1e-12, yaw, np.nan)


def refuse_nonfinite(
    values: np.ndarray,
    topic: str,
    path: Path,
    field: str,
    present: np.ndarray | None = None,
    index: np.ndarray | None = None,
    allow_nan: bool = False,
) -> None:
    """Refuse the first message whose ``field`` is not finite, naming the topic and message.

    Args:
        values: (N,) or (N, k): the field of each message.
        present: (N,) where the message carries the field (None: all).
        index: (N,) each row's index among the topic's messages (None: the row number).
        allow_nan: NaN means "not stated" (a covariance); only infinities are refused.
    Raises:
        DataError: ``topic /imu message 7: non-finite linear_acceleration (nan, 0.1, 9.8);
            1 such message in all``.
    """
    v = np.asarray(values, dtype=float).reshape(len(values), -1)
    bad = np.isinf(v) if allow_nan else ~np.isfinite(v)
    rows = np.any(bad, axis=1)
    if present is not None:
        rows &= present
    if not np.any(rows):
        return
    j = int(np.flatnonzero(rows)[0])
    k = j if index is None else int(index[j])
    shown = ", ".join(repr(float(a)) for a in v[j])
    raise DataError(
        path,
        f"topic {topic} message {k}: non-finite {field} ({shown}); "
        f"{int(rows.sum())} such message{'s' * (int(rows.sum()) != 1)} in all",
    )


def stamp_ns(msg: Any) -> int:
    """A message's header stamp [ns]."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def times(stamps: list[int], recv: list[int]) -> tuple[np.ndarray, str]:
    """Header stamps [ns] where non-zero, receive times otherwise; and which were used."""
    s = np.asarray(stamps, dtype=np.int64)
    r = np.asarray(recv, dtype=np.int64)
    zero = s == 0
    if not np.any(zero):
        return s, "header"
    if np.all(zero):
        return r, "receive"
    return np.where(zero, r, s), f"header ({int(zero.sum())} of {s.size} zero stamps: receive)"


def item_times(items: list) -> tuple[np.ndarray, str]:
    """:func:`times` of ``(receive_ns, msg)`` items."""
    return times([stamp_ns(m) for _, m in items], [t for t, _ in items])


def navsat_fields(
    items: list, topic: str, path: Path, warnings: list[str], role: str = "gps"
) -> dict[str, Any]:
    """``sensor_msgs/NavSatFix``: t, lat, lon [deg] and acc [m].

    Fixes with ``status.status < 0`` (no fix) are skipped and counted in ``warnings``. acc is
    the per-axis 1-sigma ``sqrt(mean(cov[0], cov[4]))`` of the east and north variances
    (ENU, m^2) of ``position_covariance``, NaN where its type is UNKNOWN (0).

    Raises:
        DataError: no valid fix, an invalid lat/lon or an infinite covariance (naming the
            bag, topic and message).
    """
    keep = [i for i, (_, m) in enumerate(items) if int(m.status.status) >= 0]
    skipped = len(items) - len(keep)
    if skipped:
        warnings.append(
            f"{role}: skipped {skipped} of {len(items)} NavSatFix messages on {topic} "
            "with status < 0 (no fix)"
        )
    if not keep:
        raise DataError(
            path,
            f"topic {topic}: no valid {'GPS' if role == 'gps' else role} fixes "
            f"({len(items)} messages, {skipped} without fix)",
        )
    ms = [items[i][1] for i in keep]
    lat_a = np.asarray([float(m.latitude) for m in ms])
    lon_a = np.asarray([float(m.longitude) for m in ms])
    cov = np.asarray(
        [np.asarray(m.position_covariance, dtype=float)[:5] for m in ms], dtype=float
    ).reshape(len(ms), -1)
    known = np.asarray([int(m.position_covariance_type) > 0 for m in ms]) & (cov.shape[1] >= 5)
    bad = ~np.isfinite(lat_a) | ~np.isfinite(lon_a) | (np.abs(lat_a) > 90) | (np.abs(lon_a) > 180)
    if np.any(bad):
        j = int(np.flatnonzero(bad)[0])
        raise DataError(
            path,
            f"topic {topic} message {keep[j]}: invalid lat/lon "
            f"({float(lat_a[j])!r}, {float(lon_a[j])!r}); {int(bad.sum())} invalid in all",
        )
    acc = np.full(len(ms), math.nan)
    if cov.shape[1] >= 5:
        refuse_nonfinite(
            cov[:, [0, 4]], topic, path, "position_covariance", known, np.asarray(keep), True
        )
        acc[known] = np.sqrt(np.clip(0.5 * (cov[known, 0] + cov[known, 4]), 0.0, None))
    t, src = times([stamp_ns(m) for m in ms], [items[i][0] for i in keep])
    return {"t": t, "lat": lat_a, "lon": lon_a, "acc": acc, "src": src, "index": np.asarray(keep)}


def twist_xy(m: Any) -> tuple[float, float]:
    """(linear.x, linear.y) [m/s] of a message's twist (TwistStamped,
    TwistWithCovarianceStamped or Odometry, whose twist is in ``child_frame_id``)."""
    lin = m.twist.twist.linear if hasattr(m.twist, "twist") else m.twist.linear
    return float(lin.x), float(lin.y)


def _speeds(items: list, topic: str, path: Path) -> np.ndarray:
    """|(linear.x, linear.y)| [m/s] of each message's twist; non-finite ones refused."""
    lin = np.asarray([twist_xy(m) for _, m in items], dtype=float).reshape(-1, 2)
    refuse_nonfinite(lin, topic, path, "twist linear (x, y)")
    return np.hypot(lin[:, 0], lin[:, 1])


def speed_fields(items: list, topic: str, path: Path) -> dict[str, Any]:
    """A twist topic as speed: t [ns] and v [m/s] (|(linear.x, linear.y)|,
    :func:`twist_xy`); a non-finite twist is refused (:func:`refuse_nonfinite`)."""
    t, src = item_times(items)
    return {"t": t, "v": _speeds(items, topic, path), "src": src}


def pose_fields(items: list, msgtype: str, topic: str, path: Path) -> dict[str, Any]:
    """A pose topic (PoseStamped, PoseWithCovarianceStamped or Odometry) in its own frame:
    t [ns], x, y [m], yaw [rad, about the frame's z], v [m/s] (Odometry's twist, else None),
    acc [m] (per-axis 1-sigma ``sqrt(mean(cov[0], cov[7]))`` of the pose covariance where
    stated, i.e. any positive, else None) and the frame ids. A non-finite position,
    orientation or twist, or an infinite covariance, is refused (:func:`refuse_nonfinite`)."""
    t, src = item_times(items)
    poses = [m.pose if msgtype == POSE_STAMPED else m.pose.pose for _, m in items]
    pos = np.asarray([(p.position.x, p.position.y) for p in poses], dtype=float).reshape(-1, 2)
    q = np.asarray(
        [(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z) for p in poses],
        dtype=float,
    ).reshape(-1, 4)
    refuse_nonfinite(pos, topic, path, "position (x, y)")
    refuse_nonfinite(q, topic, path, "orientation (w, x, y, z)")
    acc = None
    if msgtype != POSE_STAMPED:
        cov = np.asarray(
            [(m.pose.covariance[0], m.pose.covariance[7]) for _, m in items], dtype=float
        ).reshape(-1, 2)
        refuse_nonfinite(cov, topic, path, "pose covariance", allow_nan=True)
        if np.any(cov > 0):
            acc = np.sqrt(np.clip(cov.mean(axis=1), 0.0, None))
    v = _speeds(items, topic, path) if msgtype in TWIST_TYPES else None
    yaw = quat_yaw(*q.T)
    return {
        "t": t,
        "x": pos[:, 0],
        "y": pos[:, 1],
        "yaw": yaw if np.any(np.isfinite(yaw)) else None,
        "v": v,
        "acc": acc,
        "frames": sorted({str(m.header.frame_id) for _, m in items}),
        "src": src,
    }


def imu_fields(items: list, topic: str, path: Path) -> dict[str, Any]:
    """Raw IMU fields in the sensor frame: f (N, 3) [m/s^2], w (N, 3) [rad/s], q (N, 4) w x y z
    (NaN rows where REP 145's covariance[0] == -1 marks the field absent, or a zero quaternion).
    A field a message carries that is not finite is refused, naming the message
    (:func:`~posbench.scenarios.loaders.ros_msgs.refuse_nonfinite`)."""
    stamps, recv = [], []
    n = len(items)
    f, w, q = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 4), np.nan)
    has_f, has_w, has_q = (np.zeros(n, dtype=bool) for _ in range(3))
    for i, (t_ns, m) in enumerate(items):
        stamps.append(stamp_ns(m))
        recv.append(t_ns)
        if float(m.linear_acceleration_covariance[0]) != -1.0:
            a = m.linear_acceleration
            f[i], has_f[i] = (a.x, a.y, a.z), True
        if float(m.orientation_covariance[0]) != -1.0:
            o = m.orientation
            q[i], has_q[i] = (o.w, o.x, o.y, o.z), True
        if float(m.angular_velocity_covariance[0]) != -1.0:
            g = m.angular_velocity
            w[i], has_w[i] = (g.x, g.y, g.z), True
    zero_q = np.sum(q * q, axis=1) < 1e-12  # a zero quaternion: no orientation
    q[zero_q] = np.nan
    refuse_nonfinite(f, topic, path, "linear_acceleration", has_f)
    refuse_nonfinite(w, topic, path, "angular_velocity", has_w)
    refuse_nonfinite(q, topic, path, "orientation (w, x, y, z)", has_q & ~zero_q)
    t, src = times(stamps, recv)
    frames = sorted({str(m.header.frame_id) for _, m in items})
    return {
        "t": t,
        "f": f,
        "q": q if np.any(np.isfinite(q)) else None,
        "w": w if np.any(np.isfinite(w)) else None,
        "src": src,
        "frames": frames,
    }
