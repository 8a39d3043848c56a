"""`bench run`: replay drives through predictors and write the report."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from posbench.checks import (
    check_at_least,
    check_choice,
    check_out_dir,
    check_out_file,
    parse_predictor_names,
    parse_seeds,
    resolve_baseline,
    resolve_color_by,
)
from posbench.cli.common import (
    DEFAULT_PREDICTORS,
    WORKER_DIED,
    DataError,
    DataOpt,
    DrivePlotsOpt,
    DropoutsOpt,
    GpsLatencyOpt,
    GpsProfileOpt,
    HorizonOpt,
    IncludePoorTruthOpt,
    PlotFormatOpt,
    ProjectionOpt,
    ReportFormatOpt,
    SetOpt,
    StrictOpt,
    SyntheticDurationOpt,
    TopicOpt,
    UsageError,
    check_drive_options,
    command_line,
    console,
    fail,
    import_from_cwd,
    load_drives,
    parse_topics,
)
from posbench.replay.predictor_setup import (
    predictor_options,
    validate_predictors,
    with_model_aliases,
)
from posbench.report.markdown import TABLE_FORMATS, parse_report_formats

if TYPE_CHECKING:
    import pandas as pd

    from posbench.pipeline.jobs import FigureJobs
    from posbench.pipeline.preload import Preload
    from posbench.saved_run.run import Run
    from posbench.scoring.records import DriveRun


def run(
    data: DataOpt = None,
    predictors: Annotated[str, typer.Option(
        "--predictors", "-p", metavar="NAMES",
        help="Comma-separated predictor names (see `bench predictors`) or module:Class of a "
             "Predictor subclass of your own (from PYTHONPATH or the current folder), e.g. "
             "kf,lstm,mypkg.mymodule:MyPredictor.")
    ] = DEFAULT_PREDICTORS,
    horizon: HorizonOpt = 0.2,
    gps_profile: GpsProfileOpt = "rtk",
    gps_latency: GpsLatencyOpt = 0.0,
    dropouts: DropoutsOpt = "none",
    seed: Annotated[int | None, typer.Option(
        metavar="INT", help="Master seed (GPS draws, dropouts, synthetic data); default 0.")
    ] = None,
    seeds: Annotated[str | None, typer.Option(
        "--seeds", metavar="N|S,S,...",
        help="Repeat the run over GPS-noise and dropout seeds, same drives: a count (5 = seeds "
             "0..4) or a list (0,1,2,3,4). The report adds each figure's mean, sd, min and max "
             "across seeds; traces, plots and every other figure are the first seed's. Not "
             "with --seed.")] = None,
    baseline: Annotated[str | None, typer.Option(
        "--baseline", metavar="NAME|none",
        help="Predictor the others are compared with on the same queries (difference of mean "
             "error, 95 % CI, drives won). Default: kf when it is in the run; none: no "
             "comparison.")] = None,
    out: Annotated[Path, typer.Option("--out", "-o", metavar="DIR", help="Output folder.")
                   ] = Path("bench-out"),
    workers: Annotated[int, typer.Option(
        metavar="N", help="Parallel processes (one drive each).")] = 2,
    model: Annotated[list[str] | None, typer.Option(
        "--model", metavar="NAME=PATH...",
        help="Model file per predictor, e.g. lstm-authors=PATH.onnx or lstm=DIR.")] = None,
    set_: SetOpt = None,
    topic: TopicOpt = None,
    projection: ProjectionOpt = "enu",
    include_poor_truth: IncludePoorTruthOpt = False,
    synthetic_duration: SyntheticDurationOpt = None,
    rerun: Annotated[Path | None, typer.Option(
        "--rerun", metavar="FILE",
        help="Also write a rerun file (.rrd; needs the viz extra; open it with `bench view "
             "FILE.rrd`): one recording per drive, named DATASET/DRIVE, picked in the viewer's "
             "source list. Each shows the whole-drive map (track coloured by error, see "
             "--rerun-color-by), a view around the vehicle (north up, +-5 m: last fixes, "
             "answers, error arrows from the reference), errors in the vehicle frame (along "
             "ahead, cross left, +-1 m, last 3 s), and error, along-track and cross-track [m] "
             "plots with outages and scenario labels.")] = None,
    rerun_color_by: Annotated[str | None, typer.Option(
        "--rerun-color-by", metavar="PREDICTOR",
        help="Predictor whose current-position error colours the rerun map's track (green 0 m "
             "to red at the drive's p95, legend in the recording); default: the first "
             "predictor. Needs --rerun.")] = None,
    executor: Annotated[str, typer.Option(
        metavar="local|ray",
        help="Where to run: local (processes, --workers) or ray (one Ray task per drive and "
             "predictor; needs the ray extra).")] = "local",
    address: Annotated[str | None, typer.Option(
        metavar="ADDRESS",
        help="Ray cluster to use with --executor ray (e.g. ray://head:10001 or auto); default: "
             "start a local Ray instance with --workers CPUs.")] = None,
    report_format: ReportFormatOpt = "md,csv,latex",
    plot_format: PlotFormatOpt = "png",
    drive_plots: DrivePlotsOpt = "20",
    gate: Annotated[bool, typer.Option(
        "--gate/--no-gate", help="GPS outlier gate: drop fixes implying impossible motion before "
        "the predictors see them (counted in the report). --no-gate: the paper's ungated input.")
    ] = True,
    strict: StrictOpt = False,
) -> None:
    """Replay drives through predictors and write report.md, results.json, traces and plots.

    Example: bench run --predictors lstm,kf --data ../shared/data/kitti_raw
    """
    from concurrent.futures.process import BrokenProcessPool

    from posbench.aggregation.intervals import Statistics
    from posbench.config import RunConfig
    from posbench.replay.executors import EXECUTORS, RAY_MISSING, ExecutorError, ray_available
    from posbench.scenarios.remote import local_paths

    try:
        # every option is checked before a drive is loaded or a worker starts
        check_choice(executor, EXECUTORS, "--executor")
        if address and executor != "ray":
            raise UsageError("--address is for --executor ray")
        if executor == "ray" and not ray_available():
            raise UsageError(RAY_MISSING)
        names = parse_predictor_names(predictors)
        formats = plot_formats(plot_format)
        table_formats = parse_report_formats(report_format)
        n_drive_plots = drive_plot_limit(drive_plots)
        if seed is not None and seeds is not None:
            raise UsageError("--seed and --seeds together: give one seed (--seed 3) or the "
                             "seeds to repeat the run over (--seeds 0,1,2)")
        seed_list = parse_seeds(seeds) if seeds is not None else [0 if seed is None else seed]
        seed = seed_list[0]
        check_drive_options(gps_profile, projection, horizon, gps_latency, dropouts, seed,
                            synthetic_duration, data)
        check_at_least(workers, 1, "--workers")
        topics = parse_topics(topic)
        check_out_dir(out)
        if rerun is not None:
            check_out_file(rerun, "--rerun")
            try:
                import rerun as _rr  # noqa: F401
            except ImportError:
                raise UsageError("--rerun needs the viz extra: "
                                 "pip install 'posbench-harness[viz]'") from None
        options, given = predictor_options(model, set_)
        names = with_model_aliases(names, options)
        color_by = resolve_color_by(rerun_color_by, names, rerun)
        import_from_cwd()
        options = validate_predictors(names, options, given)
        stats = Statistics(baseline=resolve_baseline(baseline, names))
        cfg = RunConfig(predictors=names, horizon_s=horizon, gps_profile=gps_profile,
                        gps_latency_s=gps_latency, dropouts=dropouts, seed=seed,
                        exclude_poor_truth=not include_poor_truth, predictor_options=options,
                        gate=gate)
        with local_paths(data) as data:  # fsspec URLs -> local copies for the loaders
            drives = load_drives(data, projection, topics, seed=seed,
                                 synthetic_duration=synthetic_duration,
                                 workers=workers if executor == "local" else 1)
            consistency = data_check(drives, names, strict)
            _run(drives, cfg, data, out, workers, rerun, executor, address, formats,
                 n_drive_plots, stats, seed_list if seeds is not None else None,
                 table_formats, consistency, color_by)
    except (DataError, UsageError, ExecutorError) as e:
        raise fail(str(e)) from None
    except BrokenProcessPool:
        raise fail(WORKER_DIED) from None


def data_check(drives, names: list[str], strict: bool) -> dict[str, Any]:
    """The data consistency check of every loaded drive, before any predictor runs: the
    ``consistency`` key of results.json; failures and warnings printed; with ``strict`` a
    failure raises :class:`DataError` naming the drive, stream and figure."""
    from posbench.pipeline.data_check import check_drives, strict_error, to_results
    from posbench.report.data_check import summary_lines

    checks = check_drives(drives)
    err = strict_error(checks) if strict else None
    if err is not None:
        raise err
    section = to_results(checks, names)
    for line in summary_lines(section):
        console.print(line, highlight=False, markup=False)
    return section


def plot_formats(value: str) -> tuple[str, ...]:
    """``--plot-format png,pdf`` as a tuple of known formats, in the order given."""
    from posbench.figures.style import check_formats

    try:
        return check_formats(value)
    except ValueError as e:
        raise UsageError(f"--plot-format {value!r}: {e}") from None


def drive_plot_limit(value: str) -> int | None:
    """``--drive-plots``: a count >= 0, or ``all`` (None: no limit)."""
    if value.strip().lower() == "all":
        return None
    try:
        n = int(value)
    except ValueError:
        n = -1
    if n < 0:
        raise UsageError(f"--drive-plots takes a count >= 0 or 'all', got {value!r}")
    return n


def plural(n: int, word: str) -> str:
    """``1 drive``, ``2 drives``."""
    return f"{n} {word}" + ("" if n == 1 else "s")


def _replay(drives, cfg, executor: str, workers: int, address: str | None, label: str = "",
            preload: Preload | None = None):
    """Every drive through every predictor of ``cfg``, with a progress bar. ``preload``
    starts when the first drive is done (the worker processes exist by then), if the drives
    are replayed in other processes (in this one, its imports would disturb the timings)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from posbench.replay.executors import run_drives

    elsewhere = executor != "local" or (workers > 1 and len(drives) > 1)

    def done(r: DriveRun) -> None:
        prog.update(task, advance=1, last=r.name)
        if preload is not None and elsewhere:
            preload.start()

    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), TextColumn("{task.fields[last]}"), console=console) as prog:
        task = prog.add_task(f"{label}{plural(len(drives), 'drive')} x "
                             f"{plural(len(cfg.predictors), 'predictor')}",
                             total=len(drives), last="")
        return run_drives(drives, cfg, executor, workers=workers, address=address,
                          on_done=done)


