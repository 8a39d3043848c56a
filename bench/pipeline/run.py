"""``bench run`` as a library function: options in, a :class:`~posbench.saved_run.run.Run` out.

:class:`RunOptions` holds everything the command takes (as Python values: seconds, paths,
tuples); :func:`plan_run` checks them all before any drive is loaded or worker started and
resolves them into a :class:`RunPlan`; :func:`execute_run` loads the drives, checks their
data, replays them, aggregates and, given an output folder, writes the report there. The
command line (:mod:`posbench.cli.run`) and :func:`posbench.run` both call these two, so a
notebook gets exactly the figures of the command.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from posbench.aggregation.intervals import Statistics
from posbench.config import DEFAULT_PREDICTORS, RunConfig
from posbench.errors import UsageError
from posbench.naming import plural
from posbench.pipeline.publish import Published
from posbench.pipeline.reporter import SILENT, Reporter
from posbench.report.table_files import TABLE_FORMATS, parse_report_formats
from posbench.scenarios.drive import Drive

if TYPE_CHECKING:
    from posbench.pipeline.parts import PartsFolder
    from posbench.pipeline.publish import OutputWriter
    from posbench.scenarios.stored_drive import StoredDrive
    from posbench.scoring.records import DriveRun
    from posbench.scoring.trace_set import TraceSet


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


def execute_run(plan: RunPlan, command: str, reporter: Reporter = SILENT) -> Published:
    """Run a plan: load the drives (or make the built-in ones), check their data, replay them
    through every predictor (over every seed of ``plan.seeds``), combine, and publish: into
    ``plan.options.out`` when given, with the rerun recording when asked. ``command`` is
    recorded in results.json as what made the run.

    The data path is six stages, each handing the next what it needs (:func:`plan_run` is
    the first, the command's summary the last):

    1. plan: the options checked and parsed, each predictor built once (:class:`RunPlan`);
    2. drives: loaded or made in child processes, each written to the parts folder; this
       process holds their descriptions (:func:`~posbench.pipeline.drives.stored_drives`);
    3. checks: the options no drive can take, and the data check (results.json's
       ``unhonoured`` and ``consistency``), before any replay;
    4. per-drive results: a worker replays a drive through every predictor, scores it, takes
       its bound, writes its traces to the parts folder and returns a small
       :class:`~posbench.scoring.records.DriveRun` (:func:`replay_drives`; once per seed);
    5. combined results: results.json's dict, built once from the per-drive results and the
       traces on disk (:func:`~posbench.pipeline.results.build_results`);
    6. outputs: figures, traces.parquet, report.md, table files, results.json and the rerun
       recording (:class:`~posbench.pipeline.publish.OutputWriter`; the figures are drawn
       from the traces on disk in other processes from the end of stage 4).

    Raises:
        DataError: a recording that cannot be read; with ``strict``, a failing data check.
        UsageError: every drive was skipped, or an option applies to none of the drives
            (:func:`posbench.pipeline.honoured.unhonoured`: --gps-profile rtk without truths).
        ExecutorError: Ray could not start.
    """
    from posbench.pipeline.data_check import run_data_check
    from posbench.pipeline.drives import stored_drives
    from posbench.pipeline.honoured import unhonoured
    from posbench.pipeline.parts import PartsFolder
    from posbench.pipeline.reporter import WARNING
    from posbench.scenarios.remote import local_paths

    o = plan.options
    # fsspec URLs -> local copies for loaders; the parts folder: where the loading processes
    # write the drives and the workers their traces (this process holds neither)
    with local_paths(list(o.data) or None) as data, PartsFolder(o.out) as parts:
        drives = stored_drives(
            data,
            parts.drives,
            o.projection,
            dict(o.topics) or None,
            seed=plan.config.seed,
            synthetic_duration_s=o.synthetic_duration_s,
            workers=o.workers if o.executor == "local" else 1,
            reporter=reporter,
        )
        notes = unhonoured(drives, plan.config)  # an option no drive can take: stop here
        for note in notes:
            reporter.line(f"note: {note}", WARNING)
        consistency = run_data_check(drives, plan.config.predictors, o.strict, reporter)
        return _replay_and_publish(drives, plan, data, command, consistency, reporter, parts, notes)


def replay_drives(
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    options: RunOptions,
    reporter: Reporter = SILENT,
    label: str = "",
    preload: Any = None,
    limit: bool = False,
    parts: Path | None = None,
) -> list[DriveRun]:
    """Every drive through every predictor of ``cfg`` on the options' executor, as
    :class:`~posbench.scoring.records.DriveRun` records in drive order, with each drive's
    bound given ``limit`` (:func:`posbench.replay.limit.drive_limit`); one reporter step
    per drive. ``parts``: the folder the workers write the drives' traces to (the records
    then name their parts instead of holding them). ``preload``
    (:class:`~posbench.pipeline.preload.Preload`) starts when the first drive is done, if
    the drives are replayed in other processes (the worker processes exist by then; in this
    one, its imports would disturb the timings)."""
    from posbench.replay.executors import run_drives

    elsewhere = options.executor != "local" or (options.workers > 1 and len(drives) > 1)
    with reporter.steps(
        f"{label}{plural(len(drives), 'drive')} x {plural(len(cfg.predictors), 'predictor')}",
        len(drives),
    ) as done:

        def on_done(r: DriveRun) -> None:
            done(r.name)
            if preload is not None and elsewhere:
                preload.start()

        return run_drives(
            drives,
            cfg,
            options.executor,
            workers=options.workers,
            address=options.address,
            on_done=on_done,
            limit=limit,
            parts=parts,
        )


def _replay_and_publish(
    drives: Sequence[StoredDrive],
    plan: RunPlan,
    data: list[Path] | None,
    command: str,
    consistency: dict[str, Any],
    reporter: Reporter,
    parts: PartsFolder,
    unhonoured: Sequence[str] = (),
) -> Published:
    """Stages 4 to 6 of :func:`execute_run`: the per-drive results of every seed, the
    combined results built once from them, and the outputs."""
    from posbench.pipeline.jobs import Job
    from posbench.pipeline.preload import Preload
    from posbench.pipeline.publish import publish
    from posbench.pipeline.results import build_results
    from posbench.saved_run.provenance import data_provenance
    from posbench.scenarios.loaders import distinct_recordings
    from posbench.scoring.records import trace_set

    cfg, o, seeds = plan.config, plan.options, plan.seeds
    first = f"seed {cfg.seed} (1/{len(seeds)}): " if seeds else ""
    recordings = distinct_recordings(data) if data else None  # as loaded: each counted once
    sources = recordings.sources if recordings is not None else None
    provenance = Job(data_provenance, sources, cfg.seed)  # hashing the data (~1 s) meanwhile
    preload = Preload()  # the imports of the figures and the report, during the replay
    runs = replay_drives(drives, cfg, o, reporter, first, preload, limit=True, parts=parts.seed(0))
    preload.join()  # before forking the figure children
    traces = trace_set(runs)  # on disk: read one predictor or drive at a time from here on
    # the figures need only the traces: other processes draw them (and write traces.parquet)
    # while this one replays the other seeds and combines
    writer = _start_outputs(plan, drives, traces, runs)
    sections: dict[str, Any] = {"consistency": consistency}
    if unhonoured:
        sections["unhonoured"] = list(unhonoured)
    if recordings is not None and recordings.duplicates:
        sections["data_duplicates"] = [
            {"path": str(d.path), "same_as": str(d.kept), "same_file": d.same_file}
            for d in recordings.duplicates
        ]
    if seeds:
        sections["seeds"] = _seeds_section(drives, plan, traces, reporter, parts)
    res = build_results(
        runs,
        cfg,
        provenance.result(),
        command,
        traces=traces,
        models=plan.models,
        statistics=plan.statistics,
        workers=o.workers,
        sections=sections,
        paper_figures=writer.paper_figures if writer is not None else None,
    )
    published = publish(res, traces, runs, writer, reporter)
    parts.drop_drives()  # replayed and drawn
    if o.rerun is not None:
        from posbench.saved_run.run import marked_if_unfinished

        with marked_if_unfinished(published.run, "writing the rerun recording"):
            _write_rerun(o.rerun, runs, cfg, plan.color_by, reporter)
        published.recording = o.rerun
    parts.keep_for(published.run)  # without an output folder, the run reads them later
    return published


def _start_outputs(
    plan: RunPlan,
    drives: Sequence[StoredDrive],
    traces: TraceSet,
    runs: Sequence[DriveRun],
) -> OutputWriter | None:
    """The output folder's writer, started: an earlier run's files removed, the figures (the
    run's and the paper's) drawn and traces.parquet written in other processes; None without
    an output folder."""
    out = plan.options.out
    if out is None:
        return None
    from posbench.pipeline.publish import OutputWriter
    from posbench.predictor_tools.paper_figures import paper_figures

    cfg, fmts = plan.config, plan.plot_formats
    writer = OutputWriter(out, fmts, plan.drive_plots, plan.table_formats)
    writer.start(
        traces,
        cfg.predictors,
        paper=lambda: paper_figures(drives, cfg, traces, out, runs, formats=fmts),
    )
    return writer


def _seeds_section(
    drives: Sequence[StoredDrive],
    plan: RunPlan,
    traces: TraceSet,
    reporter: Reporter,
    parts: PartsFolder,
) -> dict[str, Any]:
    """results.json's ``seeds``: the run's figures under its first seed (``traces``) and under
    each other seed of ``plan.seeds``, replayed here one seed at a time (each seed's traces
    dropped once its figures are taken), with their spread across seeds."""
    from posbench.aggregation.seeds import seed_figures, seeds_section
    from posbench.scoring.records import trace_set

    cfg, seeds = plan.config, plan.seeds or ()
    base = plan.statistics.baseline
    figures = [seed_figures(traces, cfg.predictors, base, cfg.seed)]
    for i, s in enumerate(seeds[1:], start=2):
        runs_s = replay_drives(
            drives,
            replace(cfg, seed=s),
            plan.options,
            reporter,
            f"seed {s} ({i}/{len(seeds)}): ",
            parts=parts.seed(i - 1),
        )
        figures.append(seed_figures(trace_set(runs_s), cfg.predictors, base, s))
        parts.drop(i - 1)
        del runs_s
    return seeds_section(seeds, figures)


def _write_rerun(
    path: Path,
    runs: list[DriveRun],
    cfg: RunConfig,
    color_by: str | None,
    reporter: Reporter,
) -> None:
    """The rerun recording of ``runs`` at ``path``.

    Raises:
        DataError: joining the drives' recordings failed.
    """
    from posbench.recording.writer import write_recording
    from posbench.scenarios.errors import DataError

    with reporter.phase(f"writing rerun recording {path}..."):
        try:
            write_recording(path, runs, list(cfg.predictors), color_by)
        except RuntimeError as e:  # joining the drives' recordings failed
            raise DataError(path, str(e)) from None
