"""``bench latency``: per-call latency percentiles (:mod:`posbench.predictor_tools.latency`)."""

from __future__ import annotations

import json
from typing import Annotated, Any

import typer

from posbench.checks import check_at_least, check_data_paths, parse_pairs, parse_predictor_names
from posbench.cli.options import (
    ConfigOpt,
    DataOpt,
    ModelOpt,
    QuietOpt,
    VerboseOpt,
    predictors_option,
)
from posbench.cli.terminal import console, print_table, reporter
from posbench.config import DEFAULT_PREDICTORS
from posbench.errors import UsageError
from posbench.replay.predictor_options import model_options
from posbench.replay.predictor_setup import validate_predictors

#: the predictors timed by default: those of `bench run`, and hybrid (the CI latency gate
#: times it too)
DEFAULT_TIMED = (*DEFAULT_PREDICTORS, "hybrid")


def latency(
    predictors: Annotated[
        list[str] | None,
        predictors_option("those of `bench run` and hybrid (which the CI latency gate times)"),
    ] = None,
    steps: Annotated[
        int, typer.Option(help="Fix steps to time per predictor (after warm-up).")
    ] = 2000,
    rounds: Annotated[
        int,
        typer.Option(
            help="Time the predictors in turn this many times: each percentile is the lowest "
            "of its rounds, each ratio to cv the median of the rounds' ratios (each over cv "
            "timed in the same round), so that a slow or fast stretch of the machine does "
            "not decide a figure."
        ),
    ] = 5,
    data: DataOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")] = False,
    model: ModelOpt = None,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """Per-call latency percentiles (us) in one process and thread, each predictor's step as a
    ratio to constant velocity's (timed in the same run: ratios carry across machines; with
    --rounds, the median of the rounds' ratios, each over cv timed in the same round), the
    lstm's stages and batch throughput, beside the paper's figures (2 ms fit + 2 ms LSTM,
    4-6 ms per step)."""
    # every option is checked before a drive is loaded or a predictor timed
    check_at_least(steps, 1, "--steps")
    check_at_least(rounds, 1, "--rounds")
    check_data_paths(data)
    names = list(parse_predictor_names(predictors or DEFAULT_TIMED))
    if "cv" not in names:  # the yardstick of the ratios
        names.insert(0, "cv")
    options = model_options(parse_pairs(model, "--model"))
    validate_predictors(names, options)
    from posbench.pipeline.drives import load_drives
    from posbench.predictor_tools.latency import (
        PAPER_MS,
        batch_throughput,
        lstm_fused_stages,
        lstm_stages,
        ratios_to_cv,
        single_thread,
        time_predictors,
    )
    from posbench.predictors.registry import available

    single_thread()
    unknown = [n for n in names if n not in available()]
    if unknown:
        raise UsageError(f"unknown predictor(s) {', '.join(unknown)}")
    drives = load_drives(data, "enu", None, reporter=reporter())
    drive = max(drives, key=lambda d: len(d.gps))
    res: dict[str, Any] = {}
    with reporter().phase("timing...") as status:
        res.update(
            time_predictors(
                names,
                drive,
                steps,
                options,
                rounds,
                on_timing=lambda n, k: status(f"timing {n} on {drive.name}, round {k}/{rounds}..."),
            )
        )
        if "lstm" in names:
            status("timing lstm stages...")
            res["lstm_stages"] = lstm_stages(drive, steps)
            res["lstm_fused_stages"] = lstm_fused_stages(drive, steps)
            status("timing batch throughput...")
            res["batch"] = batch_throughput()
    res["ratio_to_cv"] = ratios_to_cv(res)
    res["drive"] = drive.name
    res["paper_ms"] = PAPER_MS
    if as_json:
        print(json.dumps(res, indent=2))
        return
    paper = {"lstm": "4000-6000 (step)", "kf-paper": "1000 (Kalman)"}
    rows = []
    for n in names:
        s, q = res[n]["step_us"], res[n]["query_us"]
        ratio = res["ratio_to_cv"].get(n, {})
        rows.append(
            [
                n,
                f"{s['p50']:.1f}",
                f"{s['p90']:.1f}",
                f"{s['p99']:.1f}",
                f"{s['max']:.0f}",
                f"{ratio.get('step_p50', float('nan')):.1f}",
                f"{ratio.get('step_p99', float('nan')):.1f}",
                f"{q['p50']:.1f}",
                f"{q['p99']:.1f}",
                paper.get(n, ""),
            ]
        )
    print_table(
        console,
        (
            "predictor",
            "step p50",
            "p90",
            "p99",
            "max",
            "p50 x cv",
            "p99 x cv",
            "query p50",
            "query p99",
            "paper",
        ),
        rows,
        title=f"per-call latency (us) on {drive.name}, one thread, {rounds} rounds",
    )
    if "lstm_stages" in res:
        pp = {
            "resample_positions": "~2000 (L-BFGS regression)",
            "inference": "~2000 (LSTM)",
            "cubic_fit_lbfgs": "~2000",
        }
        print_table(
            console,
            ("stage", "p50", "p90", "p99", "paper"),
            [
                [k, f"{v['p50']:.1f}", f"{v['p90']:.1f}", f"{v['p99']:.1f}", pp.get(k, "")]
                for k, v in res["lstm_stages"].items()
            ],
            title="lstm fix step by stage (us), staged reference (step=staged)",
        )
        print_table(
            console,
            ("stage", "p50", "p90", "p99"),
            [
                [k, f"{v['p50']:.1f}", f"{v['p90']:.1f}", f"{v['p99']:.1f}"]
                for k, v in res["lstm_fused_stages"].items()
            ],
            title="lstm fix step by stage (us), fused (the default)",
        )
        print_table(
            console,
            ("batch", "windows/s", "us/window"),
            [
                [str(b), f"{v['windows_per_s']:.0f}", f"{v['us_per_window']:.1f}"]
                for b, v in res["batch"].items()
            ],
            title="batch throughput (onnxruntime, one thread)",
            left_columns=0,
        )
