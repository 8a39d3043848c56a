"""A run's traces where they are: in memory (one frame) or on disk (one Parquet part per drive
task, written by the worker that replayed it), read one predictor or one drive at a time.

``bench run`` keeps no drive's answers in the process that combines the figures: each worker
writes its drive's traces as a part (:func:`write_part`, one row group per predictor) and
returns a :class:`~posbench.scoring.records.DriveRun` that names the part. Aggregation, the
figures and the saved run then read from the parts only the rows and columns they need
(:meth:`TraceSet.scored`, :meth:`TraceSet.frame`), so what the combining process holds is one
predictor's columns, never every answer of the run. A frame in memory (``bench score``, a
notebook, the tests) answers the same calls, with the same rows in the same order: the
figures do not depend on where the traces are.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from posbench.scoring.schema import scored_mask

#: the text columns read as categoricals (dictionary-encoded): small codes instead of strings
TEXT = ("dataset", "drive", "predictor")
#: what :func:`posbench.scoring.schema.scored_mask` reads
MASK_COLUMNS = ("x_ref", "y_ref", "warmup")


def write_part(folder: Path, traces: pd.DataFrame, name: str) -> Path:
    """``traces`` (one drive's, or one drive and predictor's) as ``folder/name.parquet``, one
    row group per predictor so that a read of one predictor skips the others; written to a
    temporary name and renamed, so a part that exists is whole. The path."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.parquet"
    tmp = folder / f".{name}.{os.getpid()}.tmp"
    writer = None
    try:
        for _, rows in traces.groupby("predictor", sort=False, observed=True):
            table = pa.Table.from_pandas(rows, preserve_index=False)
            if writer is None:
                writer = pq.ParquetWriter(tmp, table.schema)
            writer.write_table(table)
        if writer is None:  # no rows: an empty part keeps the columns
            pq.write_table(pa.Table.from_pandas(traces, preserve_index=False), tmp)
        else:
            writer.close()
            writer = None
        os.replace(tmp, path)
    finally:
        if writer is not None:
            writer.close()
        tmp.unlink(missing_ok=True)
    return path


def read_part(
    path: str | Path, columns: Sequence[str] | None = None, predictor: str | None = None
) -> pd.DataFrame:
    """One part's rows (of ``predictor`` only, given one), its text columns as categoricals."""
    import pyarrow.parquet as pq

    cols = None if columns is None else list(dict.fromkeys(columns))
    filters = [("predictor", "==", predictor)] if predictor is not None else None
    table = pq.read_table(
        path,
        columns=cols,
        filters=filters,
        read_dictionary=[c for c in TEXT if cols is None or c in cols],
    )
    return table.to_pandas()


