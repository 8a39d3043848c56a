"""Loader for ROS 1 (``.bag``) and ROS 2 (``.db3``, ``.mcap`` or a folder with
``metadata.yaml``) bags through :class:`rosbags.highlevel.AnyReader`.

Roles and the message types that fill them (found by type; ``topics`` maps a
role to a topic name when a bag has several candidates):

- ``gps``   ``sensor_msgs/NavSatFix`` -> :class:`GpsStream` (required). Fixes
  with ``status.status < 0`` (no fix) are skipped and counted; accuracy [m] (per-axis
  1-sigma, :class:`~posbench.scenarios.drive.GpsStream`) is ``sqrt(mean(cov[0], cov[4]))``, the
  east and north variances of ``position_covariance`` (ENU, m^2), when its type is not
  UNKNOWN (> 0), else NaN; a stream with no stated fix at all has accuracy None.
  lat/lon are projected about the first valid fix (``projection``).
- ``imu``   ``sensor_msgs/Imu`` -> :class:`ImuStream`. REP 145: ``linear_acceleration`` is in
  the sensor frame (``header.frame_id``) and includes gravity; the mount comes from
  ``/tf_static`` (or ``/tf``). :mod:`posbench.scenarios.loaders.ros_imu` levels it (orientation),
  rotates it into the vehicle frame (tf mount, or a mount estimated from the data), removes
  gravity and checks the orientation's yaw against the GPS course; the path taken is in
  ``meta.extra["imu_frame"]``. A field with covariance[0] == -1 is absent.
- ``speed`` ``geometry_msgs/TwistStamped`` -> :class:`SpeedStream`, v = |(linear.x,
  linear.y)| [m/s]; when the bag has none, a ``nav_msgs/Odometry`` topic's twist (wheel
  odometry is a speed sensor, REP 105).
- ``truth`` only when named (``topics={"truth": "/name"}``, ``nav_msgs/Odometry``): a pose
  in a drifting or local frame is no independent truth (REP 105), so nothing becomes the
  truth automatically; without one the drive is scored against its own GPS fixes, as the
  paper's routes (``meta.extra["truth_kind"] = "gps-fixes"``). A named truth is aligned to
  the GPS ENU frame by a 2-D rigid fit over the drive (:mod:`posbench.scenarios.align`, frame names
  are not trusted: ``map``/``earth``/``utm`` are not our ENU about the first fix either); the
  transform and residual RMS are in ``meta.extra["truth_alignment"]``, and a residual above
  :func:`posbench.scenarios.align.alignment_limit_m` is a DataError.

A role mapped to ``""`` or ``"none"`` is not loaded. Times: a message's header
stamp when non-zero, its receive (log) time otherwise; ``meta.time_source``
records which per role. t = 0 is the earliest sample of any stream.
"""

from __future__ import annotations

import math
import sqlite3
import struct
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.align import alignment_limit_m, umeyama_2d
from posbench.scenarios.cleaning import clean_times
from posbench.scenarios.drive import (
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.imu_frames import wrap
from posbench.scenarios.loaders.ros_imu import imu_to_vehicle
from posbench.scenarios.loaders.ros_tf import TF_TOPICS, TFMESSAGE, edges_from_messages, find_mount
from posbench.scenarios.projection import PROJECTIONS, to_local

NAVSATFIX = "sensor_msgs/msg/NavSatFix"
IMU = "sensor_msgs/msg/Imu"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
ODOMETRY = "nav_msgs/msg/Odometry"

#: role -> (types found automatically, types accepted when the topic is named)
ROLE_TYPES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "gps": ((NAVSATFIX,), (NAVSATFIX,)),
    "imu": ((IMU,), (IMU,)),
    "speed": ((TWIST_STAMPED,), (TWIST_STAMPED, ODOMETRY)),
    "truth": ((), (ODOMETRY,)),  # never chosen automatically: see the module notes
}
#: a role's fallback types when the bag has none of its automatic ones
FALLBACK_TYPES: dict[str, tuple[str, ...]] = {"speed": (ODOMETRY,)}
_OFF = ("", "none", "-")


