"""What a drive's recording reads of the run's traces: one predictor's rows of one drive at a
time, the columns it logs (:data:`COLUMNS`), in pieces of at most :data:`PIECE_ROWS` rows, so
that the recording of a long drive never holds more than a piece of its traces."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

from posbench.scoring.schema import COV_COLUMNS
from posbench.scoring.trace_set import TraceSet

if TYPE_CHECKING:
    import pandas as pd

    from posbench.scoring.records import DriveRun

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

#: at most this many rows of traces are logged at once (a row group of a part is cut in pieces)
PIECE_ROWS = 1 << 13


def drive_source(run: DriveRun, traces: TraceSet | None) -> TraceSet | None:
    """Where drive ``run``'s traces are read from: the run's ``traces`` where given, else its
    own (held, or in its parts); None for a skipped drive."""
    if run.skipped:
        return None
    if traces is not None:
        return traces
    if run.trace_parts and run.traces.empty:
        return TraceSet(parts=run.trace_parts)
    return TraceSet(run.traces)


def predictor_pieces(
    run: DriveRun, source: TraceSet, predictor: str, piece_rows: int = PIECE_ROWS
) -> Iterator[pd.DataFrame]:
    """``predictor``'s rows of drive ``run`` (its data set's only), :data:`COLUMNS` of them,
    in the traces' order, in pieces of at most ``piece_rows`` rows."""
    for rows in source.drive_rows(run.name, predictor, COLUMNS):
        if "dataset" in rows.columns and len(rows):
            rows = rows[(rows["dataset"] == run.dataset).to_numpy()]
        for a in range(0, len(rows), piece_rows):
            yield rows.iloc[a : a + piece_rows]
