"""What a drive's recording reads of the run's traces: one drive's rows, the columns it logs
(:data:`COLUMNS`), from the run's :class:`~posbench.scoring.trace_set.TraceSet` where one is
given, so that the recording of a long run never holds more than one drive's traces."""

from __future__ import annotations

from typing import TYPE_CHECKING

from posbench.scoring.schema import COV_COLUMNS

if TYPE_CHECKING:
    import pandas as pd

    from posbench.scoring.records import DriveRun
    from posbench.scoring.trace_set import TraceSet

#: the trace columns a drive's recording reads (those the traces have): positions [m],
#: errors [m], covariances [m^2], query time [s], and what tells the rows apart
COLUMNS = (
    "dataset",
    "predictor",
    "kind",
    "t_query",
    "x",
    "y",
    "x_ref",
    "y_ref",
    "error_m",
    "along_m",
    "cross_m",
    "label",
    *COV_COLUMNS,
)


def drive_traces(run: DriveRun, traces: TraceSet | None) -> pd.DataFrame | None:
    """The rows of drive ``run`` its recording reads, in the traces' order: from ``traces``
    the rows of its drive and data set, :data:`COLUMNS` of them (one drive read at a time);
    without ``traces``, the run's own (held, or read from its parts:
    :meth:`~posbench.scoring.records.DriveRun.load_traces`). None for a skipped drive."""
    if run.skipped:
        return None
    if traces is None:
        return run.load_traces()
    if traces.empty:
        return None
    rows = traces.frame(COLUMNS, drive=run.name)
    if "dataset" in rows.columns and len(rows):
        rows = rows[(rows["dataset"] == run.dataset).to_numpy()]
    return rows
