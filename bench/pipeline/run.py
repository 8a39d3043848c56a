"""``bench run`` as a library function: a checked :class:`~posbench.pipeline.plan.RunPlan`
in (:func:`~posbench.pipeline.plan.plan_run`), a :class:`~posbench.saved_run.run.Run` out.

:func:`execute_run` loads the drives, checks their data, replays them, combines and, given
an output folder, writes the report there; its docstring lists the stages of the data path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from posbench.config import RunConfig
from posbench.naming import plural
from posbench.pipeline.plan import RunOptions, RunPlan
from posbench.pipeline.publish import Published
from posbench.pipeline.reporter import SILENT, Reporter
from posbench.scenarios.drive import Drive

if TYPE_CHECKING:
    from posbench.pipeline.parts import PartsFolder
    from posbench.pipeline.publish import OutputWriter
    from posbench.scenarios.stored_drive import StoredDrive
    from posbench.scoring.records import DriveRun
    from posbench.scoring.trace_set import TraceSet


def execute_run(plan: RunPlan, command: str, reporter: Reporter = SILENT) -> Published:
    """Run a plan: load the drives (or make the built-in ones), check their data, replay them
    through every predictor (over every seed of ``plan.seeds``), combine, and publish: into
    ``plan.options.out`` when given, with the rerun recording when asked. ``command`` is
    recorded in results.json as what made the run.

    The data path is six stages, each handing the next what it needs
    (:func:`~posbench.pipeline.plan.plan_run` is the first, the command's summary the last):

    1. plan: the options checked and parsed, each predictor built once
       (:class:`~posbench.pipeline.plan.RunPlan`);
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
