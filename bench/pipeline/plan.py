"""``bench run``'s options and its checked plan: :class:`RunOptions` holds everything the
command takes (as Python values: seconds, paths, tuples); :func:`plan_run` checks them all
before any drive is loaded or worker started and resolves them into a :class:`RunPlan`, which
:func:`posbench.pipeline.run.execute_run` carries out. The command line
(:mod:`posbench.cli.run`) and :func:`posbench.run` both call these, so a notebook gets exactly
the figures of the command.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from posbench.aggregation.intervals import Statistics
from posbench.config import DEFAULT_PREDICTORS, RunConfig
from posbench.errors import UsageError
from posbench.report.table_files import TABLE_FORMATS, parse_report_formats


@dataclass(frozen=True)
class RunOptions:
    """Everything a run takes (the options of ``bench run``, as Python values).

    Attributes:
        data: recordings or folders of them (ROS 1/2 bags, KITTI raw, comma2k19 segments,
            the paper's route pickles, CSV/Parquet) or fsspec URLs; empty: the built-in
            synthetic drives.
        predictors: registered names, ``NAME@ALIAS`` or ``module:Class``, in report order.
        out: the output folder (report.md, results.json, traces, figures); None: the run is
            kept in memory only.
        horizon_s: future-point horizon after each fix [s].
        gps_profile: which fixes drives with truth are fed: auto (their own receiver's where
            it is not the truth, else rtk drawn from the truth), native, none, rtk, consumer
            (:func:`posbench.config.gps_condition`).
        gps_latency_s: receiver latency of drawn fixes [s].
        dropouts: GPS dropout profile (none, random:P, outages, outage:L, outage-lengths).
        seed: master seed (GPS draws, dropouts, synthetic data); None: 0.
        seeds: repeat the run over these seeds (the first one is the run), or a count or
            text as ``--seeds`` takes it (``5``, ``"0,1,2"``); None: once. Not with ``seed``.
        baseline: the predictor the others are compared with; None: ``kf`` when it runs;
            ``"none"``: no comparison.
        workers: parallel processes (one drive each).
        models: model file (or folder holding model.onnx) per predictor name.
        options: constructor options per predictor name, over its tuned values.
        topics: bag topics by role (gps, imu, speed, truth).
        projection: local frame of lat/lon sources (enu, mercator).
        include_poor_truth: also score drives whose truth is poor (median accuracy > 1 m).
        synthetic_duration_s: without data, one synthetic mixed drive this long [s].
        rerun: also write a rerun recording (.rrd) there.
        rerun_color_by: the predictor whose error colours the recording's track.
        executor: local (processes) or ray.
        address: the Ray cluster (with ``executor="ray"``).
        table_formats: table files beside report.md (csv, latex), or ``--table-format``'s
            text (``"md,csv"``).
        plot_formats: figure formats (png, svg, pdf), or ``--plot-format``'s text.
        drive_plots: per-drive error plots: every drive of a run with at most this many,
            else this many worst ones; None or ``"all"``: every drive.

    The options are checked, and those given as text parsed, once: by :func:`plan_run`.
        gate: the GPS outlier gate in front of every predictor.
        strict: stop (DataError) when the data consistency check fails.
        tuning: a tuning file (``bench tune --out``) used over the package's tuning for the
            predictors and GPS conditions it holds.
    """

    data: tuple[str | Path, ...] = ()
    predictors: tuple[str, ...] = DEFAULT_PREDICTORS
    out: Path | None = None
    horizon_s: float = 0.2
    gps_profile: str = "auto"
    gps_latency_s: float = 0.0
    dropouts: str = "none"
    seed: int | None = None
    seeds: tuple[int, ...] | int | str | None = None
    baseline: str | None = None
    workers: int = 2
    models: Mapping[str, str | Path] = field(default_factory=dict)
    options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    topics: Mapping[str, str] = field(default_factory=dict)
    projection: str = "enu"
    include_poor_truth: bool = False
    synthetic_duration_s: float | None = None
    rerun: Path | None = None
    rerun_color_by: str | None = None
    executor: str = "local"
    address: str | None = None
    table_formats: tuple[str, ...] | str = TABLE_FORMATS
    plot_formats: tuple[str, ...] | str = ("png",)
    drive_plots: int | str | None = 20
    gate: bool = True
    strict: bool = False
    tuning: Path | None = None

    @classmethod
    def names(cls) -> list[str]:
        """The option names, in order."""
        return [f.name for f in fields(cls)]


@dataclass(frozen=True)
class RunPlan:
    """Checked :class:`RunOptions`, resolved into what :func:`execute_run` does.

    Attributes:
        options: the options as given.
        config: the run's configuration (predictors with their aliases, resolved model
            files, the seed of the run).
        statistics: how intervals and the paired comparison are computed.
        seeds: the seeds to repeat the run over (the first one is ``config.seed``), or None.
        color_by: the predictor colouring the rerun recording's track.
        models: the learned models behind the predictors, asked of the instances built to
            check them (results.json's ``models``;
            :func:`posbench.replay.predictor_setup.plan_predictors`).
        plot_formats, drive_plots, table_formats: the options' figure formats, per-drive
            plots and table files, checked.
    """

    options: RunOptions
    config: RunConfig
    statistics: Statistics
    seeds: tuple[int, ...] | None = None
    color_by: str | None = None
    models: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    plot_formats: tuple[str, ...] = ("png",)
    drive_plots: int | None = 20
    table_formats: tuple[str, ...] = TABLE_FORMATS


def plan_run(options: RunOptions, given: Mapping[tuple[str, str], str] | None = None) -> RunPlan:
    """Check every option of a run before any work, and resolve them: the one place the
    options are checked (the command line passes its text on as given). Every predictor is
    built here once, and asked which learned model it uses.

    ``given``: how each ``(predictor, option)`` was written (``--set kf.jerk_psd=4``), for
    the messages; default ``--set NAME.OPTION=VALUE`` / ``--model NAME=PATH``.

    Raises:
        UsageError: an option that cannot work, in one line naming it.
        DataError: a model file a predictor cannot load.
    """
    from posbench.checks import (
        check_at_least,
        check_choice,
        check_drive_options,
        check_out_dir,
        check_out_file,
        check_topics,
        parse_drive_plots,
        parse_plot_formats,
        parse_predictor_names,
        parse_seeds,
        resolve_baseline,
        resolve_color_by,
    )
    from posbench.replay.executors import EXECUTORS, RAY_MISSING, ray_available
    from posbench.replay.predictor_options import merge_options, model_options
    from posbench.replay.predictor_setup import (
        check_tuning_file,
        plan_predictors,
        with_model_aliases,
    )

    o = options
    check_choice(o.executor, EXECUTORS, "--executor")
    if o.address and o.executor != "ray":
        raise UsageError("--address is for --executor ray")
    if o.executor == "ray" and not ray_available():
        raise UsageError(RAY_MISSING)
    names = parse_predictor_names(o.predictors)
    plot_formats = parse_plot_formats(o.plot_formats)
    if isinstance(o.table_formats, str):
        table_formats = parse_report_formats(o.table_formats, "--table-format")
    else:
        table_formats = tuple(o.table_formats)
    bad = [f for f in table_formats if f not in TABLE_FORMATS]
    if bad:
        raise UsageError(
            f"--table-format: unknown table format {bad[0]!r}; use "
            f"{', '.join(TABLE_FORMATS)} (report.md is always written)"
        )
    drive_plots = parse_drive_plots(o.drive_plots)
    if o.seeds is not None and o.seed is not None:
        raise UsageError(
            "--seed and --seeds together: give one seed (--seed 3) or the "
            "seeds to repeat the run over (--seeds 0,1,2)"
        )
    seeds = tuple(parse_seeds(o.seeds)) if o.seeds is not None else None
    seed = seeds[0] if seeds else (o.seed or 0)
    check_drive_options(
        o.gps_profile,
        o.projection,
        o.horizon_s,
        o.gps_latency_s,
        o.dropouts,
        seed,
        o.synthetic_duration_s,
        o.data,
    )
    check_at_least(o.workers, 1, "--workers")
    check_topics(o.topics)
    if o.out is not None:
        check_out_dir(o.out)
    if o.rerun is not None:
        check_out_file(o.rerun, "--rerun")
        try:
            import rerun as _rr  # noqa: F401
        except ImportError:
            raise UsageError(
                "--rerun needs the viz extra: pip install 'posbench-harness[viz]'"
            ) from None
    opts, given = merge_options(
        model_options(dict(o.models)), {n: dict(v) for n, v in o.options.items()}, dict(given or {})
    )
    names = with_model_aliases(names, opts)
    color_by = resolve_color_by(o.rerun_color_by, names, o.rerun)
    resolved, models = plan_predictors(names, opts, given)
    check_tuning_file(o.tuning, names, resolved)
    stats = Statistics(baseline=resolve_baseline(o.baseline, names))
    cfg = RunConfig(
        predictors=names,
        horizon_s=o.horizon_s,
        gps_profile=o.gps_profile,
        gps_latency_s=o.gps_latency_s,
        dropouts=o.dropouts,
        seed=seed,
        exclude_poor_truth=not o.include_poor_truth,
        predictor_options=resolved,
        gate=o.gate,
        tuning=str(o.tuning) if o.tuning is not None else None,
    )
    o = replace(
        o,
        predictors=names,
        plot_formats=plot_formats,
        drive_plots=drive_plots,
        seed=seed,
        seeds=seeds,
        table_formats=table_formats,
    )
    return RunPlan(o, cfg, stats, seeds, color_by, models, plot_formats, drive_plots, table_formats)