def normalize_msgtype(msgtype: str) -> str:
    """``pkg/Type`` (ROS 1 spelling) -> ``pkg/msg/Type``; ROS 2 names pass through."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def quat_yaw(w: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Yaw [rad] (rotation about z, ENU: 0 = east, CCW) of quaternions; NaN for zero norm."""
    w, x, y, z = (np.asarray(a, dtype=float) for a in (w, x, y, z))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    norm = w * w + x * x + y * y + z * z
    return np.where(norm > 1e-12, yaw, np.nan)


def _describe(topic_types: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m})" for t, m in sorted(topic_types.items())) or "none"


def select_topics(topic_types: dict[str, str], topics: dict[str, str] | None,
                  path: Path) -> dict[str, str | None]:
    """Choose one topic (or ``None``) per role.

    Args:
        topic_types: topic -> normalized message type, for every topic in the bag.
        topics: user's role -> topic choices (validated: role known, topic present,
            type acceptable for the role).
    Raises:
        DataError: unknown role / topic, wrong type, or several candidates for a role
            the user did not name.
    """
    topics = dict(topics or {})
    unknown = sorted(set(topics) - set(ROLE_TYPES))
    if unknown:
        raise DataError(path, f"unknown topic role(s) {', '.join(unknown)}; "
                              f"roles are {', '.join(ROLE_TYPES)}")
    chosen: dict[str, str | None] = {}
    for role, (auto, accepted) in ROLE_TYPES.items():
        if role in topics:
            name = topics[role]
            if name.strip().lower() in _OFF:
                chosen[role] = None
                continue
            if name not in topic_types:
                raise DataError(path, f"--topic {role}={name}: no such topic; the bag has "
                                      f"{_describe(topic_types)}")
            if topic_types[name] not in accepted:
                raise DataError(path, f"--topic {role}={name}: topic has type "
                                      f"{topic_types[name]}, expected "
                                      f"{' or '.join(accepted)}")
            chosen[role] = name
            continue
        cands = sorted(t for t, m in topic_types.items() if m in auto)
        kind = auto[0] if auto else ""
        if not cands and role in FALLBACK_TYPES:
            fb = FALLBACK_TYPES[role]
            cands = sorted(t for t, m in topic_types.items()
                           if m in fb and t != topics.get("truth"))
            kind = fb[0]
        if len(cands) > 1:
            off = "" if role == "gps" else f" (or --topic {role}=none to skip it)"
            raise DataError(path, f"several {role} topics ({kind}): {', '.join(cands)}; "
                                  f"choose one with --topic {role}=/name{off}")
        chosen[role] = cands[0] if cands else None
    if chosen["gps"] is None:
        raise DataError(path, f"no GPS topic ({NAVSATFIX}); the bag has "
                              f"{_describe(topic_types)}")
    return chosen


def _stamp_ns(msg: Any) -> int:
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def _times(stamps: list[int], recv: list[int]) -> tuple[np.ndarray, str]:
    """Header stamps [ns] where non-zero, receive times otherwise; and which were used."""
    s = np.asarray(stamps, dtype=np.int64)
    r = np.asarray(recv, dtype=np.int64)
    zero = s == 0
    if not np.any(zero):
        return s, "header"
    if np.all(zero):
        return r, "receive"
    return np.where(zero, r, s), f"header ({int(zero.sum())} of {s.size} zero stamps: receive)"


_READ_ERRORS: tuple[type[BaseException], ...] = (
    sqlite3.DatabaseError, struct.error, EOFError, ValueError, KeyError, IndexError,
    AssertionError, UnicodeDecodeError, OSError, TypeError, AttributeError,
)


