"""``sensor_msgs/Imu`` samples (sensor frame, gravity included: REP 145) -> the Drive's IMU
stream (vehicle frame x forward / y left, gravity-free, yaw ENU), choosing one path per drive:

``orientation+tf_static`` / ``orientation``
    the message's orientation levels the specific force (gravity removed in the level frame);
    the horizontal part is rotated by -vehicle yaw, the vehicle attitude being the sensor's
    composed with the inverse mount from ``/tf_static`` (identity when there is none);
    yaw rate = world-up component of the angular velocity.
``tf_static``
    no orientation, mount from ``/tf_static``: f_b = R_bs f_s, vehicle assumed level (gravity on
    base z only); yaw rate = base-z component.
``estimated``
    no orientation, no mount, gravity off the sensor z: the mount is estimated from the data
    (:func:`posbench.scenarios.imu_frames.estimate_mount`) and a warning says so.
``as-is``
    no orientation, no mount, and the data are level (mean specific force within
    :data:`~posbench.scenarios.imu_frames.LEVEL_TILT_DEG` of +z) or hold no gravity: x, y
    used as they are.

Yaw (orientation paths only): checked against the GPS course while moving
(:func:`posbench.scenarios.imu_frames.yaw_offset`): kept ("enu"), shifted ("offset-corrected") or
not used ("dropped"). ``meta.extra["imu_frame"]`` records the path and the figures.
"""

from __future__ import annotations

from typing import Any, TypedDict

import numpy as np

import posbench.scenarios.imu_frames as fr
from posbench.scenarios.loaders.ros_tf import find_mount


class VehicleImu(TypedDict):
    """An IMU in the vehicle frame: ax, ay [m/s^2] (x forward, y left, gravity-free), yaw
    [rad, ENU] and yaw rate [rad/s] (None where the data give none)."""

    ax: np.ndarray
    ay: np.ndarray
    yaw: np.ndarray | None
    yaw_rate: np.ndarray | None


def _rpy_deg(r: np.ndarray) -> list[float]:
    return [round(float(np.degrees(a)), 1) + 0.0 for a in fr.matrix_to_rpy(r)]


def _check_yaw(
    t: np.ndarray,
    yaw_b: np.ndarray,
    gps: tuple[np.ndarray, np.ndarray, np.ndarray],
    info: dict[str, Any],
    warnings: list[str],
) -> np.ndarray | None:
    ct, course = fr.gps_course(*gps)
    off, spread, n = fr.yaw_offset(t, yaw_b, ct, course)
    info["yaw_samples"] = n
    info["yaw_offset_deg"] = round(float(np.degrees(off)), 1) if n else None
    info["yaw_spread_deg"] = round(float(np.degrees(spread)), 1) if n else None
    if n < fr.YAW_MIN_SAMPLES:
        info["yaw"] = "dropped"
        warnings.append(
            f"imu: yaw not used: too little motion to check it against the GPS course "
            f"({n} samples moving >= {fr.COURSE_MIN_DISPLACEMENT_M:g} m in "
            f"{fr.COURSE_CHORD_S:g} s, need {fr.YAW_MIN_SAMPLES})"
        )
        return None
    if np.degrees(spread) > fr.YAW_MAX_SPREAD_DEG:
        info["yaw"] = "dropped"
        warnings.append(
            f"imu: yaw not used: yaw - GPS course spreads {np.degrees(spread):.1f} deg "
            f"(limit {fr.YAW_MAX_SPREAD_DEG:g} deg, {n} samples while moving)"
        )
        return None
    if abs(np.degrees(off)) <= fr.YAW_ENU_TOL_DEG:
        info["yaw"] = "enu"
        return yaw_b
    info["yaw"] = "offset-corrected"
    warnings.append(
        f"imu: yaw is not ENU (magnetic or power-on reference?): offset "
        f"{np.degrees(off):+.1f} deg estimated against the GPS course "
        f"(spread {np.degrees(spread):.1f} deg, {n} samples) and added"
    )
    return fr.wrap(yaw_b + off)


def _speed_ref(
    speed: tuple[np.ndarray, np.ndarray] | None, gps: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray | None, np.ndarray | None, str]:
    if speed is not None and speed[0].size > 3:
        return speed[0], speed[1], "speed stream"
    tm, v, _ = fr.gps_chords(*gps)
    if tm.size > 3:
        return tm, v, "GPS-derived speed"
    return None, None, "none"


