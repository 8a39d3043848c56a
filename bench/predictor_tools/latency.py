"""``bench latency``: per-call timing of predictors on one drive, one process, one thread.

Each predictor replays the drive once to warm up (imports, allocations, ONNX
session), then replays it again, repeating until at least ``steps`` fix steps
were timed; every call is timed with ``perf_counter_ns``. Figures are
percentiles in microseconds, never a single timing, and each predictor's step as a ratio
to constant velocity's step timed in the same run (:func:`ratios_to_cv`): absolute times
differ by machine, ratios far less, so the CI latency budgets are ratios
(tests/project/latency_budgets.json).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

from posbench.config import RunConfig
from posbench.metrics.latency import latency_summary
from posbench.predictors.registry import create
from posbench.replay.loop import replay
from posbench.replay.prepare import prepare_drive
from posbench.scenarios.drive import Drive

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


def time_predictor(
    name: str, drive: Drive, steps: int, options: dict[str, Any] | None = None
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
    return {
        "step_us": latency_summary(np.concatenate(step)[:steps]),
        "query_us": latency_summary(np.concatenate(query)),
    }


def time_predictors(
    names: list[str],
    drive: Drive,
    steps: int,
    options: dict[str, dict[str, Any]] | None = None,
    rounds: int = 1,
    on_timing: Callable[[str, int], object] | None = None,
) -> dict[str, dict[str, Any]]:
    """:func:`time_predictor` for each name; with ``rounds`` > 1 the predictors are timed in
    turn that many times and each percentile is the lowest of its rounds, so that a burst
    of load from another process, which hits one round, does not decide a figure. Each
    predictor's ``step_p50_rounds`` lists its rounds' step p50 [us] in order, which
    :func:`ratios_to_cv` pairs with cv's of the same round. ``on_timing(name, round)``
    (rounds from 1) is called before each timing (a progress line)."""
    out: dict[str, dict[str, Any]] = {}
    for round_no in range(1, rounds + 1):
        for n in names:
            if on_timing is not None:
                on_timing(n, round_no)
            r = time_predictor(n, drive, steps, (options or {}).get(n))
            if n not in out:
                out[n] = {**r, "step_p50_rounds": [r["step_us"]["p50"]]}
                continue
            out[n]["step_p50_rounds"].append(r["step_us"]["p50"])
            for kind in ("step_us", "query_us"):
                best = out[n][kind]
                for k in ("p50", "p90", "p99", "max", "mean"):
                    best[k] = min(best[k], r[kind][k])
    return out


def ratios_to_cv(results: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Per timed predictor: its step p50 and p99 over cv's step p50 of the same run, and its
    own p99 over p50 (a spread); {} when cv was not timed.

    Timed in several rounds (:func:`time_predictors`), the p50 ratio is the median of the
    rounds' ratios, each round's p50 over cv's p50 of that round (timed just before it): a
    round in which cv ran unusually fast, or the predictor unusually slow, does not decide
    it, as it could when the lowest p50 of each was divided (kf 4.2x cv once in CI; the
    rounds' median read the same code at 3.0-3.6x in 8 processes on the development machine)."""
    cv_result = results.get("cv", {})
    cv = cv_result.get("step_us", {}).get("p50")
    if not cv:
        return {}
    cv_rounds = cv_result.get("step_p50_rounds") or []
    out = {}
    for name, r in results.items():
        step = r.get("step_us") if isinstance(r, dict) else None
        if not step or "p50" not in step or name.startswith("lstm_"):
            continue
        own_rounds = r.get("step_p50_rounds") or []
        if len(cv_rounds) > 1 and len(own_rounds) == len(cv_rounds):
            p50_ratio = float(np.median(np.divide(own_rounds, cv_rounds)))
        else:
            p50_ratio = step["p50"] / cv
        out[name] = {
            "step_p50": p50_ratio,
            "step_p99": step["p99"] / cv,
            "p99_over_p50": step["p99"] / step["p50"],
        }
    return out