def _rosbags_errors() -> tuple[type[BaseException], ...]:
    from rosbags.highlevel.anyreader import AnyReaderError
    from rosbags.rosbag1 import ReaderError as R1Error
    from rosbags.rosbag2 import ReaderError as R2Error
    from rosbags.serde import SerdeError
    from rosbags.typesys import TypesysError

    extra: tuple[type[BaseException], ...] = ()
    try:  # rosbags reads .db3 through apsw, whose errors are not sqlite3's
        import apsw

        extra = (apsw.Error,)
    except ImportError:  # pragma: no cover - depends on the rosbags version
        pass
    return (AnyReaderError, R1Error, R2Error, SerdeError, TypesysError) + extra + _READ_ERRORS


def _read(path: Path, wanted: dict[str, str | None], reader: Any) -> dict[str, list]:
    """Deserialize the chosen topics' messages: role -> list of (receive_ns, msg)."""
    by_topic: dict[str, list[str]] = {}
    for role, topic in wanted.items():
        if topic is not None:
            by_topic.setdefault(topic, []).append(role)
    conns = [c for c in reader.connections if c.topic in by_topic]
    out: dict[str, list] = {role: [] for role, t in wanted.items() if t is not None}
    for conn, t_ns, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        for role in by_topic[conn.topic]:
            out[role].append((int(t_ns), msg))
    return out


def _read_tf(reader: Any, topic_types: dict[str, str], imu_frame: str | None
             ) -> dict[tuple[str, str], np.ndarray]:
    """tf edges from ``/tf_static`` (all of it), then from ``/tf`` only while the IMU's mount
    is still unknown (stops reading as soon as it is found)."""
    from posbench.scenarios.loaders.ros_tf import frame_name

    edges: dict[tuple[str, str], np.ndarray] = {}
    if not imu_frame:
        return edges
    for topic in TF_TOPICS:
        if topic_types.get(topic) != TFMESSAGE:
            continue
        if find_mount(edges, imu_frame)[0] is not None:
            break
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in reader.messages(connections=conns):
            new = edges_from_messages([reader.deserialize(raw, conn.msgtype)])
            added = {k: v for k, v in new.items() if k not in edges}
            if not added:
                continue
            edges.update(added)
            if topic != "/tf_static" and any(frame_name(imu_frame) in k for k in added) \
                    and find_mount(edges, imu_frame)[0] is not None:
                break
    return edges


def _gps(items: list, topic: str, path: Path, warnings: list[str]) -> dict[str, Any]:
    stamps, recv, lat, lon, acc, idx = [], [], [], [], [], []
    skipped = 0
    for i, (t_ns, m) in enumerate(items):
        if int(m.status.status) < 0:
            skipped += 1
            continue
        stamps.append(_stamp_ns(m))
        recv.append(t_ns)
        lat.append(float(m.latitude))
        lon.append(float(m.longitude))
        idx.append(i)
        cov = np.asarray(m.position_covariance, dtype=float)
        acc.append(math.sqrt(max(0.5 * (cov[0] + cov[4]), 0.0))
                   if int(m.position_covariance_type) > 0 and cov.size >= 5 else math.nan)
    if skipped:
        warnings.append(f"gps: skipped {skipped} of {len(items)} NavSatFix messages on {topic} "
                        "with status < 0 (no fix)")
    if not lat:
        raise DataError(path, f"topic {topic}: no valid GPS fixes ({len(items)} messages, "
                              f"{skipped} without fix)")
    lat_a, lon_a = np.asarray(lat), np.asarray(lon)
    bad = ~np.isfinite(lat_a) | ~np.isfinite(lon_a) | (np.abs(lat_a) > 90) | (np.abs(lon_a) > 180)
    if np.any(bad):
        j = int(np.flatnonzero(bad)[0])
        raise DataError(path, f"topic {topic} message {idx[j]}: invalid lat/lon "
                              f"({float(lat_a[j])!r}, {float(lon_a[j])!r}); {int(bad.sum())} invalid in all")
    t, src = _times(stamps, recv)
    return {"t": t, "lat": lat_a, "lon": lon_a, "acc": np.asarray(acc), "src": src}


