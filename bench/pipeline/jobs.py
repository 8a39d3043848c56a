"""Draw a run's figures in other processes while this one aggregates.

The figures of a ``bench run`` need only the traces (and, for the paper's figures, the
drives and the run's fixes), not the aggregated results; drawing them takes about as long
as the aggregation (matplotlib, one core). So ``bench run`` starts them right after the
replay as forked child processes (:class:`Job`: the child inherits the traces'
:class:`~posbench.scoring.trace_set.TraceSet` without a copy - a frame in memory, or just
the paths of its parts on disk - reads from it one predictor or one drive at a time, draws,
and sends back only the list of files written and their notes) and collects them when the
report is written. The children run a little nicer than the parent
(:data:`CHILD_NICENESS`), so the aggregation keeps a core to itself. The files are byte for
byte those drawn in-process.

Where ``fork`` is not available (macOS and Windows start processes by ``spawn``, which
would pickle the traces), or when a child dies, the work is done in this process when
its result is asked for: slower, never different.

A child ends with this process however it ends, ignores Ctrl-C (this process answers it) and
is forked with Ctrl-C held (:mod:`posbench.scenarios.child_processes`); this process
interrupted while it waits for a child's answer ends that child.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

from posbench.figures.style import PlotsWritten
from posbench.figures.writer import joined, write_drive_plots, write_summary_plots
from posbench.scenarios.forked import CHILD_NICENESS as CHILD_NICENESS
from posbench.scenarios.forked import Job as Job
from posbench.scenarios.forked import can_fork as can_fork
from posbench.scoring.trace_set import TraceSet, lean_traces


class FigureJobs:
    """The figures of one run, drawn in parallel: the summary figures, the per-drive
    figures and (given ``paper``) the paper's figures, each in its own child process.

    Args:
        traces: the run's traces (a frame is wrapped in a :class:`TraceSet`; one in memory
            gets its text columns as categoricals once, :func:`lean_traces`); preds: the
            run's predictors in report order.
        out, formats, drive_plots: as :func:`posbench.figures.writer.write_plots`.
        paper: draws the paper's figures into ``out`` and returns (file, caption) pairs
            (:func:`posbench.predictor_tools.paper_figures.paper_figures` with the run bound);
            None: none.
        background: False draws everything in this process, when asked (for tests and
            platforms without fork this is what happens anyway).
    """

    def __init__(
        self,
        traces: TraceSet | pd.DataFrame,
        preds: Sequence[str],
        out: Path,
        formats: Sequence[str] = ("png",),
        drive_plots: int | None = 20,
        paper: Callable[[], list[tuple[str, str]]] | None = None,
        background: bool = True,
    ) -> None:
        background = background and bool(formats)  # none: nothing to draw, nothing to fork
        if background and can_fork():
            import matplotlib.figure  # noqa: F401  (once here, not once per child)
        preds = list(preds)
        frame = traces if isinstance(traces, pd.DataFrame) else traces.in_memory
        if frame is not None:  # categorical text columns: cheaper filters in the children
            traces = TraceSet(lean_traces(frame))
        self._paper = Job(paper, background=background) if paper is not None else None
        self._drives = Job(
            write_drive_plots,
            traces,
            preds,
            out,
            tuple(formats),
            drive_plots,
            background=background,
        )
        self._summary = Job(
            write_summary_plots, traces, preds, out, tuple(formats), background=background
        )

    def paper(self) -> list[tuple[str, str]]:
        """The paper's figures written: (file, caption) pairs ([] without ``paper``)."""
        return self._paper.result() if self._paper is not None else []

    def plots(self) -> PlotsWritten:
        """The run's figures written and their notes, as :func:`posbench.figures.writer.write_plots`
        gives them (summary figures first, then the per-drive ones)."""
        return joined(self._summary.result(), self._drives.result())
