"""``bench run``: replay drives through predictors and write the report
(:mod:`posbench.pipeline.plan` and :mod:`posbench.pipeline.run` do the work; this module
reads the command line)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.options import (
    ConfigOpt,
    DataOpt,
    DrivePlotsOpt,
    DropoutsOpt,
    GateOpt,
    GpsLatencyOpt,
    GpsProfileOpt,
    HorizonOpt,
    IncludePoorTruthOpt,
    ModelOpt,
    OldFormatOpt,
    PlotFormatOpt,
    ProjectionOpt,
    QuietOpt,
    SetOpt,
    StrictOpt,
    SyntheticDurationOpt,
    TableFormatOpt,
    TopicOpt,
    VerboseOpt,
    WideOpt,
    WorkersOpt,
    command_line,
    import_from_cwd,
    parse_topics,
    predictors_option,
    renamed,
)
from posbench.config import DEFAULT_PREDICTORS


def run(
    ctx: typer.Context,
    data: DataOpt = None,
    predictors: Annotated[list[str] | None, predictors_option(",".join(DEFAULT_PREDICTORS))] = None,
    horizon: HorizonOpt = 0.2,
    gps_profile: GpsProfileOpt = "auto",
    gps_latency: GpsLatencyOpt = 0.0,
    dropouts: DropoutsOpt = "none",
    seed: Annotated[
        int | None,
        typer.Option(
            metavar="INT", help="Master seed (GPS draws, dropouts, synthetic data); default 0."
        ),
    ] = None,
    seeds: Annotated[
        str | None,
        typer.Option(
            "--seeds",
            metavar="N|S,S,...",
            help="Repeat the run over GPS-noise and dropout seeds, same drives: a count (5 = seeds "
            "0..4) or a list (0,1,2,3,4). The report adds each figure's mean, sd, min and max "
            "across seeds; traces, plots and every other figure are the first seed's. Not "
            "with --seed.",
        ),
    ] = None,
    baseline: Annotated[
        str | None,
        typer.Option(
            "--baseline",
            metavar="NAME|none",
            help="Predictor the others are compared with on the same queries (difference of mean "
            "error, 95 % CI, drives won). Default: kf when it is in the run; none: no "
            "comparison.",
        ),
    ] = None,
    out: Annotated[Path, typer.Option("--out", "-o", metavar="DIR", help="Output folder.")] = Path(
        "bench-out"
    ),
    workers: WorkersOpt = 2,
    model: ModelOpt = None,
    set_: SetOpt = None,
    topic: TopicOpt = None,
    projection: ProjectionOpt = "enu",
    include_poor_truth: IncludePoorTruthOpt = False,
    tuning: Annotated[
        Path | None,
        typer.Option(
            "--tuning",
            metavar="FILE",
            help="A tuning file written by `bench tune --out` (your own development drives): its "
            "parameters replace the built-in ones for the predictors and GPS conditions it "
            "holds. report.md and results.json name the tuning each baseline used.",
        ),
    ] = None,
    synthetic_duration: SyntheticDurationOpt = None,
    rerun: Annotated[
        Path | None,
        typer.Option(
            "--rerun",
            metavar="FILE",
            help="Also write a rerun file (.rrd; needs the viz extra; open it with `bench view "
            "FILE.rrd`): one recording per drive, named DATASET/DRIVE, picked in the viewer's "
            "source list. Each shows the whole-drive map (track coloured by error, see "
            "--rerun-color-by), a view around the vehicle (north up, +-5 m: last fixes, "
            "answers, error arrows from the reference), errors in the vehicle frame (along "
            "ahead, cross left, +-1 m, last 3 s), and error, along-track and cross-track [m] "
            "plots with outages and scenario labels.",
        ),
    ] = None,
    rerun_color_by: Annotated[
        str | None,
        typer.Option(
            "--rerun-color-by",
            metavar="PREDICTOR",
            help="Predictor whose current-position error colours the rerun map's track (green 0 m "
            "to red at the drive's p95, legend in the recording); default: the first "
            "predictor. Needs --rerun.",
        ),
    ] = None,
    executor: Annotated[
        str,
        typer.Option(
            metavar="local|ray",
            help="Where to run: local (processes, --workers) or ray (one Ray task per drive and "
            "predictor; needs the ray extra).",
        ),
    ] = "local",
    address: Annotated[
        str | None,
        typer.Option(
            metavar="ADDRESS",
            help="Ray cluster to use with --executor ray (e.g. ray://head:10001 or auto); default: "
            "start a local Ray instance with --workers CPUs.",
        ),
    ] = None,
    table_format: TableFormatOpt = "md,csv,latex",
    plot_format: PlotFormatOpt = "png",
    drive_plots: DrivePlotsOpt = "20",
    gate: GateOpt = True,
    strict: StrictOpt = False,
    print_config: Annotated[
        bool,
        typer.Option(
            "--print-config",
            help="Print this run's options (defaults, --config file and command line merged) as a "
            "TOML table for --config, and exit without running.",
        ),
    ] = False,
    wide: WideOpt = False,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    old_format: OldFormatOpt = None,
) -> None:
    """Replay drives through predictors and write report.md, results.json, traces and plots.

    Examples: bench run; bench run -p lstm -p kf --data ../shared/data/kitti_raw;
    bench run --config run.toml --seeds 5
    """
    from posbench.checks import parse_pairs
    from posbench.cli.config_file import to_toml
    from posbench.cli.summary import print_run_summary
    from posbench.cli.terminal import reporter
    from posbench.pipeline.plan import RunOptions, plan_run
    from posbench.pipeline.run import execute_run
    from posbench.replay.predictor_options import parse_set

    if old_format is not None:
        renamed("--format", "--table-format", "bench run")
        table_format = old_format
    if print_config:
        print(to_toml(ctx), end="")
        return
    # the options are passed on as given: plan_run checks (and parses) each one, once
    options, given = parse_set(set_)
    opts = RunOptions(
        data=tuple(data or ()),
        predictors=tuple(predictors or DEFAULT_PREDICTORS),
        out=out,
        horizon_s=horizon,
        gps_profile=gps_profile,
        gps_latency_s=gps_latency,
        dropouts=dropouts,
        seed=seed,
        seeds=seeds,
        baseline=baseline,
        workers=workers,
        models=parse_pairs(model, "--model"),
        options=options,
        topics=parse_topics(topic),
        projection=projection,
        include_poor_truth=include_poor_truth,
        synthetic_duration_s=synthetic_duration,
        rerun=rerun,
        rerun_color_by=rerun_color_by,
        executor=executor,
        address=address,
        table_formats=table_format,
        plot_formats=plot_format,
        drive_plots=drive_plots,
        gate=gate,
        strict=strict,
        tuning=tuning,
    )
    import_from_cwd()
    plan = plan_run(opts, given)  # every option is checked before a drive is loaded
    print_run_summary(execute_run(plan, command_line(), reporter()), wide=wide)