def imu_to_vehicle(
    t: np.ndarray,
    f_s: np.ndarray,
    w_s: np.ndarray | None,
    q: np.ndarray | None,
    frame: str,
    edges: dict[tuple[str, str], np.ndarray],
    gps: tuple[np.ndarray, np.ndarray, np.ndarray],
    speed: tuple[np.ndarray, np.ndarray] | None,
    topic: str,
    warnings: list[str],
) -> tuple[VehicleImu, dict[str, Any]]:
    """Convert one drive's IMU samples (see module doc).

    Args:
        t: (N,) times [s]; f_s: (N, 3) linear_acceleration [m/s^2], sensor frame (NaN: absent);
        w_s: (N, 3) angular velocity [rad/s] or None; q: (N, 4) orientation (w, x, y, z) or None.
        frame: the IMU's ``header.frame_id``; edges: tf edges
            (:mod:`posbench.scenarios.loaders.ros_tf`).
        gps: (t [s], x [m], y [m]) ENU fixes; speed: (t [s], v [m/s]) or None.
        topic: for messages; warnings: appended one line per non-trivial decision.
    Returns:
        ({"ax", "ay", "yaw", "yaw_rate"}, info for ``meta.extra["imu_frame"]``).
    """
    r_bs, base = find_mount(edges, frame)
    info: dict[str, Any] = {"frame": frame or None, "mount_from": None, "mount_rpy_deg": None}
    if r_bs is not None:
        info["mount_from"] = f"tf {base} -> {frame}"
        info["mount_rpy_deg"] = _rpy_deg(r_bs)
    if q is not None and np.any(np.all(np.isfinite(q), axis=1)):
        r_ws = fr.quat_to_matrix(*q.T)
        ax, ay, yaw_b = fr.level_vehicle_accel(f_s, r_ws, r_bs)
        yaw_rate = None if w_s is None else fr.world_yaw_rate(w_s, r_ws)
        info.update(
            method="orientation+tf_static" if r_bs is not None else "orientation",
            gravity_removed=True,
        )
        if r_bs is None:
            warnings.append(
                f"imu: {topic} levelled by its orientation, gravity removed; no "
                f"/tf_static mount for frame '{frame}': its x axis taken as forward"
            )
        else:
            warnings.append(
                f"imu: {topic} levelled by its orientation, gravity removed; mount "
                f"{base} -> {frame} from tf (roll, pitch, yaw "
                f"{', '.join(f'{a:g}' for a in info['mount_rpy_deg'])} deg)"
            )
        yaw = _check_yaw(t, yaw_b, gps, info, warnings)
        return {"ax": ax, "ay": ay, "yaw": yaw, "yaw_rate": yaw_rate}, info

    info["yaw"] = "none"
    if r_bs is not None:
        ax, ay, yaw_rate = fr.vehicle_from_mount(f_s, w_s, r_bs)
        info.update(method="tf_static", gravity_removed=True)
        warnings.append(
            f"imu: {topic} has no orientation: rotated by the tf mount {base} -> "
            f"{frame}, vehicle assumed level (gravity on its z only)"
        )
        return {"ax": ax, "ay": ay, "yaw": None, "yaw_rate": yaw_rate}, info

    ok = np.all(np.isfinite(f_s), axis=1)
    mean = f_s[ok].mean(axis=0) if ok.any() else np.full(3, np.nan)
    norm = float(np.linalg.norm(mean))
    level = (
        ok.any()
        and norm > fr.NO_GRAVITY_FRACTION * fr.G0
        and fr.tilt_deg(mean) <= fr.LEVEL_TILT_DEG
    )
    if not ok.any() or norm <= fr.NO_GRAVITY_FRACTION * fr.G0 or level:
        info.update(
            method="as-is",
            gravity_removed=False,
            mean_specific_force=[round(float(v), 3) for v in mean],
        )
        if ok.any() and not level:
            warnings.append(
                f"imu: {topic} shows no gravity (mean specific force {norm:.2f} m/s^2):"
                " x, y used as vehicle-frame acceleration as they are"
            )
        yr = None if w_s is None else w_s[:, 2]
        return {"ax": f_s[:, 0], "ay": f_s[:, 1], "yaw": None, "yaw_rate": yr}, info
    st, sv, ref = _speed_ref(speed, gps)
    r_bs, est = fr.estimate_mount(t, f_s, st, sv)
    ax, ay, yaw_rate = fr.vehicle_from_mount(f_s, w_s, r_bs)
    corr = est["forward_corr"]
    info.update(
        method="estimated",
        gravity_removed=True,
        mount_rpy_deg=_rpy_deg(r_bs),
        mount_from=f"data: up from {est['up_from']}, forward from {est['forward_from']}"
        + (f" ({ref})" if est["forward_from"] == "d(speed)/dt" else ""),
        forward_corr=None if not np.isfinite(corr) else round(float(corr), 3),
    )
    warnings.append(
        f"imu: {topic} has no orientation and no tf mount, gravity "
        f"{fr.tilt_deg(mean):.0f} deg off its z: mount estimated from the data "
        f"(roll, pitch, yaw {', '.join(f'{a:g}' for a in info['mount_rpy_deg'])} deg; "
        f"{info['mount_from']}" + (f", correlation {corr:.2f}" if np.isfinite(corr) else "") + ")"
    )
    return {"ax": ax, "ay": ay, "yaw": None, "yaw_rate": yaw_rate}, info
