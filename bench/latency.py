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


def lstm_stages(drive: Drive, steps: int) -> dict[str, Any]:
    """Per-stage latency [us] of the ``lstm`` fix step on a drive's real windows, plus the
    paper's iterative (L-BFGS) fit and the closed-form fit alone for comparison.

    The predictor's own stage methods are wrapped with timers on this one instance, so the
    code timed is the code that runs: IMU fit (``_imu_on_grid``), features (``_displacement``
    less inference), inference (``net.run``), current-position fit (``_final.fit``); the
    position fit is the rest of the step (window search, fit, grid, heading)."""
    from time import perf_counter_ns

    from predictors.cubic import fit_cubic_lbfgs
    from predictors.lstm.predictor import LstmPredictor
    from predictors.lstm.resample import fit_poly, window_start

    clock = perf_counter_ns
    prep = prepare_drive(drive, RunConfig(predictors=("lstm",)))
    p = LstmPredictor()
    spent: dict[str, int] = {}

    def timed(key: str, fn: Any) -> Any:
        def wrapper(*args: Any) -> Any:
            c0 = clock()
            out = fn(*args)
            spent[key] = spent.get(key, 0) + clock() - c0
            return out
        return wrapper

    p._imu_on_grid = timed("imu", p._imu_on_grid)
    p._displacement = timed("displacement", p._displacement)
    p.net.run = timed("inference", p.net.run)
    p._final.fit = timed("final", p._final.fit)
    names = ("resample_positions", "resample_imu", "features", "inference", "current_position_fit")
    rec: dict[str, list[int]] = {n: [] for n in names}
    fit_alone: list[int] = []
    lbfgs: list[int] = []
    step = p.observe_gps

    def observe_gps(t: float, x: float, y: float) -> None:
        spent.clear()
        c0 = clock()
        step(t, x, y)
        total = clock() - c0
        if "inference" not in spent:  # start-up line fit: no network step to time
            return
        rec["resample_positions"].append(
            total - spent["imu"] - spent["displacement"] - spent["final"])
        rec["resample_imu"].append(spent["imu"])
        rec["features"].append(spent["displacement"] - spent["inference"])
        rec["inference"].append(spent["inference"])
        rec["current_position_fit"].append(spent["final"])
        a = p._fix.view()
        i = window_start(a[:, 0], a.shape[0] - 1)
        tt, xy = a[i:, 0], a[i:, 1:]
        c0 = clock()
        fit_poly(tt, xy, float(tt[-1]), float(tt[-1] - tt[0]))
        fit_alone.append(clock() - c0)
        if len(lbfgs) < 200:
            c0 = clock()
            fit_cubic_lbfgs(tt, xy)
            lbfgs.append(clock() - c0)

    p.observe_gps = observe_gps
    while len(rec["inference"]) < steps:
        replay(p, prep, RunConfig().horizon_s)
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
