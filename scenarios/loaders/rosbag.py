"""Loader for ROS 1 (``.bag``) and ROS 2 (``.db3``, ``.mcap`` or a folder with
``metadata.yaml``) bags through :class:`rosbags.highlevel.AnyReader`.

Roles and the message types that fill them (found by type,
:mod:`~posbench.scenarios.loaders.ros_topics`; ``topics`` maps a role to a topic name when a
bag has several candidates). Which topic plays which role and why is in
``meta.extra["topics"]`` (role -> {"topic", "type", "why"}), the other topics in
``meta.extra["unused_topics"]`` (topic -> {"type", "why"}); ``bench data inspect`` prints both.

- ``gps``   ``sensor_msgs/NavSatFix`` -> :class:`GpsStream` (required). Fixes
  with ``status.status < 0`` (no fix) are skipped and counted; accuracy [m] (per-axis
  1-sigma, :class:`~posbench.scenarios.drive.GpsStream`) is ``sqrt(mean(cov[0], cov[4]))``, the
  east and north variances of ``position_covariance`` (ENU, m^2), when its type is not
  UNKNOWN (> 0), else NaN; a stream with no stated fix at all has accuracy None.
  lat/lon are projected about the first valid fix (``projection``). They are a receiver of
  their own (``meta.fix_source = "receiver"``) unless the named truth is the same topic.
- ``imu``   ``sensor_msgs/Imu`` -> :class:`ImuStream`. REP 145: ``linear_acceleration`` is in
  the sensor frame (``header.frame_id``) and includes gravity; the mount comes from
  ``/tf_static`` (or ``/tf``). :mod:`posbench.scenarios.loaders.ros_imu` levels it (orientation),
  rotates it into the vehicle frame (tf mount, or a mount estimated from the data), removes
  gravity and checks the orientation's yaw against the GPS course; the path taken is in
  ``meta.extra["imu_frame"]``. A field with covariance[0] == -1 is absent.
- ``speed`` ``geometry_msgs/TwistStamped`` or ``geometry_msgs/TwistWithCovarianceStamped``
  -> :class:`SpeedStream`, v = |(linear.x, linear.y)| [m/s]; when the bag has neither, a
  ``nav_msgs/Odometry`` topic's twist (wheel odometry is a speed sensor, REP 105). A topic
  named as the truth is never taken as the speed.
- ``truth`` only when named (``topics={"truth": "/name"}``): ``sensor_msgs/NavSatFix`` (a second
  receiver such as RTK: projected like the fixes, no fit), ``geometry_msgs/PoseStamped``,
  ``geometry_msgs/PoseWithCovarianceStamped`` or ``nav_msgs/Odometry`` (aligned to the GPS
  ENU frame by a 2-D rigid fit, refused when its residual is over the limit):
  :mod:`posbench.scenarios.loaders.ros_truth`. A pose in a drifting or local frame is no
  independent truth (REP 105), so nothing becomes the truth automatically; without one the
  drive is scored against its own GPS fixes, as the paper's routes
  (``meta.extra["truth_kind"] = "gps-fixes"``).

A role mapped to ``""`` or ``"none"`` is not loaded. Times: a message's header
stamp when non-zero, its receive (log) time otherwise; ``meta.time_source``
records which per role. t = 0 is the earliest sample of any stream [s].
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.cleaning import clean_index, take
from posbench.scenarios.drive import (
    FIXES_FROM_TRUTH,
    FIXES_RECEIVER,
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.ros_imu import imu_to_vehicle
from posbench.scenarios.loaders.ros_msgs import (
    IMU,
    NAVSATFIX,
    ODOMETRY,
    POSE_COV_STAMPED,
    POSE_STAMPED,
    TWIST_COV_STAMPED,
    TWIST_STAMPED,
    imu_fields,
    navsat_fields,
    normalize_msgtype,
    quat_yaw,
    short_type,
    speed_fields,
)
from posbench.scenarios.loaders.ros_read import (
    bag_topic_types,
    open_reader,
    read_errors,
    read_messages,
    read_tf_edges,
)
from posbench.scenarios.loaders.ros_topics import (
    FALLBACK_TYPES,
    ROLE_TYPES,
    describe,
    select_topics,
    unused_topics,
)
from posbench.scenarios.loaders.ros_truth import truth_fields, truth_stream
from posbench.scenarios.projection import PROJECTIONS, to_local
from posbench.scenarios.time_axis import check_span, check_stream_times

__all__ = [
    "FALLBACK_TYPES",
    "IMU",
    "NAVSATFIX",
    "ODOMETRY",
    "POSE_COV_STAMPED",
    "POSE_STAMPED",
    "ROLE_TYPES",
    "TWIST_COV_STAMPED",
    "TWIST_STAMPED",
    "load_rosbag",
    "normalize_msgtype",
    "quat_yaw",
    "select_topics",
]


def load_rosbag(path: Path, projection: str = "enu", topics: dict[str, str] | None = None) -> Drive:
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
        raise DataError(
            path, f"unknown projection {projection!r}; choose one of {', '.join(PROJECTIONS)}"
        )
    if not path.exists():
        raise DataError(path, "no such file or folder")
    fmt = "ros1" if path.suffix.lower() == ".bag" else "ros2"
    errors = read_errors()
    try:
        reader = open_reader(path)
        with reader:
            if reader.message_count == 0:
                raise DataError(
                    path,
                    "empty bag: it holds no messages "
                    f"(topics: {describe(bag_topic_types(reader.connections))})",
                )
            topic_types = bag_topic_types(reader.connections)
            chosen, why = select_topics(topic_types, topics, path)
            items = read_messages(path, chosen, reader)
            imu_items = items.get("imu") or []
            edges = read_tf_edges(
                reader, topic_types, str(imu_items[0][1].header.frame_id) if imu_items else None
            )
    except DataError:
        raise
    except FileNotFoundError as exc:
        raise DataError(path, f"cannot open bag: {exc}") from None
    except errors as exc:
        raise DataError(
            path, f"cannot read bag (truncated or corrupt?): {type(exc).__name__}: {exc}"
        ) from None
    roles = {
        r: {"topic": t, "type": topic_types[t], "why": why.get(r, "")}
        for r in ROLE_TYPES
        if (t := chosen.get(r)) is not None
    }
    return _assemble(
        path,
        fmt,
        projection,
        chosen,
        items,
        topic_types,
        edges,
        roles,
        unused_topics(topic_types, chosen, topics),
    )


def _no_truth_notes(
    topic_types: dict[str, str], chosen: dict[str, str | None], warnings: list[str]
) -> None:
    """Why a drive without a named truth is scored against its own fixes (REP 105)."""
    odoms = sorted(t for t, m in topic_types.items() if m == ODOMETRY)
    if odoms:
        used = [t for t in odoms if t == chosen["speed"]]
        how = (
            f"its twist feeds the speed stream ({used[0]})"
            if used
            else "not used (speed from " + (chosen["speed"] or "nowhere") + ")"
        )
        warnings.append(
            f"truth: odometry {', '.join(odoms)} is not used as truth (a pose in a "
            f"drifting frame such as odom is no independent reference, REP 105): "
            f"{how}; scored against the GPS fixes themselves, as the paper's "
            f"routes (name it with --topic truth=/name to align it to the GPS "
            f"and score against it)"
        )
    others = sorted(
        f"{t} ({short_type(m)})"
        for t, m in topic_types.items()
        if m in (NAVSATFIX, POSE_STAMPED, POSE_COV_STAMPED) and t != chosen["gps"]
    )
    if others:
        warnings.append(
            f"truth: {', '.join(others)} could be the truth but nothing is the truth "
            f"unless named: scored against the GPS fixes themselves (name one with "
            f"--topic truth=/name)"
        )


def _checked_times(
    t: np.ndarray,
    index: np.ndarray | None,
    role: str,
    topic: str,
    path: Path,
    warnings: list[str],
) -> tuple[np.ndarray, np.ndarray]:
    """A stream's times [s] cleaned (:func:`clean_index`) and checked
    (:func:`~posbench.scenarios.time_axis.check_stream_times`, naming the topic and message:
    ``index`` maps its samples to their messages on the topic, None where they are the same),
    and the kept samples' indices."""
    t, idx = clean_index(t, role, warnings)
    msg = idx if index is None else index[idx]
    check_stream_times(
        t, role, path, lambda i: f"topic {topic} message {int(msg[i])}", f"topic {topic} stamps"
    )
    return t, idx


