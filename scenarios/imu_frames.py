"""IMU frames, gravity and yaw reference: pure maths for the loaders (numpy only).

Frames (REP 103 / REP 145):

- *sensor* ``s``: the IMU's own axes (``header.frame_id``); ``linear_acceleration`` is the
  specific force f = a - g_vec [m/s^2] in it, so a sensor at rest reads +9.81 m/s^2 *up*;
- *base* ``b`` (vehicle): x forward, y left, z up (``base_link``);
- *world* ``w``: ENU-like level frame, z up. An IMU's ``orientation`` is R_ws (sensor attitude
  in the world); its yaw reference is often magnetic north or the power-on heading, not east.

``R_bs`` ("mount") maps sensor vectors into the base frame: v_b = R_bs v_s (the rotation of
the tf transform base_link -> imu frame). Vehicle attitude: R_wb = R_ws R_bs^T.

Rotation matrices are (N, 3, 3) or (3, 3) arrays; quaternions are given as w, x, y, z.
"""

from __future__ import annotations

from typing import TypedDict

import numpy as np

#: standard gravity [m/s^2]
G0 = 9.80665
#: the specific force's mean tilt from sensor +z [deg] below which an IMU without orientation
#: counts as level (its x/y used as they are, "as-is")
LEVEL_TILT_DEG = 2.0
#: a mean specific force below this fraction of G0 means the data hold no gravity (already removed)
NO_GRAVITY_FRACTION = 0.5
#: speed [m/s] below which a sample counts as standstill (gravity estimate)
STANDSTILL_MPS = 0.2
#: yaw vs GPS course: chord length [s] and minimum chord displacement [m] (GPS noise averages out)
COURSE_CHORD_S = 2.0
COURSE_MIN_DISPLACEMENT_M = 8.0
#: yaw offsets smaller than this [deg] count as "already ENU"
YAW_ENU_TOL_DEG = 5.0
#: circular spread (std) [deg] of yaw - course above which the yaw is not used
YAW_MAX_SPREAD_DEG = 15.0
#: fewest course samples needed to judge the yaw
YAW_MIN_SAMPLES = 8


def quat_to_matrix(w: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of quaternions (normalised first; zero norm -> NaN)."""
    q = np.stack([np.asarray(a, dtype=float) for a in (w, x, y, z)], axis=-1).reshape(-1, 4)
    n = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(n > 1e-12, q / np.where(n > 1e-12, n, 1.0), np.nan)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (w, x, y, z), w >= 0, of (N, 3, 3) rotation matrices."""
    r = np.asarray(r, dtype=float).reshape(-1, 3, 3)
    tr = np.trace(r, axis1=1, axis2=2)
    w = 0.5 * np.sqrt(np.clip(1 + tr, 0, None))
    x = 0.5 * np.sqrt(np.clip(1 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2], 0, None))
    y = 0.5 * np.sqrt(np.clip(1 - r[:, 0, 0] + r[:, 1, 1] - r[:, 2, 2], 0, None))
    z = 0.5 * np.sqrt(np.clip(1 - r[:, 0, 0] - r[:, 1, 1] + r[:, 2, 2], 0, None))
    x = np.copysign(x, r[:, 2, 1] - r[:, 1, 2])
    y = np.copysign(y, r[:, 0, 2] - r[:, 2, 0])
    z = np.copysign(z, r[:, 1, 0] - r[:, 0, 1])
    return np.stack([w, x, y, z], axis=1)


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(3, 3) rotation Rz(yaw) Ry(pitch) Rx(roll) [rad] (REP 103 fixed-axis roll, pitch, yaw)."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def matrix_to_rpy(r: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] of one (3, 3) rotation, inverse of :func:`rpy_to_matrix`."""
    r = np.asarray(r, dtype=float)
    return (
        float(np.arctan2(r[2, 1], r[2, 2])),
        float(np.arcsin(np.clip(-r[2, 0], -1, 1))),
        float(np.arctan2(r[1, 0], r[0, 0])),
    )


def matrix_yaw(r: np.ndarray) -> np.ndarray:
    """Heading [rad, CCW from world x] of the body x axis of (N, 3, 3) rotations R_w(body)."""
    r = np.asarray(r, dtype=float).reshape(-1, 3, 3)
    return np.arctan2(r[:, 1, 0], r[:, 0, 0])


def wrap(a: np.ndarray) -> np.ndarray:
    """Angles [rad] wrapped to [-pi, pi)."""
    return (np.asarray(a, dtype=float) + np.pi) % (2 * np.pi) - np.pi


