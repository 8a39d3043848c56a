"""Along-track and cross-track errors: an answer's error in the reference's heading frame.

Pure numpy, imports nothing of posbench. Frames: positions are (N, 2) arrays in a local
ENU frame [m] (x east, y north). The reference's heading is its direction of travel,
taken from the reference track itself (three reference positions around the query time,
:func:`reference_motion`), as an angle [rad] counter-clockwise from east.

Sign conventions (vehicle frame, REP 103: x forward, y left):

- ``along`` [m]: component of ``answer - reference`` along the heading; positive = the
  answer is ahead of the reference along its direction of travel, negative = it lags.
- ``cross`` [m]: component to the left of the heading; positive = left of the reference's
  direction of travel, negative = right.
- ``inward`` [m]: ``cross`` signed by the turn direction (:func:`inward_cross`); positive =
  toward the inside of the turn (the turn centre; a predictor that cuts the corner),
  negative = outside (one that overshoots or runs wide). Defined only while the reference
  turns at least :data:`TURN_RATE_RAD_S`; NaN otherwise.

At standstill (reference speed below :data:`STANDSTILL_MPS`) there is no direction of
travel: heading, along and cross are NaN; such queries are counted (``standstill``) and
left out of the along/cross summaries, never averaged as zero.
"""

from __future__ import annotations

import numpy as np

#: below this reference speed [m/s] the heading is undefined (NaN): standstill
STANDSTILL_MPS = 0.5
#: the reference turns when its yaw rate is at least this [rad/s] (about 2.9 deg/s: a
#: 50 m radius at 10 km/h, a 280 m radius at 50 km/h)
TURN_RATE_RAD_S = 0.05
#: half the time between the reference positions the heading is taken from [s]
HEADING_DT_S = 0.1

TRACK_SUMMARY_KEYS = (
    "count",
    "standstill",
    "along_mean_m",
    "along_p95_abs_m",
    "cross_mean_m",
    "cross_p95_abs_m",
    "turning",
    "inward_mean_m",
)

#: what each figure means (a report's glossary may collect these)
DEFINITIONS = {
    "along-track": "component [m] of answer - reference along the reference's direction of "
    "travel: positive = ahead, negative = lagging behind.",
    "cross-track": "component [m] of answer - reference to the left of the reference's "
    "direction of travel (ENU): positive = left, negative = right.",
    "inward": f"cross-track [m] signed by the turn direction while the reference turns at "
    f">= {TURN_RATE_RAD_S:g} rad/s: positive = toward the inside of the turn "
    f"(cutting the corner), negative = outside (running wide).",
    "standstill": f"queries whose reference moves slower than {STANDSTILL_MPS:g} m/s: no "
    f"direction of travel, no along/cross-track error (counted, not averaged).",
}