def _assemble(
    path: Path,
    fmt: str,
    projection: str,
    chosen: dict[str, str | None],
    items: dict[str, list],
    topic_types: dict[str, str],
    edges: dict[tuple[str, str], np.ndarray],
    roles: dict[str, dict[str, str]],
    unused: dict[str, dict[str, str]],
) -> Drive:
    warnings: list[str] = []
    extra: dict[str, Any] = {"topics": roles, "unused_topics": unused}
    sources: dict[str, str] = {}

    gps_topic = chosen["gps"]
    assert gps_topic is not None
    g = navsat_fields(items["gps"], gps_topic, path, warnings)
    sources["gps"] = g["src"]
    streams: dict[str, dict[str, Any]] = {"gps": g}
    if chosen["imu"] is not None and items["imu"]:
        streams["imu"] = imu_fields(items["imu"], str(chosen["imu"]), path)
    if chosen["speed"] is not None and items["speed"]:
        streams["speed"] = speed_fields(items["speed"], str(chosen["speed"]), path)
    truth_topic = chosen["truth"]
    if truth_topic is not None and items["truth"]:
        ttype = topic_types[truth_topic]
        streams["truth"] = tr = truth_fields(
            items["truth"], ttype, truth_topic, path, warnings if truth_topic != gps_topic else []
        )
        extra["truth_frame"] = ",".join(tr["frames"])
    for role in ("imu", "speed", "truth"):
        if chosen[role] is not None and not items[role]:
            warnings.append(f"{role}: topic {chosen[role]} has no messages")
        if role in streams:
            sources[role] = streams[role]["src"]
    if "truth" not in streams:
        extra["truth_kind"] = "gps-fixes"
        _no_truth_notes(topic_types, chosen, warnings)
    else:
        extra["truth_kind"] = "named"

    t0 = min(int(s["t"].min()) for s in streams.values())

    def rel(s: dict[str, Any]) -> np.ndarray:
        return (s["t"] - t0) * 1e-9

    # every stream's times cleaned and checked before anything is built on them
    cleaned: dict[str, tuple[np.ndarray, np.ndarray]] = {
        role: _checked_times(
            rel(s := streams[role]), s.get("index"), role, str(chosen[role]), path, warnings
        )
        for role in ("gps", "speed", "imu")
        if role in streams
    }
    if "truth" in streams:  # cleaned with its fields in truth_stream: only checked here
        tr = streams["truth"]
        cleaned["truth"] = _checked_times(
            rel(tr), tr.get("index"), "truth", str(truth_topic), path, []
        )
    check_span({role: t for role, (t, _) in cleaned.items()}, path)

    t, idx = cleaned["gps"]
    c = {k: take(g[k], idx) for k in ("lat", "lon", "acc")}
    lat0, lon0 = float(c["lat"][0]), float(c["lon"][0])
    x, y = to_local(c["lat"], c["lon"], lat0, lon0, projection)
    acc = c["acc"] if np.any(np.isfinite(c["acc"])) else None
    gps = GpsStream(t, x, y, c["lat"], c["lon"], acc)

    imu = speed = truth = None
    if "speed" in streams:
        t, idx = cleaned["speed"]
        speed = SpeedStream(t, take(streams["speed"]["v"], idx))
    if "imu" in streams:
        s = streams["imu"]
        t, idx = cleaned["imu"]
        if len(s["frames"]) > 1:
            warnings.append(
                f"imu: several frame ids {', '.join(s['frames'])}: the mount of "
                f"'{s['frames'][0]}' used for all"
            )
        cols, info = imu_to_vehicle(
            t,
            take(s["f"], idx),
            take(s["w"], idx),
            take(s["q"], idx),
            s["frames"][0],
            edges,
            (gps.t, gps.x, gps.y),
            None if speed is None else (speed.t, speed.v),
            str(chosen["imu"]),
            warnings,
        )
        extra["imu_frame"] = info
        imu = ImuStream(t, cols["ax"], cols["ay"], cols["yaw"], cols["yaw_rate"])
    if "truth" in streams:
        truth = truth_stream(
            streams["truth"],
            rel(streams["truth"]),
            gps,
            lat0,
            lon0,
            projection,
            str(truth_topic),
            path,
            extra,
            warnings,
        )
        al = extra.get("truth_alignment", {})
        if "residual_rms_m" in al:
            roles["truth"]["why"] += (
                f": rotation {al['rotation_deg']:+.1f} deg, residual RMS "
                f"{al['residual_rms_m']:.2f} m, limit {al['limit_m']:.2f} m"
            )

    name = path.name if path.is_dir() else path.stem
    meta = DriveMeta(
        name=name,
        source=str(path),
        format=fmt,
        epoch_s=t0 / 1e9,
        origin_lat=lat0,
        origin_lon=lon0,
        projection=projection,
        time_source="; ".join(f"{r}={s}" for r, s in sources.items()),
        warnings=warnings,
        extra=extra,
        fix_source=FIXES_FROM_TRUTH if gps_topic == truth_topic else FIXES_RECEIVER,
    )
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)