def level_vehicle_accel(
    f_s: np.ndarray, r_ws: np.ndarray, r_bs: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gravity-free level acceleration in the vehicle frame from an IMU with orientation.

    Args:
        f_s: (N, 3) specific force [m/s^2] in the sensor frame (gravity included).
        r_ws: (N, 3, 3) sensor attitude in the world (the message's orientation).
        r_bs: (3, 3) mount, sensor -> base; ``None`` = identity (mount unknown).
    Returns:
        (ax, ay, yaw_b): level acceleration [m/s^2] along the vehicle's heading (x forward) and
        to its left (y), and the vehicle heading [rad] in the orientation's yaw reference.
        ax, ay do not depend on that reference: the acceleration and the heading are rotated by
        the same unknown offset, which cancels.
    """
    a_w = np.einsum("nij,nj->ni", r_ws, np.asarray(f_s, dtype=float))
    a_w[:, 2] -= G0
    r_wb = r_ws if r_bs is None else np.einsum("nij,kj->nik", r_ws, r_bs)
    yaw_b = matrix_yaw(r_wb)
    c, s = np.cos(yaw_b), np.sin(yaw_b)
    ax = c * a_w[:, 0] + s * a_w[:, 1]
    ay = -s * a_w[:, 0] + c * a_w[:, 1]
    return ax, ay, yaw_b


def world_yaw_rate(w_s: np.ndarray, r_ws: np.ndarray) -> np.ndarray:
    """Heading rate [rad/s]: the world-z (up) component of the sensor's angular velocity."""
    return np.einsum("nj,nj->n", r_ws[:, 2, :], np.asarray(w_s, dtype=float))


def tilt_deg(v: np.ndarray) -> float:
    """Angle [deg] between a 3-vector and +z."""
    v = np.asarray(v, dtype=float)
    return float(np.degrees(np.arccos(np.clip(v[2] / np.linalg.norm(v), -1.0, 1.0))))


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    if width <= 1:
        return x
    k = np.ones(width) / width
    if x.ndim == 1:
        return np.convolve(x, k, mode="same")
    return np.stack([np.convolve(x[:, j], k, mode="same") for j in range(x.shape[1])], axis=1)


class MountEstimate(TypedDict):
    """How :func:`estimate_mount` found the mount (see there)."""

    up_from: str
    forward_from: str
    forward_corr: float


def estimate_mount(
    t: np.ndarray,
    f_s: np.ndarray,
    speed_t: np.ndarray | None = None,
    speed_v: np.ndarray | None = None,
) -> tuple[np.ndarray, MountEstimate]:
    """Estimate the mount R_bs of an IMU without orientation from its data.

    Up: the mean specific force at standstill (speed < :data:`STANDSTILL_MPS`), or over the
    whole drive when no standstill is known. Forward: the horizontal specific force regressed
    on d(speed)/dt (both smoothed over 1 s on a 0.1 s grid): the direction whose component
    follows the longitudinal acceleration. Left = up x forward.

    Args:
        t: (N,) IMU times [s]; f_s: (N, 3) specific force [m/s^2], sensor frame.
        speed_t, speed_v: a speed [m/s] at times [s] (wheel or GPS-derived); None = unknown.
    Returns:
        (R_bs (3, 3), info) with info keys ``up_from`` ("standstill" | "whole drive"),
        ``forward_from`` ("d(speed)/dt" | "sensor x (no speed)"), ``forward_corr`` (correlation
        of the forward component with d(speed)/dt, NaN when not computed).
    """
    t = np.asarray(t, dtype=float)
    f_s = np.asarray(f_s, dtype=float)
    ok = np.all(np.isfinite(f_s), axis=1)
    t, f_s = t[ok], f_s[ok]
    info: MountEstimate = {
        "up_from": "whole drive",
        "forward_from": "sensor x (no speed)",
        "forward_corr": float("nan"),
    }
    # (times [s], speeds [m/s]) when known and long enough to use
    speed = (
        (speed_t, speed_v)
        if speed_t is not None and speed_v is not None and np.size(speed_t) > 3
        else None
    )
    still = np.zeros(t.size, dtype=bool)
    if speed is not None:
        v_at = np.interp(t, speed[0], speed[1], left=np.nan, right=np.nan)
        still = v_at < STANDSTILL_MPS
    if still.sum() >= 20:
        up = f_s[still].mean(axis=0)
        info["up_from"] = "standstill"
    else:
        up = f_s.mean(axis=0)
    up = up / np.linalg.norm(up)
    # initial forward: the sensor axis most nearly horizontal, made horizontal
    axes = np.eye(3)
    cand = axes[int(np.argmin(np.abs(axes @ up)))]
    fwd = cand - (cand @ up) * up
    fwd /= np.linalg.norm(fwd)
    if speed is not None:
        speed_t, speed_v = speed
        grid = np.arange(max(t[0], speed_t[0]), min(t[-1], speed_t[-1]), 0.1)
        if grid.size > 50:
            width = 10  # 1 s
            v = _smooth(np.interp(grid, speed_t, speed_v), width)
            dv = np.gradient(v, grid)
            f = _smooth(np.stack([np.interp(grid, t, f_s[:, j]) for j in range(3)], axis=1), width)
            h = f - np.outer(f @ up, up)
            h -= h.mean(axis=0)
            dv0 = dv - dv.mean()
            inner = slice(width, grid.size - width)
            h, dv0 = h[inner], dv0[inner]
            if np.sum(dv0 * dv0) > 1e-6:
                d = (h * dv0[:, None]).sum(axis=0) / np.sum(dv0 * dv0)
                d -= (d @ up) * up
                if np.linalg.norm(d) > 1e-9:
                    fwd = d / np.linalg.norm(d)
                    comp = h @ fwd
                    info["forward_corr"] = float(np.corrcoef(comp, dv0)[0, 1])
                    info["forward_from"] = "d(speed)/dt"
    left = np.cross(up, fwd)
    return np.stack([fwd, left, up]), info


def vehicle_from_mount(
    f_s: np.ndarray, w_s: np.ndarray | None, r_bs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(ax, ay, yaw_rate) in the vehicle frame for a level vehicle: f_b = R_bs f_s; gravity
    (on base z) does not enter x, y; yaw rate = base-z component of R_bs w_s [rad/s]."""
    f_b = np.asarray(f_s, dtype=float) @ np.asarray(r_bs).T
    yr = None if w_s is None else (np.asarray(w_s, dtype=float) @ np.asarray(r_bs).T)[:, 2]
    return f_b[:, 0], f_b[:, 1], yr


def gps_chords(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, chord_s: float = COURSE_CHORD_S
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chords from each fix to the first fix at least ``chord_s`` [s] later: (midpoint times
    [s], mean speed [m/s], course [rad, ENU]) - long enough for metre-level fix noise to
    average out."""
    t, x, y = (np.asarray(a, dtype=float) for a in (t, x, y))
    j = np.searchsorted(t, t + chord_s, side="left")
    i = np.flatnonzero(j < t.size)
    j = j[j < t.size]
    dx, dy, dt = x[j] - x[i], y[j] - y[i], t[j] - t[i]
    return 0.5 * (t[i] + t[j]), np.hypot(dx, dy) / dt, np.arctan2(dy, dx)


def gps_course(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    chord_s: float = COURSE_CHORD_S,
    min_disp_m: float = COURSE_MIN_DISPLACEMENT_M,
) -> tuple[np.ndarray, np.ndarray]:
    """(times [s], course [rad, ENU]) of the :func:`gps_chords` longer than ``min_disp_m``
    (moving: the fix noise adds only a few degrees); course of a chord = the heading at its
    middle for a constant-rate turn."""
    t, x, y = (np.asarray(a, dtype=float) for a in (t, x, y))
    j = np.searchsorted(t, t + chord_s, side="left")
    i = np.flatnonzero(j < t.size)
    j = j[j < t.size]
    dx, dy = x[j] - x[i], y[j] - y[i]
    moving = np.hypot(dx, dy) >= min_disp_m
    return 0.5 * (t[i] + t[j])[moving], np.arctan2(dy, dx)[moving]


def yaw_offset(
    yaw_t: np.ndarray, yaw: np.ndarray, course_t: np.ndarray, course: np.ndarray
) -> tuple[float, float, int]:
    """Offset [rad] to add to an IMU yaw to make it ENU, from the GPS course while moving.

    The circular mean of (course - yaw) over the course samples (yaw interpolated, unwrapped,
    at the course times), its circular standard deviation sqrt(-2 ln R) [rad] and the number
    of samples used. (NaN, NaN, 0) when there are none.
    """
    yaw_t = np.asarray(yaw_t, dtype=float)
    yaw = np.asarray(yaw, dtype=float)
    ok = np.isfinite(yaw)
    if ok.sum() < 2 or np.size(course_t) == 0:
        return float("nan"), float("nan"), 0
    yu = np.unwrap(yaw[ok])
    yi = np.interp(course_t, yaw_t[ok], yu, left=np.nan, right=np.nan)
    d = np.asarray(course, dtype=float) - yi
    d = d[np.isfinite(d)]
    off, spread = circular_offset(d)
    return off, spread, int(d.size)


def circular_offset(d: np.ndarray) -> tuple[float, float]:
    """Circular mean [rad, wrapped to (-pi, pi]] of the angle differences ``d`` [rad] and
    their circular standard deviation sqrt(-2 ln R) [rad], over the finite ones; NaNs
    when there are none."""
    d = np.asarray(d, dtype=float)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return float("nan"), float("nan")
    c, s = float(np.cos(d).mean()), float(np.sin(d).mean())
    r = min(float(np.hypot(c, s)), 1.0)
    return float(np.arctan2(s, c)), float(np.sqrt(-2.0 * np.log(r))) if r > 0 else float("inf")