def lstm_stages(drive: Drive, steps: int) -> dict[str, Any]:
    """Per-stage latency [us] of the *staged* ``lstm`` fix step (the readable reference,
    ``step="staged"``) on a drive's real windows, plus the paper's iterative (L-BFGS) fit
    and the closed-form fit alone for comparison.

    The stages are those the predictor reports through its ``stage_timer`` hook
    (:data:`posbench.predictors.lstm.predictor.STAGES`), so the code timed is the code that runs;
    start-up line fits (no network) report none. After each step the hook also times the
    position cubic alone on that step's window of fixes (the first 200 by L-BFGS too),
    interleaved with the steps as before; the hook's own time is charged to no stage."""
    from time import perf_counter_ns

    from posbench.predictors.cubic import fit_cubic_lbfgs
    from posbench.predictors.lstm.resample import fit_poly, window_start

    clock = perf_counter_ns
    cfg = RunConfig(predictors=("lstm",))
    prep = prepare_drive(drive, cfg)
    t, xy = prep.gps.t, np.column_stack([prep.gps.x, prep.gps.y])
    fit_alone: list[int] = []
    lbfgs: list[int] = []

    def after_step(p: Any) -> None:
        step = p.last_step()
        end = int(np.searchsorted(t, step.t_fix))  # the fix this step ran on
        i = window_start(t, end)
        tt, w = t[i : end + 1], xy[i : end + 1]
        c0 = clock()
        fit_poly(tt, w, float(tt[-1]), float(tt[-1] - tt[0]))
        fit_alone.append(clock() - c0)
        if len(lbfgs) < 200:
            c0 = clock()
            fit_cubic_lbfgs(tt, w)
            lbfgs.append(clock() - c0)

    out = _stage_times(prep, cfg.horizon_s, steps, "staged", after_step)
    out["cubic_fit_closed_form"] = latency_summary(np.asarray(fit_alone[:steps]))
    out["cubic_fit_lbfgs"] = latency_summary(np.asarray(lbfgs))
    return out


def lstm_fused_stages(drive: Drive, steps: int) -> dict[str, Any]:
    """Per-stage latency [us] of the default, *fused* ``lstm`` fix step
    (:data:`posbench.predictors.lstm.predictor.FUSED_STAGES`: ``resample`` = fix bookkeeping and
    both cubics in one solve, ``features``, ``inference``, ``current_position_fit``), timed
    through the same ``stage_timer`` hook during a normal replay."""
    cfg = RunConfig(predictors=("lstm",))
    return _stage_times(prepare_drive(drive, cfg), cfg.horizon_s, steps, "fused")


def _stage_times(
    prep: Any,
    horizon_s: float,
    steps: int,
    step: str,
    after_step: Callable[[Any], None] | None = None,
) -> dict[str, Any]:
    """Replay ``prep`` through ``LstmPredictor(step=step)`` with a stage hook until ``steps``
    network steps were timed; percentiles [us] per stage, in the predictor's stage order.
    ``after_step(predictor)`` runs after each step's last stage (outside every stage)."""
    from posbench.predictors.lstm.predictor import LstmPredictor, StageRecorder

    p = LstmPredictor(step=step)  # type: ignore[arg-type]  # checked by the caller's --step
    stages = p.stages
    rec = StageRecorder()
    count = rec.ns.setdefault("inference", [])

    def hook(stage: str, ns: int) -> None:
        rec(stage, ns)
        if stage == stages[-1] and after_step is not None:
            after_step(p)

    p.stage_timer = hook
    while len(count) < steps:
        before = len(count)
        replay(p, prep, horizon_s)
        if len(count) == before:  # no window of fixes spans 2 s: nothing to time
            break
    return {n: latency_summary(np.asarray(rec.ns.get(n, [])[:steps])) for n in stages}


def batch_throughput(
    batches: tuple[int, ...] = (1, 64, 1024), seconds: float = 1.0
) -> dict[str, Any]:
    """Windows per second of the bundled network through onnxruntime at several batch sizes."""
    from time import perf_counter

    from posbench.predictors.lstm.predictor import LstmPredictor

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