def _run(drives, cfg, data, out: Path, workers: int, rerun: Path | None = None,
         executor: str = "local", address: str | None = None,
         formats: tuple[str, ...] = ("png",), drive_plots: int | None = 20,
         stats=None, seeds: list[int] | None = None,
         table_formats: tuple[str, ...] = TABLE_FORMATS,
         consistency: dict[str, Any] | None = None, color_by: str | None = None) -> None:
    from dataclasses import replace

    from posbench.aggregation.seeds import seed_figures, seeds_section
    from posbench.pipeline.jobs import FigureJobs, Job
    from posbench.pipeline.preload import Preload
    from posbench.pipeline.results import build_results
    from posbench.predictor_tools.paper_figures import paper_figures
    from posbench.saved_run.outputs import remove_previous_outputs
    from posbench.saved_run.provenance import data_provenance
    from posbench.saved_run.run import write_traces
    from posbench.scoring.records import all_traces, lean_traces

    command = command_line()
    first = f"seed {cfg.seed} (1/{len(seeds)}): " if seeds else ""
    provenance = Job(data_provenance, data, cfg.seed)  # hashing the data (~1 s) meanwhile
    preload = Preload()  # the imports of the figures and the report, during the replay
    runs = _replay(drives, cfg, executor, workers, address, first, preload)
    preload.join()  # before forking the figure children
    traces = all_traces(runs)
    # the figures need only the traces: other processes draw them while this one aggregates
    # (an earlier run's files are removed first, so none of the new ones is)

    out.mkdir(parents=True, exist_ok=True)
    removed = remove_previous_outputs(out)
    lean = lean_traces(traces)  # text columns as categoricals: cheaper filters, same results
    jobs = FigureJobs(lean, cfg.predictors, out, formats, drive_plots, paper=lambda: (
        paper_figures(list(drives), cfg, traces, out, runs, formats=formats)))
    traces_file = Job(write_traces, out, traces)  # the parquet (~0.5 s) meanwhile too
    res = build_results(runs, cfg, provenance.result(), command, traces=lean, statistics=stats)
    if consistency is not None:
        res["consistency"] = consistency
    if seeds:
        base = res["paired"]["baseline"]
        figures = [seed_figures(traces, cfg.predictors, base, cfg.seed)]
        for i, s in enumerate(seeds[1:], start=2):
            runs_s = _replay(drives, replace(cfg, seed=s), executor, workers, address,
                             f"seed {s} ({i}/{len(seeds)}): ")
            figures.append(seed_figures(all_traces(runs_s), cfg.predictors, base, s))
            del runs_s
        res["seeds"] = seeds_section(seeds, figures)

    publish(res, traces, runs, out, formats, drive_plots, lambda _: jobs.paper(), table_formats,
            plots=jobs, removed=removed, traces_written=traces_file.result)
    if rerun is not None:
        from posbench.recording.writer import write_recording

        with console.status(f"writing rerun recording {rerun}..."):
            try:
                write_recording(rerun, runs, list(cfg.predictors), color_by)
            except RuntimeError as e:  # joining the drives' recordings failed
                raise DataError(rerun, str(e)) from None
        console.print(f"wrote {rerun} (open it with: bench view {rerun})")