def _imu(items: list) -> dict[str, Any]:
    """Raw IMU fields in the sensor frame: f (N, 3) [m/s^2], w (N, 3) [rad/s], q (N, 4) w x y z
    (NaN rows where REP 145's covariance[0] == -1 marks the field absent, or a zero quaternion)."""
    stamps, recv = [], []
    n = len(items)
    f, w, q = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 4), np.nan)
    for i, (t_ns, m) in enumerate(items):
        stamps.append(_stamp_ns(m))
        recv.append(t_ns)
        if float(m.linear_acceleration_covariance[0]) != -1.0:
            a = m.linear_acceleration
            f[i] = (a.x, a.y, a.z)
        if float(m.orientation_covariance[0]) != -1.0:
            o = m.orientation
            q[i] = (o.w, o.x, o.y, o.z)
        if float(m.angular_velocity_covariance[0]) != -1.0:
            g = m.angular_velocity
            w[i] = (g.x, g.y, g.z)
    q[np.sum(q * q, axis=1) < 1e-12] = np.nan
    t, src = _times(stamps, recv)
    frames = sorted({str(m.header.frame_id) for _, m in items})
    return {"t": t, "f": f, "q": q if np.any(np.isfinite(q)) else None,
            "w": w if np.any(np.isfinite(w)) else None, "src": src, "frames": frames}


def _twist_v(m: Any) -> float:
    lin = m.twist.twist.linear if hasattr(m.twist, "twist") else m.twist.linear
    return math.hypot(float(lin.x), float(lin.y))


def _speed(items: list) -> dict[str, Any]:
    t, src = _times([_stamp_ns(m) for _, m in items], [t for t, _ in items])
    return {"t": t, "v": np.asarray([_twist_v(m) for _, m in items], dtype=float), "src": src}


def _truth(items: list) -> dict[str, Any]:
    t, src = _times([_stamp_ns(m) for _, m in items], [t for t, _ in items])
    pos = np.asarray([(m.pose.pose.position.x, m.pose.pose.position.y) for _, m in items],
                     dtype=float).reshape(-1, 2)
    q = np.asarray([(m.pose.pose.orientation.w, m.pose.pose.orientation.x,
                     m.pose.pose.orientation.y, m.pose.pose.orientation.z) for _, m in items],
                   dtype=float).reshape(-1, 4)
    cov = np.asarray([(m.pose.covariance[0], m.pose.covariance[7]) for _, m in items],
                     dtype=float).reshape(-1, 2)
    acc = np.sqrt(np.clip(cov.mean(axis=1), 0.0, None))
    frames = {str(m.header.frame_id) for _, m in items}
    return {"t": t, "x": pos[:, 0], "y": pos[:, 1], "yaw": quat_yaw(*q.T),
            "v": np.asarray([_twist_v(m) for _, m in items], dtype=float),
            "acc": acc if np.any(cov > 0) else None, "frames": sorted(frames), "src": src}


def _open_reader(path: Path) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    return AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))


def load_rosbag(path: Path, projection: str = "enu",
                topics: dict[str, str] | None = None) -> Drive:
    """Read a ROS 1 or ROS 2 bag into a :class:`Drive` (see the module notes).

    Args:
        path: a ``.bag``, ``.db3`` or ``.mcap`` file, or a ROS 2 bag folder.
        projection: ``"enu"`` or ``"mercator"`` (about the first valid fix).
        topics: role (``gps``, ``imu``, ``speed``, ``truth``) -> topic name.
    Raises:
        DataError: unreadable / empty bag, no or ambiguous GPS topic, invalid lat/lon.
    """
    path = Path(path)
    if projection not in PROJECTIONS:
        raise DataError(path, f"unknown projection {projection!r}; choose one of "
                              f"{', '.join(PROJECTIONS)}")
    if not path.exists():
        raise DataError(path, "no such file or folder")
    fmt = "ros1" if path.suffix.lower() == ".bag" else "ros2"
    errors = _rosbags_errors()
    try:
        reader = _open_reader(path)
        with reader:
            if reader.message_count == 0:
                raise DataError(path, "empty bag: it holds no messages "
                                      f"(topics: {_describe(_topic_types(reader.connections))})")
            topic_types = _topic_types(reader.connections)
            chosen = select_topics(topic_types, topics, path)
            items = _read(path, chosen, reader)
            imu_items = items.get("imu") or []
            edges = _read_tf(reader, topic_types,
                             str(imu_items[0][1].header.frame_id) if imu_items else None)
    except DataError:
        raise
    except FileNotFoundError as exc:
        raise DataError(path, f"cannot open bag: {exc}") from None
    except errors as exc:
        raise DataError(path, f"cannot read bag (truncated or corrupt?): "
                              f"{type(exc).__name__}: {exc}") from None
    return _assemble(path, fmt, projection, chosen, items, topic_types, edges)


