"""``bench latency``: per-call timing of predictors on one drive, one process, one thread.

Each predictor replays the drive once to warm up (imports, allocations, ONNX
session), then replays it again, repeating until at least ``steps`` fix steps
were timed; every call is timed with ``perf_counter_ns``. Figures are
percentiles in microseconds, never a single timing.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from bench.config import RunConfig
from bench.prepare import prepare_drive
from bench.replay import replay
from metrics.latency import latency_summary
from predictors.registry import create
from scenarios.drive import Drive

PAPER_MS = {"regression": 2.0, "lstm": 2.0, "kalman": 1.0, "step_total": (4.0, 6.0)}


def single_thread() -> None:
    """Pin BLAS / OpenMP pools to one thread (call before numpy-heavy work)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass


def time_predictor(name: str, drive: Drive, steps: int, options: dict[str, Any] | None = None
                   ) -> dict[str, Any]:
    """p50/p90/p99/max [us] of fix steps (observe_gps + future query) and between-fix queries."""
    cfg = RunConfig(predictors=(name,), gps_profile="rtk")
    prep = prepare_drive(drive, cfg)
    pred = create(name, **(options or {}))
    replay(pred, prep, cfg.horizon_s)  # warm-up
    step, query = [], []
    n = 0
    while n < steps:
        r = replay(pred, prep, cfg.horizon_s)
        step.append(r.step_ns)
        query.append(r.query_ns)
        n += r.step_ns.size
    return {"step_us": latency_summary(np.concatenate(step)[:steps]),
            "query_us": latency_summary(np.concatenate(query))}


def _stage_times(p: Any, clock: Any) -> tuple[int, int, int, int, int] | None:
    """Time one fix step of an LstmPredictor stage by stage (mirrors its ``_step_on_fixes``).
    Returns ns for (position fit, IMU fit, features, inference, current-position fit)."""
    import math

    from predictors.lstm.features import features_one
    from predictors.lstm.resample import (
        GRID_OFFSETS,
        MIN_SPAN_S,
        N_STEPS,
        eval_poly,
        fit_poly,
        window_start,
    )

    a = p._fix.view()
    end = a.shape[0] - 1
    t = a[:, 0]
    c0 = clock()
    start = window_start(t, end)
    t_end = float(t[end])
    if t_end - t[start] < MIN_SPAN_S:
        return None
    tt = t[start:end + 1]
    scale = t_end - float(tt[0])
    coef = fit_poly(tt, a[start:end + 1, 1:], t_end, scale)
    grid = eval_poly(coef, GRID_OFFSETS / scale)
    psi = math.atan2(coef[1, 1], coef[1, 0])
    c1 = clock()
    ax, ay, yaw = p._imu_on_grid(float(tt[0]), t_end, coef, scale)
    c2 = clock()
    x = features_one(grid, ax, ay, yaw, psi, p.frame, p._x)
    c3 = clock()
    out = p.net.run(x)
    c4 = clock()
    pts = p._pts
    pts[:N_STEPS] = grid
    pts[N_STEPS] = grid[-1] + out[:2]
    p._final.fit(pts)
    c5 = clock()
    return c1 - c0, c2 - c1, c3 - c2, c4 - c3, c5 - c4


def lstm_stages(drive: Drive, steps: int) -> dict[str, Any]:
    """Per-stage latency [us] of the ``lstm`` fix step on a drive's real windows, plus the
    paper's iterative (L-BFGS) fit and the closed-form fit alone for comparison."""
    from time import perf_counter_ns

    from bench.replay import GPS, IMU, SPEED, build_events
    from predictors.lstm.predictor import LstmPredictor
    from predictors.lstm.resample import fit_poly, window_start

    prep = prepare_drive(drive, RunConfig(predictors=("lstm",)))
    kinds, idxs = build_events(prep)
    p = LstmPredictor()
    names = ("resample_positions", "resample_imu", "features", "inference", "current_position_fit")
    rec: dict[str, list[int]] = {n: [] for n in names}
    fit_alone: list[int] = []
    lbfgs: list[int] = []
    g, imu, sp = prep.gps, drive.imu, drive.speed
    nan = float("nan")
    while len(rec["inference"]) < steps:
        p.reset()
        for k, i in zip(kinds.tolist(), idxs.tolist(), strict=True):
            if k == IMU:
                p.observe_imu(imu.t[i], imu.ax[i], imu.ay[i],
                              imu.yaw[i] if imu.yaw is not None else nan,
                              imu.yaw_rate[i] if imu.yaw_rate is not None else nan)
            elif k == SPEED:
                p.observe_speed(sp.t[i], sp.v[i])
            elif k == GPS:
                p.observe_gps(g.t[i], g.x[i], g.y[i])
                r = _stage_times(p, perf_counter_ns)
                if r is None:
                    continue
                for n, v in zip(names, r, strict=True):
                    rec[n].append(v)
                a = p._fix.view()
                s = window_start(a[:, 0], a.shape[0] - 1)
                tt, xy = a[s:, 0], a[s:, 1:]
                c0 = perf_counter_ns()
                fit_poly(tt, xy, float(tt[-1]), float(tt[-1] - tt[0]))
                fit_alone.append(perf_counter_ns() - c0)
                if len(lbfgs) < 200:
                    from predictors.cubic import fit_cubic_lbfgs

                    c0 = perf_counter_ns()
                    fit_cubic_lbfgs(tt, xy)
                    lbfgs.append(perf_counter_ns() - c0)
    out = {n: latency_summary(np.asarray(v[:steps])) for n, v in rec.items()}
    out["cubic_fit_closed_form"] = latency_summary(np.asarray(fit_alone[:steps]))
    out["cubic_fit_lbfgs"] = latency_summary(np.asarray(lbfgs))
    return out


def batch_throughput(batches: tuple[int, ...] = (1, 64, 1024), seconds: float = 1.0
                     ) -> dict[str, Any]:
    """Windows per second of the bundled network through onnxruntime at several batch sizes."""
    from time import perf_counter

    from predictors.lstm.predictor import LstmPredictor

    net = LstmPredictor().net
    rng = np.random.default_rng(0)
    out: dict[str, Any] = {}
    for b in batches:
        X = rng.standard_normal((b, 8, 6)).astype(np.float32)
        net.run_batch(X)
        n = 0
        t0 = perf_counter()
        while perf_counter() - t0 < seconds:
            net.run_batch(X)
            n += 1
        dt = perf_counter() - t0
        out[str(b)] = {"windows_per_s": n * b / dt, "us_per_window": dt / (n * b) * 1e6}
    return out
