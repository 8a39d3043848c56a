"""A run's trace parts written: one Parquet file per drive task, its rows in row groups of one
predictor each (:class:`PartWriter`, piece by piece as a worker scores them;
:func:`write_part`, a frame at once). They are read by :mod:`posbench.scoring.trace_parts`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pandas as pd

#: the most rows of a part's row group that :class:`PartWriter` gathers from pieces
GROUP_ROWS = 1 << 16


class PartWriter:
    """A traces part written piece by piece (:meth:`write`, in the order its rows are to be
    read) as ``folder/name.parquet``: to a temporary name, renamed by :meth:`close`, so a part
    that exists is whole (left unfinished, as when an error leaves the ``with`` block, it is
    removed). Consecutive pieces of one predictor are gathered into row groups of up to
    :data:`GROUP_ROWS` rows (a piece larger than that is a group of its own); a row group
    holds one predictor's rows, so that a read of one predictor skips the others
    (:func:`read_part`). Memory: one row group."""

    def __init__(self, folder: Path, name: str) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.path = folder / f"{name}.parquet"
        self._tmp = folder / f".{name}.{os.getpid()}.tmp"
        self._writer: Any = None
        self._pending: list[Any] = []  # Arrow tables of one predictor, not yet written
        self._pending_rows = 0
        self._pending_of: object = None
        #: the rows written so far
        self.rows = 0
        #: the first piece's columns and types, no rows (None before any piece)
        self.empty: pd.DataFrame | None = None

    def write(self, piece: pd.DataFrame) -> None:
        """Append ``piece`` (the columns and types of every piece the same)."""
        import pyarrow as pa

        if self.empty is None:
            self.empty = piece.iloc[:0]
        if piece.empty:
            return
        of = piece["predictor"].iloc[0] if "predictor" in piece.columns else None
        if self._pending and (
            of != self._pending_of or self._pending_rows + len(piece) > GROUP_ROWS
        ):
            self._flush()
        self._pending.append(pa.Table.from_pandas(piece, preserve_index=False))
        self._pending_rows += len(piece)
        self._pending_of = of
        self.rows += len(piece)

    def _flush(self) -> None:
        """The pieces gathered, written as one row group."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._pending:
            return
        table = pa.concat_tables(self._pending)
        self._pending, self._pending_rows = [], 0
        if self._writer is None:
            self._writer = pq.ParquetWriter(self._tmp, table.schema)
        self._writer.write_table(table)

    def write_by_predictor(self, rows: pd.DataFrame) -> None:
        """Append ``rows`` of several predictors, one predictor's after another's in the
        order they first appear (each predictor's rows one piece)."""
        for _, mine in rows.groupby("predictor", sort=False, observed=True):
            self.write(mine)

    def close(self) -> Path:
        """Finish the part (with no rows: the columns of the first piece) and name it."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        self._flush()
        if self._writer is None:
            empty = self.empty if self.empty is not None else pd.DataFrame()
            pq.write_table(pa.Table.from_pandas(empty, preserve_index=False), self._tmp)
        else:
            self._writer.close()
            self._writer = None
        os.replace(self._tmp, self.path)
        return self.path

    def __enter__(self) -> PartWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        self._tmp.unlink(missing_ok=True)


def write_part(folder: Path, traces: pd.DataFrame, name: str) -> Path:
    """``traces`` (one drive's, or one drive and predictor's) as ``folder/name.parquet``, one
    row group per predictor (:class:`PartWriter`). The path."""
    with PartWriter(folder, name) as part:
        part.write(traces.iloc[:0])
        part.write_by_predictor(traces)
        return part.close()