def _topic_types(connections: Iterable[Any]) -> dict[str, str]:
    return {c.topic: normalize_msgtype(c.msgtype) for c in connections}


def _align_truth(c: dict[str, Any], gps: GpsStream, topic: str, path: Path,
                 extra: dict[str, Any], warnings: list[str]) -> dict[str, Any]:
    """Rotate and shift a named truth (local frame) onto the GPS fixes (2-D rigid fit)."""
    tt = c["t"]
    inside = (gps.t >= tt[0]) & (gps.t <= tt[-1])
    if inside.sum() < 3 or tt.size < 2:
        raise DataError(path, f"--topic truth={topic}: cannot align it to the GPS: only "
                              f"{int(inside.sum())} fixes fall inside its time span")
    src = np.column_stack([np.interp(gps.t[inside], tt, c["x"]),
                           np.interp(gps.t[inside], tt, c["y"])])
    dst = np.column_stack([gps.x[inside], gps.y[inside]])
    rot, tr, rms = umeyama_2d(src, dst)
    acc = gps.accuracy[inside] if gps.accuracy is not None else np.empty(0)
    acc = acc[np.isfinite(acc)]
    med = float(np.median(acc)) if acc.size else None
    limit = alignment_limit_m(med)
    ang = float(np.degrees(np.arctan2(rot[1, 0], rot[0, 0])))
    fit = f"rotation {ang:+.1f} deg, translation ({tr[0]:+.1f}, {tr[1]:+.1f}) m"
    what = f"{fit}, residual RMS {rms:.2f} m over {int(inside.sum())} fixes"
    extra["truth_alignment"] = {"rotation_deg": round(ang, 3),
                                "translation_m": [round(float(tr[0]), 3), round(float(tr[1]), 3)],
                                "residual_rms_m": round(rms, 3), "limit_m": round(limit, 3),
                                "fixes": int(inside.sum())}
    if rms > limit:
        stated = f"3 x median stated GPS accuracy {med:.2f} m, " if med is not None else ""
        raise DataError(path, f"--topic truth={topic}: residual RMS {rms:.2f} m after aligning it "
                              f"to the GPS fixes exceeds the limit {limit:.2f} m (max({stated}"
                              f"5 m); {fit}): it drifts or is mis-scaled, so it is no truth")
    warnings.append(f"truth: {topic} (frame {extra.get('truth_frame') or '?'}) aligned to the GPS "
                    f"ENU frame by a 2-D rigid fit: {what} (limit {limit:.2f} m)")
    xy = np.column_stack([c["x"], c["y"]]) @ rot.T + tr
    out = dict(c)
    out["x"], out["y"] = xy[:, 0], xy[:, 1]
    if c["yaw"] is not None:
        out["yaw"] = wrap(c["yaw"] + np.radians(ang))
    return out


