"""Reading a ROS bag through :class:`rosbags.highlevel.AnyReader`: opening it, the errors a
truncated or corrupt bag raises (:func:`read_errors`), its topics' message types
(:func:`bag_topic_types`), the chosen topics' messages and the tf edges that give the IMU's
mount. Nothing here interprets a message's fields (:mod:`posbench.scenarios.loaders.ros_msgs`
does); receive times are integer nanoseconds as the bag logs them.
"""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.loaders.ros_msgs import normalize_msgtype
from posbench.scenarios.loaders.ros_tf import TF_TOPICS, TFMESSAGE, edges_from_messages, find_mount

_READ_ERRORS: tuple[type[BaseException], ...] = (
    sqlite3.DatabaseError,
    struct.error,
    EOFError,
    ValueError,
    KeyError,
    IndexError,
    AssertionError,
    UnicodeDecodeError,
    OSError,
    TypeError,
    AttributeError,
)


def read_errors() -> tuple[type[BaseException], ...]:
    """The exceptions reading a damaged bag can raise: rosbags' own, apsw's (where rosbags
    reads .db3 through it) and the low-level ones a truncated file gives."""
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


def read_messages(path: Path, wanted: dict[str, str | None], reader: Any) -> dict[str, list]:
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


def read_tf_edges(
    reader: Any, topic_types: dict[str, str], imu_frame: str | None
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
            if (
                topic != "/tf_static"
                and any(frame_name(imu_frame) in k for k in added)
                and find_mount(edges, imu_frame)[0] is not None
            ):
                break
    return edges


def open_reader(path: Path) -> Any:
    """An (unopened) reader of the bag at ``path``, ROS 2 Humble's types as the default."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    return AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))


def bag_topic_types(connections: Iterable[Any]) -> dict[str, str]:
    """Topic -> its message type, normalised
    (:func:`~posbench.scenarios.loaders.ros_msgs.normalize_msgtype`)."""
    return {c.topic: normalize_msgtype(c.msgtype) for c in connections}
