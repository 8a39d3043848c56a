"""The contract's inputs, built once per process and deterministic: the first 52 s of the
first built-in synthetic drive with its own fixes, a straight line and a standstill, each
prepared as ``bench run`` prepares a drive; and what the clauses need to cut them.

Units: seconds, metres (local ENU)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from posbench.config import RunConfig
from posbench.predictors.base import Predictor
from posbench.replay.prepare import PreparedDrive, Queries, prepare_drive
from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, ImuStream, SpeedStream

#: "future" query horizon after each fix [s] (the paper's 0.2 s)
HORIZON_S = 0.2
#: length of the synthetic drive window [s]: straight, turn, roundabout, straight, a stop
DRIVE_S = 52.0
#: two answers closer than this [m] are the same answer
SAME_M = 1e-9
#: straight line: speed [m/s], heading [rad, ENU], largest error allowed [m]
LINE_SPEED = 15.0
LINE_HEADING = 0.5
LINE_BOUND_M = 0.5
#: standstill: largest distance [m] an answer may drift from where the car stands
STAND_BOUND_M = 0.1
#: answers issued in the first this many seconds after the first fix are warm-up [s]
WARMUP_S = 2.0
#: where the car of the line / standstill drives is at t = 0 [m]
START_XY = (120.0, -40.0)
#: eigenvalues of a reported covariance may be this negative [m^2] (rounding)
PSD_TOL = 1e-9
Factory = Callable[[], Predictor]


# ---------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class Inputs:
    """The prepared drives every check replays (see the module doc)."""

    drive: PreparedDrive
    line: PreparedDrive
    stand: PreparedDrive
    line_first_fix_s: float


def _steady_drive(
    name: str, speed: float, duration_s: float = 10.0, first_fix_s: float = 1.0
) -> Drive:
    """A car at constant ``speed`` [m/s] on heading :data:`LINE_HEADING` from
    :data:`START_XY`: IMU (50 Hz) and speed (50 Hz, 10 ms later) from t = 0, exact fixes
    at 5 Hz from ``first_fix_s``."""
    c, s = math.cos(LINE_HEADING), math.sin(LINE_HEADING)
    t_imu = np.arange(0.0, duration_s, 0.02)
    t_spd = t_imu + 0.01
    t_fix = first_fix_s + 0.2 * np.arange(int(round((duration_s - first_fix_s) / 0.2)))
    zero = np.zeros_like(t_imu)
    return Drive(
        DriveMeta(name, "contract", "contract", projection="source"),
        GpsStream(t_fix, START_XY[0] + speed * c * t_fix, START_XY[1] + speed * s * t_fix),
        ImuStream(t_imu, zero, zero, np.full_like(t_imu, LINE_HEADING), zero),
        SpeedStream(t_spd, np.full_like(t_spd, speed)),
    )


def line_position(t: np.ndarray) -> np.ndarray:
    """Where the straight-line car is at times ``t`` [s]: (N, 2) [m]."""
    c, s = math.cos(LINE_HEADING), math.sin(LINE_HEADING)
    t = np.asarray(t, dtype=float)
    return np.stack([START_XY[0] + LINE_SPEED * c * t, START_XY[1] + LINE_SPEED * s * t], axis=1)


@lru_cache(maxsize=1)
def inputs() -> Inputs:
    """The check's drives, prepared as ``bench run`` prepares them (the drives' own fixes,
    no dropouts added). Built once per process."""
    from posbench.scenarios.synthetic import default_drives

    cfg = RunConfig(predictors=(), horizon_s=HORIZON_S, gps_profile="native", gate=False)
    drive = default_drives()[0].window(0.0, DRIVE_S)
    line = _steady_drive("contract-line", LINE_SPEED)
    stand = _steady_drive("contract-standstill", 0.0)
    return Inputs(
        prepare_drive(drive, cfg),
        prepare_drive(line, cfg),
        prepare_drive(stand, cfg),
        float(line.gps.t[0]),
    )


def _cut_queries(q: Queries, keep: np.ndarray) -> Queries:
    return Queries(
        q.t_issue[keep],
        q.t_query[keep],
        q.ref_xy[keep],
        q.speed_mps[keep],
        q.label[keep],
        q.since_fix_s[keep],
        None if q.heading_rad is None else q.heading_rad[keep],
        None if q.yaw_rate is None else q.yaw_rate[keep],
    )


def cut_prepared(prep: PreparedDrive, t_cut: float) -> PreparedDrive:
    """``prep`` with every observation stamped after ``t_cut`` [s] withheld, and the queries
    issued after it: its replay is the first part of ``prep``'s, event for event."""
    gps = prep.gps.take(prep.gps.t <= t_cut)
    drive = prep.drive.window(-math.inf, t_cut)
    return replace(
        prep,
        drive=drive,
        gps=gps,
        future=_cut_queries(prep.future, prep.future.t_issue <= t_cut),
        now=_cut_queries(prep.now, prep.now.t_issue <= t_cut),
    )


def last_observation_s(prep: PreparedDrive) -> float:
    """The stamp [s] of the newest observation (fix, IMU or speed sample) in ``prep``."""
    d = prep.drive
    ends = [s.t[-1] for s in (prep.gps, d.imu, d.speed) if s is not None and len(s)]
    return float(max(ends))