def _assemble(path: Path, fmt: str, projection: str, chosen: dict[str, str | None],
              items: dict[str, list], topic_types: dict[str, str] | None = None,
              edges: dict[tuple[str, str], np.ndarray] | None = None) -> Drive:
    warnings: list[str] = []
    topic_types = topic_types or {}
    extra: dict[str, Any] = {"topics": {r: t for r, t in chosen.items() if t is not None}}
    sources: dict[str, str] = {}

    gps_topic = chosen["gps"]
    assert gps_topic is not None
    g = _gps(items["gps"], gps_topic, path, warnings)
    sources["gps"] = g["src"]
    streams: dict[str, dict[str, Any]] = {"gps": g}
    if chosen["imu"] is not None and items["imu"]:
        streams["imu"] = _imu(items["imu"])
    if chosen["speed"] is not None and items["speed"]:
        streams["speed"] = _speed(items["speed"])
    if chosen["truth"] is not None and items["truth"]:
        streams["truth"] = tr = _truth(items["truth"])
        extra["truth_frame"] = ",".join(tr["frames"])
    for role in ("imu", "speed", "truth"):
        if chosen[role] is not None and not items[role]:
            warnings.append(f"{role}: topic {chosen[role]} has no messages")
        if role in streams:
            sources[role] = streams[role]["src"]
    odoms = sorted(t for t, m in topic_types.items() if m == ODOMETRY and t != chosen["truth"])
    if "truth" not in streams:
        extra["truth_kind"] = "gps-fixes"
        if odoms:
            used = [t for t in odoms if t == chosen["speed"]]
            how = (f"its twist feeds the speed stream ({used[0]})" if used
                   else "not used (speed from " + (chosen["speed"] or "nowhere") + ")")
            warnings.append(f"truth: odometry {', '.join(odoms)} is not used as truth (a pose in a "
                            f"drifting frame such as odom is no independent reference, REP 105): "
                            f"{how}; scored against the GPS fixes themselves, as the paper's "
                            f"routes (name it with --topic truth=/name to align it to the GPS "
                            f"and score against it)")
    else:
        extra["truth_kind"] = "named"

    t0 = min(int(s["t"].min()) for s in streams.values())

    def rel(s: dict[str, Any]) -> np.ndarray:
        return (s["t"] - t0) * 1e-9

    t, c = clean_times(rel(g), {"lat": g["lat"], "lon": g["lon"], "acc": g["acc"]}, "gps",
                       warnings)
    lat0, lon0 = float(c["lat"][0]), float(c["lon"][0])
    x, y = to_local(c["lat"], c["lon"], lat0, lon0, projection)
    acc = c["acc"] if np.any(np.isfinite(c["acc"])) else None
    gps = GpsStream(t, x, y, c["lat"], c["lon"], acc)

    imu = speed = truth = None
    if "speed" in streams:
        s = streams["speed"]
        t, c = clean_times(rel(s), {"v": s["v"]}, "speed", warnings)
        speed = SpeedStream(t, c["v"])
    if "imu" in streams:
        s = streams["imu"]
        t, c = clean_times(rel(s), {k: s[k] for k in ("f", "w", "q")}, "imu", warnings)
        if len(s["frames"]) > 1:
            warnings.append(f"imu: several frame ids {', '.join(s['frames'])}: the mount of "
                            f"'{s['frames'][0]}' used for all")
        cols, info = imu_to_vehicle(t, c["f"], c["w"], c["q"], s["frames"][0], edges or {},
                                    (gps.t, gps.x, gps.y),
                                    None if speed is None else (speed.t, speed.v),
                                    str(chosen["imu"]), warnings)
        extra["imu_frame"] = info
        imu = ImuStream(t, cols["ax"], cols["ay"], cols["yaw"], cols["yaw_rate"])
    if "truth" in streams:
        s = streams["truth"]
        t, c = clean_times(rel(s), {k: s[k] for k in ("x", "y", "yaw", "v", "acc")}, "truth",
                           warnings)
        c["t"] = t
        c = _align_truth(c, gps, str(chosen["truth"]), path, extra, warnings)
        truth = TruthStream(t, c["x"], c["y"], c["yaw"], c["v"], c["acc"])

    name = path.name if path.is_dir() else path.stem
    meta = DriveMeta(name=name, source=str(path), format=fmt, epoch_s=t0 / 1e9,
                     origin_lat=lat0, origin_lon=lon0, projection=projection,
                     time_source="; ".join(f"{r}={s}" for r, s in sources.items()),
                     warnings=warnings, extra=extra)
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)
