"""How ``bench run`` and ``bench score`` end: aggregated results become a :class:`Run`, and,
given a folder, its files (report.md, figures, table files, results.json, traces.parquet)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from posbench.errors import UsageError
from posbench.naming import plural
from posbench.pipeline.reporter import SILENT, Reporter
from posbench.report.markdown import TABLE_FORMATS
from posbench.saved_run.run import Run
from posbench.scenarios.errors import DataError
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS

if TYPE_CHECKING:
    from posbench.pipeline.jobs import FigureJobs


@dataclass
class Published:
    """What a pipeline made: the run, and what it did in its output folder.

    Attributes:
        run: the run (saved in ``run.folder``, or in memory only when that is None).
        written: the files written into the output folder (none without one).
        removed: the files of an earlier run removed from it first.
        recording: the rerun recording written, if one was asked for.
    """

    run: Run
    written: list[Path] = field(default_factory=list)
    removed: list[Path] = field(default_factory=list)
    recording: Path | None = None


def publish(
    res: dict[str, Any],
    traces: pd.DataFrame,
    runs: Sequence[DriveRun],
    out: Path | None,
    *,
    plot_formats: tuple[str, ...] = ("png",),
    drive_plots: int | None = 20,
    figures: Callable[[Run], list[tuple[str, str]]] | None = None,
    table_formats: tuple[str, ...] = TABLE_FORMATS,
    plots: FigureJobs | None = None,
    removed: list[Path] | None = None,
    traces_written: Callable[[], Path | None] | None = None,
    reporter: Reporter = SILENT,
) -> Published:
    """The :class:`Run` of aggregated results ``res``, written into ``out`` (report.md,
    figures, tables, results.json, traces.parquet; an earlier run's files there are
    replaced) or, with ``out`` None, kept in memory.

    A run that fails (the errors below) is written all the same, its results.json marked
    ``status`` failed with the error line as ``reason``; one interrupted (or failing) while
    its files are written gets a results.json marked interrupted (or failed) all the same.
    results.json is written last and atomically: no folder cut short reads as complete.

    Args:
        res: :func:`posbench.pipeline.results.build_results` output; ``traces`` the traces
            it was made from.
        runs: the per-drive :class:`~posbench.scoring.records.DriveRun` records (skipped
            drives named).
        figures: ``figures(run) -> [(file stem, caption)]`` draws extra figures into ``out``
            (the paper's figures of ``bench run``); None: none.
        table_formats: table files beside report.md (csv, latex; empty: none).
        plots: the run's plots, being drawn by :class:`~posbench.pipeline.jobs.FigureJobs`;
            None: drawn here.
        removed: the files of an earlier run already removed from ``out`` (by the caller,
            before it started drawing into it); None: removed here.
        traces_written: returns ``out/traces.parquet`` once written by the caller
            (:func:`posbench.saved_run.run.write_traces`, in another process); None: written
            here.

    Raises:
        UsageError: every drive was skipped (the report is written first).
        DataError: no query of any drive could be scored (the report is written first).
    """
    from posbench.saved_run.run import FAILED, mark_unfinished

    run = Run.from_results(res, traces)
    failure = run_failure(run, runs, out)
    if failure is not None:
        mark_unfinished(run, FAILED, str(failure))
    written: list[Path] = []
    if out is not None:
        from posbench.saved_run.run import marked_if_unfinished

        with marked_if_unfinished(run, out=out):
            written, removed = _write(
                run,
                out,
                plot_formats,
                drive_plots,
                figures,
                table_formats,
                plots,
                removed,
                traces_written,
            )
    else:
        run.results["paper_figures"] = []
    skipped = [r for r in runs if r.skipped]
    if skipped:
        reporter.line(
            f"skipped {plural(len(skipped), 'drive')}: "
            + "; ".join(f"{r.name} ({r.skipped})" for r in skipped)
        )
    if failure is not None:
        raise failure
    return Published(run, written, list(removed or []))


def _write(
    run: Run,
    out: Path,
    plot_formats: tuple[str, ...],
    drive_plots: int | None,
    figures: Callable[[Run], list[tuple[str, str]]] | None,
    table_formats: tuple[str, ...],
    plots: FigureJobs | None,
    removed: list[Path] | None,
    traces_written: Callable[[], Path | None] | None,
) -> tuple[list[Path], list[Path]]:
    """``run``'s files in ``out`` (see :func:`publish`), results.json last: the files
    written, and those of an earlier run removed first."""
    from posbench.report.markdown import write_report
    from posbench.saved_run.outputs import remove_previous_outputs
    from posbench.saved_run.run import save_run

    out.mkdir(parents=True, exist_ok=True)
    if removed is None:
        removed = remove_previous_outputs(out)
    drawn = figures(run) if figures is not None else []
    run.results["paper_figures"] = [{"file": f, "caption": c} for f, c in drawn]
    written = [(out / f).with_suffix("." + fmt) for f, _ in drawn for fmt in plot_formats]
    written += write_report(
        run,
        out,
        formats=plot_formats,
        drive_plots=drive_plots,
        table_formats=table_formats,
        plots=plots.plots() if plots is not None else None,
    )
    written += save_run(out, run, also_written=written, traces_written=traces_written)
    return written, removed


def run_failure(
    run: Run, runs: Sequence[DriveRun], out: Path | None
) -> UsageError | DataError | None:
    """Why ``run`` fails, as the error its command exits with, or None: every drive was
    skipped (UsageError), or no query of any drive could be scored (DataError). ``out``: where
    report.md is written, named in the message."""
    skipped = [r for r in runs if r.skipped]
    if len(skipped) == len(runs):
        where = (
            f"the reasons are in {out / 'report.md'}"
            if out is not None
            else "; ".join(f"{r.name}: {r.skipped}" for r in skipped[:3])
            + ("; ..." if len(skipped) > 3 else "")
        )
        return UsageError(
            f"every drive was skipped ({plural(len(runs), 'drive')}), nothing was scored; {where}"
        )
    if not any(
        p[k]["count"] + p[k]["missing"] for p in run.results["predictors"].values() for k in KINDS
    ):
        return DataError(None, nothing_scored(run.results, runs, out))
    return None


def nothing_scored(res: dict[str, Any], runs: Sequence[DriveRun], out: Path | None) -> str:
    """Why a run scored no query of any drive, in one line: the drives fed fewer than two
    fixes (queries start at a drive's second fix), and the queries left out as warm-up or
    for want of a reference position; where report.md was written."""
    from posbench.report.notes import excluded_counts

    few = [r for r in runs if not r.skipped and r.gps_count < 2]
    parts = []
    if few:
        parts.append(
            "; ".join(
                f"drive {r.name} was fed {r.gps_count} fix{'' if r.gps_count == 1 else 'es'}"
                for r in few[:3]
            )
            + ("; ..." if len(few) > 3 else "")
            + " (queries start at a drive's second fix)"
        )
    n_warm, n_noref = excluded_counts(res)
    if n_warm:
        parts.append(
            f"{n_warm} warm-up quer{'y' if n_warm == 1 else 'ies'} (before a "
            f"drive's second received fix)"
        )
    if n_noref:
        parts.append(
            f"{n_noref} quer{'y' if n_noref == 1 else 'ies'} without a reference "
            f"position (past the end of the truth or of the fixes)"
        )
    where = f"; wrote {out / 'report.md'} all the same" if out is not None else ""
    return "no query of any drive could be scored: " + ("; ".join(parts) or "no queries") + where
