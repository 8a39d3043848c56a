"""Static transforms from a bag's ``/tf_static`` (and ``/tf``): the IMU -> ``base_link`` mount.

``tf2_msgs/TFMessage`` holds ``geometry_msgs/TransformStamped`` s; each gives the pose of
``child_frame_id`` in ``header.frame_id``, i.e. the rotation R_parent_child with
v_parent = R_parent_child v_child (REP 105 / tf2 conventions). :func:`chain_rotation` walks
the tree between two frames (either direction) and multiplies the rotations.

Frame names are compared without a leading ``/`` (ROS 1 bags often write ``/base_link``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from typing import Any

import numpy as np

from posbench.scenarios.imu_frames import quat_to_matrix

TFMESSAGE = "tf2_msgs/msg/TFMessage"
TF_TOPICS = ("/tf_static", "/tf")
#: the vehicle frame names tried, in order (REP 105)
BASE_FRAMES = ("base_link", "base_footprint")

#: ``tf2_msgs/msg/TFMessage`` definition, for typestores that lack it (rosbags' ROS1_NOETIC)
TFMESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms\n"


def register_tfmessage(typestore: Any) -> None:
    """Add ``tf2_msgs/msg/TFMessage`` to a rosbags typestore that does not have it."""
    if TFMESSAGE in typestore.types:
        return
    from rosbags.typesys import get_types_from_msg

    typestore.register(get_types_from_msg(TFMESSAGE_MSG, TFMESSAGE))


def frame_name(name: str) -> str:
    """A tf frame id without the ROS 1 leading slash."""
    return str(name).lstrip("/")


def edges_from_messages(msgs: Iterable[Any]) -> dict[tuple[str, str], np.ndarray]:
    """(parent, child) -> R_parent_child (3, 3), first occurrence of each edge kept."""
    out: dict[tuple[str, str], np.ndarray] = {}
    for m in msgs:
        for tr in m.transforms:
            key = (frame_name(tr.header.frame_id), frame_name(tr.child_frame_id))
            if key in out or not key[0] or not key[1]:
                continue
            q = tr.transform.rotation
            out[key] = quat_to_matrix(q.w, q.x, q.y, q.z)[0]
    return out


def chain_rotation(
    edges: dict[tuple[str, str], np.ndarray], parent: str, child: str
) -> np.ndarray | None:
    """R_parent_child (3, 3) through the tf tree (breadth-first, edges used both ways);
    identity when the frames are the same; None when they are not connected."""
    parent, child = frame_name(parent), frame_name(child)
    if parent == child:
        return np.eye(3)
    adj: dict[str, list[tuple[str, np.ndarray]]] = {}
    for (p, c), r in edges.items():
        if not np.all(np.isfinite(r)):
            continue
        adj.setdefault(p, []).append((c, r))  # v_p = r v_c
        adj.setdefault(c, []).append((p, r.T))
    seen = {parent: np.eye(3)}
    todo = deque([parent])
    while todo:
        f = todo.popleft()
        for nxt, r in adj.get(f, []):
            if nxt in seen:
                continue
            seen[nxt] = seen[f] @ r
            if nxt == child:
                return seen[nxt]
            todo.append(nxt)
    return None


def find_mount(
    edges: dict[tuple[str, str], np.ndarray], imu_frame: str
) -> tuple[np.ndarray | None, str | None]:
    """(R_base_imu, base frame name) for the first of :data:`BASE_FRAMES` connected to
    ``imu_frame``; (None, None) when none is (or the IMU frame is itself a base frame)."""
    imu_frame = frame_name(imu_frame)
    if not imu_frame or imu_frame in BASE_FRAMES:
        return None, None
    for base in BASE_FRAMES:
        r = chain_rotation(edges, base, imu_frame)
        if r is not None:
            return r, base
    return None, None
