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
from posbench.report.table_files import TABLE_FORMATS
from posbench.saved_run.run import Run
from posbench.scenarios.errors import DataError
from posbench.scenarios.truth_gaps import TRUTH_MAX_GAP_S
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet, as_trace_set

if TYPE_CHECKING:
    from posbench.pipeline.jobs import FigureJobs, Job


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


class OutputWriter:
    """The one writer of a run's output folder: traces.parquet, figures (the run's and the
    paper's), report.md with its table files, and results.json, last and atomically.

    :meth:`start` begins the work that needs only the traces, right after the replay: it
    removes an earlier run's files, then draws the figures and writes traces.parquet in
    forked child processes (:class:`~posbench.pipeline.jobs.FigureJobs`,
    :class:`~posbench.pipeline.jobs.Job`) while this process aggregates. :meth:`write`
    collects them and writes the rest; without :meth:`start` it does everything itself
    (``bench score``). The files are the same either way.

    Args:
        out: the output folder.
        plot_formats: figure formats (png, svg, pdf).
        drive_plots: per-drive error plots (as ``--drive-plots``; None: every drive).
        table_formats: table files beside report.md (csv, latex; empty: none).
    """

    def __init__(
        self,
        out: Path,
        plot_formats: tuple[str, ...] = ("png",),
        drive_plots: int | None = 20,
        table_formats: tuple[str, ...] = TABLE_FORMATS,
    ) -> None:
        self.out = out
        self.plot_formats = tuple(plot_formats)
        self.drive_plots = drive_plots
        self.table_formats = tuple(table_formats)
        self._removed: list[Path] | None = None
        self._jobs: FigureJobs | None = None
        self._traces: Job[Path | None] | None = None

    def start(
        self,
        traces: TraceSet | pd.DataFrame,
        predictors: Sequence[str],
        paper: Callable[[], list[tuple[str, str]]] | None = None,
        lean: pd.DataFrame | None = None,
    ) -> None:
        """Remove an earlier run's files (first, so none of the new ones is), then start
        drawing the figures of ``traces`` (and ``paper()``, the paper's figures) and writing
        traces.parquet in other processes. ``traces``: where they are (a frame is wrapped in
        a :class:`~posbench.scoring.trace_set.TraceSet`); ``lean``: a frame ``traces`` as
        :func:`~posbench.scoring.trace_set.lean_traces` gives them, if already made."""
        from posbench.pipeline.jobs import FigureJobs, Job
        from posbench.saved_run.outputs import remove_previous_outputs
        from posbench.saved_run.run import TRACES

        ts = as_trace_set(traces)
        self.out.mkdir(parents=True, exist_ok=True)
        self._removed = remove_previous_outputs(self.out)
        self._jobs = FigureJobs(
            ts if lean is None else TraceSet(lean),
            predictors,
            self.out,
            self.plot_formats,
            self.drive_plots,
            paper=paper,
        )
        self._traces = Job(ts.write, self.out / TRACES)

    def paper_figures(self) -> list[tuple[str, str]]:
        """The paper's figures drawn since :meth:`start`, as (file name, caption) pairs, once
        their process is done (none without :meth:`start`): results.json's
        ``paper_figures`` (:func:`posbench.pipeline.results.build_results`)."""
        return self._jobs.paper() if self._jobs is not None else []

    def write(self, run: Run) -> tuple[list[Path], list[Path]]:
        """``run``'s files, results.json last: the files written, and those of an earlier
        run removed first."""
        from posbench.report.markdown import write_report
        from posbench.saved_run.outputs import remove_previous_outputs
        from posbench.saved_run.run import save_run

        out, jobs = self.out, self._jobs
        out.mkdir(parents=True, exist_ok=True)
        removed = self._removed if self._removed is not None else remove_previous_outputs(out)
        drawn = [f["file"] for f in run.results.get("paper_figures") or []]
        written = [(out / f).with_suffix("." + fmt) for f in drawn for fmt in self.plot_formats]
        written += write_report(
            run,
            out,
            formats=self.plot_formats,
            drive_plots=self.drive_plots,
            table_formats=self.table_formats,
            plots=jobs.plots() if jobs is not None else None,
        )
        traces_written = self._traces.result if self._traces is not None else None
        written += save_run(out, run, also_written=written, traces_written=traces_written)
        return written, removed


def publish(
    res: dict[str, Any],
    traces: pd.DataFrame,
    runs: Sequence[DriveRun],
    writer: OutputWriter | None = None,
    reporter: Reporter = SILENT,
) -> Published:
    """The :class:`Run` of aggregated results ``res``, written by ``writer`` into its folder
    (report.md, figures, tables, results.json, traces.parquet; an earlier run's files there
    are replaced) or, with ``writer`` None, kept in memory.

    A run that fails (the errors below) is written all the same, its results.json marked
    ``status`` failed with the error line as ``reason``; one interrupted (or failing) while
    its files are written gets a results.json marked interrupted (or failed) all the same.
    results.json is written last and atomically: no folder cut short reads as complete.

    Args:
        res: :func:`posbench.pipeline.results.build_results` output; ``traces`` the traces
            it was made from.
        runs: the per-drive :class:`~posbench.scoring.records.DriveRun` records (skipped
            drives named).
        writer: the output folder's writer (started or not); None: no folder.

    Raises:
        UsageError: every drive was skipped (the report is written first).
        DataError: no query of any drive could be scored (the report is written first).
    """
    from posbench.saved_run.run import FAILED, mark_unfinished

    run = Run.from_results(res, traces)
    out = writer.out if writer is not None else None
    failure = run_failure(run, runs, out)
    if failure is not None:
        mark_unfinished(run, FAILED, str(failure))
    written: list[Path] = []
    removed: list[Path] = []
    if writer is not None:
        from posbench.saved_run.run import marked_if_unfinished

        with marked_if_unfinished(run, out=writer.out):
            written, removed = writer.write(run)
    skipped = [r for r in runs if r.skipped]
    if skipped:
        reporter.line(
            f"skipped {plural(len(skipped), 'drive')}: "
            + "; ".join(f"{r.name} ({r.skipped})" for r in skipped)
        )
    if failure is not None:
        raise failure
    return Published(run, written, removed)


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
    for want of a reference position (with the truth's sampling where that is the cause:
    :attr:`~posbench.scoring.records.DriveRun.reference_gaps`); where report.md was
    written."""
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
        gaps = [r for r in runs if not r.skipped and r.reference_gaps]
        why = (
            "; ".join(f"drive {r.name}: {r.reference_gaps}" for r in gaps[:3])
            + ("; ..." if len(gaps) > 3 else "")
            if gaps
            else "past the end of the truth or of the fixes, or in a gap of the truth longer "
            f"than {TRUTH_MAX_GAP_S:g} s"
        )
        parts.append(
            f"{n_noref} quer{'y' if n_noref == 1 else 'ies'} without a reference position ({why})"
        )
    where = f"; wrote {out / 'report.md'} all the same" if out is not None else ""
    return "no query of any drive could be scored: " + ("; ".join(parts) or "no queries") + where