class TraceSet:
    """The traces of a run, in memory (``frame``) or as part files in drive order (``parts``;
    a drive replayed one predictor per task has one part per predictor, in predictor order).

    Every read gives the rows in the order of the concatenated traces (drive, then
    predictor, then future before now), whichever the source."""

    def __init__(self, frame: pd.DataFrame | None = None, parts: Sequence[str | Path] = ()) -> None:
        if frame is not None and parts:
            raise ValueError("a TraceSet is a frame or parts, not both")
        self._frame = frame if frame is not None else (None if parts else pd.DataFrame())
        self.parts = tuple(Path(p) for p in parts)
        self._keep: np.ndarray | None = None
        self._columns: list[str] | None = None
        self._rows: int | None = None

    # -- what it holds ------------------------------------------------------------------
    @property
    def in_memory(self) -> pd.DataFrame | None:
        """The frame, when the traces are in memory; None when they are on disk."""
        return self._frame

    @property
    def columns(self) -> list[str]:
        """The trace columns."""
        if self._columns is None:
            if self._frame is not None:
                self._columns = [str(c) for c in self._frame.columns]
            else:
                import pyarrow.parquet as pq

                self._columns = list(pq.read_schema(self.parts[0]).names)
        return self._columns

    def __contains__(self, column: object) -> bool:
        return column in self.columns

    @property
    def rows(self) -> int:
        """How many rows (queries x predictors)."""
        if self._rows is None:
            if self._frame is not None:
                self._rows = len(self._frame)
            else:
                import pyarrow.parquet as pq

                self._rows = sum(pq.ParquetFile(p).metadata.num_rows for p in self.parts)
        return self._rows

    @property
    def empty(self) -> bool:
        """No rows at all."""
        return self.rows == 0

    # -- reads ---------------------------------------------------------------------------
    def frame(
        self, columns: Sequence[str] | None = None, predictor: str | None = None
    ) -> pd.DataFrame:
        """Rows (of ``predictor`` only, given one) with ``columns`` (None: all), text columns
        as categoricals. On disk, this reads them: ask for what you need."""
        if self._frame is not None:
            from posbench.scoring.records import lean_traces

            df = self._frame
            if predictor is not None and not df.empty:
                df = df.loc[(df["predictor"] == predictor).to_numpy()]
            if columns is not None:
                df = df[[c for c in columns if c in df.columns]] if not df.empty else df
            return lean_traces(df)
        cols = None if columns is None else [c for c in columns if c in self.columns]
        frames = [read_part(p, cols, predictor) for p in self.parts]
        frames = [f for f in frames if len(f)] or frames[:1]
        return _concat(frames)

    def scored(self, predictor: str, columns: Sequence[str]) -> pd.DataFrame:
        """The scored rows (:func:`~posbench.scoring.schema.scored_mask`) of ``predictor``
        with ``columns`` that exist, its text columns as categoricals, a fresh 0-based
        index."""
        cols = [c for c in columns if c in self.columns]
        if self._frame is not None:
            df = self._frame
            if df.empty:
                return pd.DataFrame(columns=cols)
            if self._keep is None:
                self._keep = scored_mask(df)
            mine = self._keep & (df["predictor"] == predictor).to_numpy()
            from posbench.scoring.records import lean_traces

            return lean_traces(df.loc[mine, cols])
        df = self.frame([*cols, *MASK_COLUMNS], predictor)
        if df.empty:
            return df[cols]
        return df.loc[scored_mask(df), cols].reset_index(drop=True)

    def per_predictor(
        self, predictors: Sequence[str], columns: Sequence[str], scored: bool = True
    ) -> Iterator[tuple[str, pd.DataFrame]]:
        """``(name, rows)`` per predictor, one at a time (:meth:`scored`, or every row with
        ``scored`` False)."""
        for name in predictors:
            yield name, self.scored(name, columns) if scored else self.frame(columns, name)

    def materialize(self) -> pd.DataFrame:
        """Every row and column in one frame (text columns as written): for small runs and
        for callers that need it all; on disk, this reads every part."""
        if self._frame is not None:
            return self._frame
        import pyarrow.parquet as pq

        return _concat([pq.read_table(p).to_pandas() for p in self.parts])

    def write(self, path: Path) -> Path | None:
        """Every row into one Parquet file ``path`` (one row group per part, a part at a time:
        memory bounded by the largest part); None when there are no rows."""
        if self.empty:
            return None
        if self._frame is not None:
            self._frame.to_parquet(path, index=False)
            return path
        import pyarrow.parquet as pq

        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        schema = pq.read_schema(self.parts[0])
        try:
            with pq.ParquetWriter(tmp, schema) as writer:
                for p in self.parts:
                    table = pq.read_table(p)
                    if table.num_rows:
                        writer.write_table(table.cast(schema))
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
        return path


def _concat(frames: list[pd.DataFrame]) -> pd.DataFrame:
    """Frames read from parts as one, with a fresh index; dictionary columns stay categorical
    (their categories united)."""
    if not frames:
        return pd.DataFrame()
    if len(frames) == 1:
        return frames[0].reset_index(drop=True)
    cats = [c for c in frames[0].columns if isinstance(frames[0][c].dtype, pd.CategoricalDtype)]
    if cats:
        from pandas.api.types import union_categoricals

        united = {
            c: union_categoricals([f[c] for f in frames], ignore_order=True).categories
            for c in cats
        }
        frames = [f.astype({c: pd.CategoricalDtype(united[c]) for c in cats}) for f in frames]
    return pd.concat(frames, ignore_index=True)
