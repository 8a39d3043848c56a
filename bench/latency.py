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
