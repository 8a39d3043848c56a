"""Which bag topic plays which role (gps, imu, speed, truth), and why.

Found by message type; the user's ``topics`` (``--topic role=/name``) override it:

- ``gps``   ``NavSatFix``; the only one besides a named truth. When the only NavSatFix is the
  named truth itself, it is the fixes too (``meta.fix_source = "truth"``: a run simulates
  its fixes from it).
- ``imu``   ``Imu``.
- ``speed`` ``TwistStamped`` or ``TwistWithCovarianceStamped``; when the bag has none, an
  ``Odometry`` (wheel odometry is a speed sensor, REP 105). A named truth is never the speed.
- ``truth`` only when named: ``NavSatFix`` (a second receiver, e.g. RTK), ``PoseStamped``,
  ``PoseWithCovarianceStamped`` or ``Odometry``. A pose in a drifting or local frame is no
  independent truth (REP 105), so nothing becomes the truth by itself.

A role mapped to ``""``, ``"none"`` or ``"-"`` is not loaded.
"""

from __future__ import annotations

from pathlib import Path

from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.ros_msgs import (
    IMU,
    NAVSATFIX,
    ODOMETRY,
    POSE_COV_STAMPED,
    POSE_STAMPED,
    TWIST_COV_STAMPED,
    TWIST_STAMPED,
    short_type,
)
from posbench.scenarios.loaders.ros_tf import TF_TOPICS

#: role -> (types found automatically, types accepted when the topic is named)
ROLE_TYPES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "gps": ((NAVSATFIX,), (NAVSATFIX,)),
    "imu": ((IMU,), (IMU,)),
    "speed": ((TWIST_STAMPED, TWIST_COV_STAMPED), (TWIST_STAMPED, TWIST_COV_STAMPED, ODOMETRY)),
    # never chosen automatically: see the module notes
    "truth": ((), (NAVSATFIX, POSE_STAMPED, POSE_COV_STAMPED, ODOMETRY)),
}
#: a role's fallback types when the bag has none of its automatic ones
FALLBACK_TYPES: dict[str, tuple[str, ...]] = {"speed": (ODOMETRY,)}
OFF = ("", "none", "-")


def describe(topic_types: dict[str, str]) -> str:
    """``/a (type), /b (type)`` of every topic, or ``none``."""
    return ", ".join(f"{t} ({m})" for t, m in sorted(topic_types.items())) or "none"


def _named(role: str, name: str, topic_types: dict[str, str], path: Path) -> str:
    accepted = ROLE_TYPES[role][1]
    if name not in topic_types:
        raise DataError(
            path, f"--topic {role}={name}: no such topic; the bag has {describe(topic_types)}"
        )
    if topic_types[name] not in accepted:
        raise DataError(
            path,
            f"--topic {role}={name}: topic has type {topic_types[name]}, "
            f"expected {' or '.join(accepted)}",
        )
    return name


def select_topics(
    topic_types: dict[str, str], topics: dict[str, str] | None, path: Path
) -> tuple[dict[str, str | None], dict[str, str]]:
    """Choose one topic (or ``None``) per role, and say why.

    Args:
        topic_types: topic -> normalized message type, for every topic in the bag.
        topics: the user's role -> topic choices (validated: role known, topic present,
            type acceptable for the role).
    Returns:
        (role -> topic or None, role -> why it was chosen, for the chosen roles).
    Raises:
        DataError: unknown role / topic, wrong type, no GPS, or several candidates for a role
            the user did not name (naming the bag).
    """
    topics = dict(topics or {})
    unknown = sorted(set(topics) - set(ROLE_TYPES))
    if unknown:
        raise DataError(
            path, f"unknown topic role(s) {', '.join(unknown)}; roles are {', '.join(ROLE_TYPES)}"
        )
    chosen: dict[str, str | None] = {}
    why: dict[str, str] = {}
    for role in ROLE_TYPES:
        name = topics.get(role)
        if name is None:
            continue
        if name.strip().lower() in OFF:
            chosen[role] = None
        else:
            chosen[role] = _named(role, name, topic_types, path)
            why[role] = "named"
    truth = chosen.get("truth")
    if truth is not None:
        why["truth"] = (
            "named; a second receiver: projected like the fixes (same origin and "
            "projection), no fit"
            if topic_types[truth] == NAVSATFIX
            else "named; aligned to the fixes' ENU frame by a 2-D rigid fit"
        )
    for role, (auto, _) in ROLE_TYPES.items():
        if role in chosen or not auto:
            chosen.setdefault(role, None)
            continue
        kinds = " or ".join(short_type(k) for k in auto)
        cands = sorted(t for t, m in topic_types.items() if m in auto and t != truth)
        reason = f"only {kinds}" + (
            "" if truth is None or topic_types[truth] not in auto else " besides the truth"
        )
        if not cands and role in FALLBACK_TYPES:
            fb = FALLBACK_TYPES[role]
            cands = sorted(t for t, m in topic_types.items() if m in fb and t != truth)
            reason = f"fallback: no {kinds}"
            kinds = " or ".join(short_type(k) for k in fb)
        if len(cands) > 1:
            off = "" if role == "gps" else f" (or --topic {role}=none to skip it)"
            raise DataError(
                path,
                f"several {role} topics ({kinds}): {', '.join(cands)}; "
                f"choose one with --topic {role}=/name{off}",
            )
        if not cands and role == "gps" and truth is not None and topic_types[truth] == NAVSATFIX:
            cands, reason = (
                [truth],
                (
                    "the truth's own topic (the only NavSatFix): a run "
                    "simulates its fixes from the truth"
                ),
            )
        chosen[role] = cands[0] if cands else None
        if cands:
            why[role] = reason
    if chosen["gps"] is None:
        raise DataError(path, f"no GPS topic ({NAVSATFIX}); the bag has {describe(topic_types)}")
    return chosen, why


def unused_topics(
    topic_types: dict[str, str], chosen: dict[str, str | None], topics: dict[str, str] | None
) -> dict[str, dict[str, str]]:
    """The bag's other topics: topic -> {"type", "why"} (why each plays no role)."""
    topics = topics or {}
    used = {t for t in chosen.values() if t is not None}
    out: dict[str, dict[str, str]] = {}
    for topic, mt in sorted(topic_types.items()):
        if topic in used:
            continue
        off = [
            r
            for r, (auto, acc) in ROLE_TYPES.items()
            if mt in acc and r in topics and topics[r].strip().lower() in OFF
        ]
        if topic in TF_TOPICS:
            why = "tf: read for the IMU's mount" if chosen.get("imu") else "tf: no IMU to mount"
        elif off:
            why = f"--topic {off[0]}=none"
        elif mt in (ODOMETRY, POSE_STAMPED, POSE_COV_STAMPED, NAVSATFIX):
            why = f"a truth only when named: --topic truth={topic}" + (
                "; odometry drifts (REP 105)" if mt == ODOMETRY else ""
            )
        elif any(mt in acc for acc in (a for _, a in ROLE_TYPES.values())):
            why = "another topic was named for its role"
        else:
            why = "no role for this type"
        out[topic] = {"type": mt, "why": why}
    return out