def reference_motion(
    before_xy: np.ndarray,
    at_xy: np.ndarray,
    after_xy: np.ndarray,
    dt_s: float = HEADING_DT_S,
    min_speed_mps: float = STANDSTILL_MPS,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heading, speed and yaw rate of a reference track from its positions at t - dt, t, t + dt.

    Args:
        before_xy, at_xy, after_xy: (N, 2) reference positions [m, ENU] at t - dt, t, t + dt
            (NaN where unknown).
        dt_s: the time step dt [s].
        min_speed_mps: below this speed the heading is NaN (standstill).

    Returns:
        heading [rad] (direction of travel, counter-clockwise from east; NaN at standstill
        or when the track is unknown), speed [m/s] (central difference, one-sided where one
        neighbour is unknown; NaN where both are) and yaw rate [rad/s] (change of direction
        between the two half-steps, positive = turning left; NaN unless all three positions
        are known and the track moves).
    """
    b, a, f = (np.asarray(p, dtype=float).reshape(-1, 2) for p in (before_xy, at_xy, after_xy))
    central = (f - b) / (2.0 * dt_s)
    forward = (f - a) / dt_s
    backward = (a - b) / dt_s
    ok_c = np.all(np.isfinite(central), axis=1)
    v = np.where(
        ok_c[:, None],
        central,
        np.where(np.all(np.isfinite(forward), axis=1)[:, None], forward, backward),
    )
    speed = np.hypot(v[:, 0], v[:, 1])
    moving = speed >= min_speed_mps  # False for NaN
    heading = np.where(moving, np.arctan2(v[:, 1], v[:, 0]), np.nan)
    d1, d2 = a - b, f - a
    turn = np.arctan2(
        d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0], d1[:, 0] * d2[:, 0] + d1[:, 1] * d2[:, 1]
    )  # signed angle d1 -> d2
    yaw_rate = np.where(moving & ok_c, turn / dt_s, np.nan)
    return heading, speed, yaw_rate


def track_errors(
    answer_xy: np.ndarray, ref_xy: np.ndarray, heading_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Along-track and cross-track errors [m] of (N, 2) answers against (N, 2) references
    [m, ENU] whose direction of travel is ``heading_rad`` [rad, counter-clockwise from east].

    along = d . (cos h, sin h), cross = d . (-sin h, cos h) with d = answer - reference, so
    along**2 + cross**2 = |d|**2. NaN where the answer, the reference or the heading is.
    """
    d = np.asarray(answer_xy, dtype=float).reshape(-1, 2) - np.asarray(ref_xy, dtype=float).reshape(
        -1, 2
    )
    h = np.asarray(heading_rad, dtype=float).ravel()
    c, s = np.cos(h), np.sin(h)
    return d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c


def inward_cross(
    cross_m: np.ndarray, yaw_rate_rad_s: np.ndarray, min_rate_rad_s: float = TURN_RATE_RAD_S
) -> np.ndarray:
    """Cross-track error [m] signed by the turn: positive toward the inside of the turn.

    In a left turn (yaw rate > 0) the inside is left, so inward = cross; in a right turn
    inward = -cross. NaN where the reference turns slower than ``min_rate_rad_s`` [rad/s]
    (or its yaw rate is unknown).
    """
    c = np.asarray(cross_m, dtype=float)
    r = np.asarray(yaw_rate_rad_s, dtype=float)
    turning = np.abs(r) >= min_rate_rad_s  # False for NaN
    return np.where(turning, c * np.sign(r), np.nan)


def track_summary(
    along_m: np.ndarray, cross_m: np.ndarray, inward_m: np.ndarray, error_m: np.ndarray
) -> dict[str, float | int]:
    """Summary of along/cross-track errors [m] over one group of queries.

    ``count``: queries with a finite along/cross error; ``standstill``: queries with a
    finite Euclidean ``error_m`` but no along/cross error (reference at standstill, heading
    unknown); ``along_mean_m`` (signed: < 0 lags), ``along_p95_abs_m`` (p95 of |along|),
    ``cross_mean_m`` (signed, + = left: a side bias), ``cross_p95_abs_m`` (p95 of |cross|),
    ``turning``: queries with a finite inward error; ``inward_mean_m`` (+ = cuts corners).
    Percentiles by linear interpolation; NaN figures where their count is 0.
    """
    a = np.asarray(along_m, dtype=float).ravel()
    c = np.asarray(cross_m, dtype=float).ravel()
    i = np.asarray(inward_m, dtype=float).ravel()
    e = np.asarray(error_m, dtype=float).ravel()
    ok = np.isfinite(a) & np.isfinite(c)
    ok_i = np.isfinite(i)
    av, cv = a[ok], c[ok]
    nan = float("nan")
    return {
        "count": int(ok.sum()),
        "standstill": int((np.isfinite(e) & ~ok).sum()),
        "along_mean_m": float(av.mean()) if av.size else nan,
        "along_p95_abs_m": float(np.percentile(np.abs(av), 95)) if av.size else nan,
        "cross_mean_m": float(cv.mean()) if cv.size else nan,
        "cross_p95_abs_m": float(np.percentile(np.abs(cv), 95)) if cv.size else nan,
        "turning": int(ok_i.sum()),
        "inward_mean_m": float(i[ok_i].mean()) if ok_i.any() else nan,
    }