def publish(res: dict[str, Any], traces: pd.DataFrame, runs: Sequence[DriveRun], out: Path,
            formats: tuple[str, ...] = ("png",), drive_plots: int | None = 20,
            figures: Callable[[Run], list[tuple[str, str]]] | None = None,
            table_formats: tuple[str, ...] = TABLE_FORMATS, plots: FigureJobs | None = None,
            removed: list[Path] | None = None,
            traces_written: Callable[[], Path | None] | None = None) -> Run:
    """Write the report folder for aggregated results ``res`` (report.md, figures, tables,
    results.json, traces.parquet; an earlier run's files there are replaced) and print the
    summary tables and the ``wrote ...`` line: how ``bench run`` and ``bench score`` end.

    Args:
        res: :func:`posbench.aggregation.aggregate.aggregate` output; ``traces`` the traces it was made from.
        runs: the per-drive :class:`~posbench.scoring.records.DriveRun` records (skipped drives named).
        figures: ``figures(run) -> [(file stem, caption)]`` draws extra figures into ``out``
            (the paper's figures of ``bench run``); None: none.
        table_formats: table files beside report.md (csv, latex; empty: none).
        plots: the run's plots, being drawn by :class:`~posbench.pipeline.jobs.FigureJobs`; None:
            drawn here.
        removed: the files of an earlier run already removed from ``out`` (by the caller,
            before it started drawing into it); None: removed here.
        traces_written: returns ``out/traces.parquet`` once written by the caller
            (:func:`posbench.saved_run.run.write_traces`, in another process); None: written here.

    Returns:
        the saved :class:`~posbench.saved_run.run.Run`.

    Raises:
        UsageError: every drive was skipped (the report is written first).
    """
    from posbench.cli.terminal import print_table
    from posbench.report.markdown import write_report
    from posbench.report.notes import excluded_note, trained_note
    from posbench.saved_run.outputs import remove_previous_outputs
    from posbench.saved_run.run import Run, save_run

    out.mkdir(parents=True, exist_ok=True)
    if removed is None:
        removed = remove_previous_outputs(out)
    result = Run.from_results(res, traces)
    drawn = figures(result) if figures is not None else []
    result.results["paper_figures"] = [{"file": f, "caption": c} for f, c in drawn]
    written = [(out / f).with_suffix("." + fmt) for f, _ in drawn for fmt in formats]
    written += write_report(result, out, formats=formats, drive_plots=drive_plots,
                            table_formats=table_formats,
                            plots=plots.plots() if plots is not None else None)
    written += save_run(out, result, also_written=written, traces_written=traces_written)
    res = result.results
    skipped = [r for r in runs if r.skipped]
    scored = len(runs) - len(skipped)
    if skipped:
        console.print(f"skipped {plural(len(skipped), 'drive')}: " + "; ".join(
            f"{r.name} ({r.skipped})" for r in skipped), highlight=False)
    if scored == 0:
        raise UsageError(f"every drive was skipped ({plural(len(runs), 'drive')}), nothing was "
                         f"scored; the reasons are in {out / 'report.md'}")
    if not any(p[k]["count"] + p[k]["missing"] for p in res["predictors"].values()
               for k in ("future", "now")):
        console.print("warning: no query could be scored (no reference position at any query "
                      "past the warm-up); see the exclusions below", highlight=False)
    from posbench.report.notes import has_held_out_paired, has_paired
    from posbench.tables.run_tables import summary_table
    from posbench.tables.stat_tables import paired_table, seeds_table

    headline = summary_table(res, compact=True)
    print_table(console, headline.header(), headline.cells(),
                title=f"{plural(scored, 'drive')} - errors in metres [95 % CI], latency in "
                      f"microseconds")
    for note in (trained_note(res), excluded_note(res)):
        if note:
            console.print(note, highlight=False)
    if has_paired(res):
        paired = paired_table(res)
        print_table(console, paired.header(), paired.cells(),
                    title=f"vs {res['paired']['baseline']}: Δ mean error [m], same queries "
                          f"[95 % CI]; * CI excludes 0")
    if res.get("seeds"):
        st = seeds_table(res)
        print_table(console, st.header(), st.cells(),
                    title=f"over seeds {', '.join(map(str, res['seeds']['seeds']))}: mean error "
                          f"[m] (figures and traces: seed {res['seeds']['traces_seed']})")
    if res.get("held_out_all"):
        ho = res["held_out_all"]
        held = summary_table(res, held_out=True, compact=True)
        print_table(console, held.header(), held.cells(),
                    title=f"held-out {plural(len(ho['drives']), 'drive')} (no learned predictor "
                          f"trained on them) - errors in metres")
        if has_held_out_paired(res):
            hp = paired_table(res, held_out=True)
            print_table(console, hp.header(), hp.cells(),
                        title=f"held-out drives vs {res['paired']['baseline']}: Δ mean error [m] "
                              f"[95 % CI]; * CI excludes 0")
    console.print(written_summary(out, written, removed), highlight=False)
    return result


def written_summary(out: Path, written: list[Path], removed: list[Path]) -> str:
    """One line naming what the run wrote into ``out`` (and removed of an earlier run)."""
    top = [p.name for p in written if p.parent == out]
    text = f"wrote {out}/: " + ", ".join(top)
    nested: dict[str, int] = {}
    for p in written:
        if p.parent != out:
            folder = p.relative_to(out).parts[0]
            nested[folder] = nested.get(folder, 0) + 1
    what = {"drives": "per-drive plot", "tables": "table file"}
    for folder, n in nested.items():
        text += f", {plural(n, what.get(folder, 'file'))} in {folder}/"
    if removed:
        text += f" (removed {plural(len(removed), 'file')} of an earlier run there)"
    return text
