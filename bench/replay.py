"""Replay one prepared drive through one predictor, exactly as a vehicle would see it.

All observations (GPS fixes fed, IMU, speed) and the "now" queries are merged
into one time-ordered event list; at equal times observations come before the
query. A "future" query is asked right after its fix is observed, so the
predictor never holds an observation stamped after the time it is asked about.
Every fix step (``observe_gps`` + the future query) and every "now" query is
timed with ``perf_counter_ns``.
"""

from __future__ import annotations

from dataclasses import dataclass
from time import perf_counter_ns

import numpy as np

from bench.prepare import PreparedDrive
from predictors.base import Predictor

GPS, IMU, SPEED, QUERY = 0, 1, 2, 3


@dataclass
class ReplayResult:
    """Predicted positions [m] for each query, and call durations [ns]."""

    future_xy: np.ndarray  # (n_fixes, 2)
    now_xy: np.ndarray  # (n_now, 2)
    step_ns: np.ndarray  # per fix: observe_gps + future position_at
    query_ns: np.ndarray  # per now query


def build_events(prep: PreparedDrive) -> tuple[np.ndarray, np.ndarray]:
    """(kind, index) arrays of all events in replay order."""
    d = prep.drive
    parts_t = [prep.gps.t]
    parts_k = [np.full(len(prep.gps), GPS)]
    if d.imu is not None:
        parts_t.append(d.imu.t)
        parts_k.append(np.full(len(d.imu), IMU))
    if d.speed is not None:
        parts_t.append(d.speed.t)
        parts_k.append(np.full(len(d.speed), SPEED))
    parts_t.append(prep.now.t_issue)
    parts_k.append(np.full(prep.now.t_issue.size, QUERY))
    t = np.concatenate(parts_t)
    k = np.concatenate(parts_k)
    idx = np.concatenate([np.arange(p.size) for p in parts_t])
    order = np.lexsort((k, t))
    return k[order], idx[order]


def replay(predictor: Predictor, prep: PreparedDrive, horizon_s: float) -> ReplayResult:
    """Feed every event to ``predictor`` in order; collect its answers and timings."""
    d = prep.drive
    kinds, idxs = build_events(prep)
    gt, gx, gy = prep.gps.t.tolist(), prep.gps.x.tolist(), prep.gps.y.tolist()
    if d.imu is not None:
        n = len(d.imu)
        nan = [float("nan")] * n
        it, iax, iay = d.imu.t.tolist(), d.imu.ax.tolist(), d.imu.ay.tolist()
        iyaw = d.imu.yaw.tolist() if d.imu.yaw is not None else nan
        irate = d.imu.yaw_rate.tolist() if d.imu.yaw_rate is not None else nan
    if d.speed is not None:
        st, sv = d.speed.t.tolist(), d.speed.v.tolist()
    qt = prep.now.t_query.tolist()

    future = np.full((len(gt), 2), np.nan)
    now = np.full((len(qt), 2), np.nan)
    step_ns = np.zeros(len(gt), dtype=np.int64)
    query_ns = np.zeros(len(qt), dtype=np.int64)
    clock = perf_counter_ns
    observe_gps, observe_imu = predictor.observe_gps, predictor.observe_imu
    observe_speed, position_at = predictor.observe_speed, predictor.position_at
    predictor.reset()
    for k, i in zip(kinds.tolist(), idxs.tolist(), strict=True):
        if k == IMU:
            observe_imu(it[i], iax[i], iay[i], iyaw[i], irate[i])
        elif k == GPS:
            t = gt[i]
            c0 = clock()
            observe_gps(t, gx[i], gy[i])
            p = position_at(t + horizon_s)
            step_ns[i] = clock() - c0
            future[i] = p
        elif k == SPEED:
            observe_speed(st[i], sv[i])
        else:
            c0 = clock()
            p = position_at(qt[i])
            query_ns[i] = clock() - c0
            now[i] = p
    return ReplayResult(future, now, step_ns, query_ns)
