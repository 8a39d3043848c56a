"""A run's traces where they are: in memory (one frame) or on disk (one Parquet part per drive
task, written by the worker that replayed it), read one predictor or one drive at a time.

``bench run`` keeps no drive's answers in the process that combines the figures: each worker
writes its drive's traces as a part (:mod:`posbench.scoring.trace_parts`: one row group per
predictor) and returns a :class:`~posbench.scoring.records.DriveRun` that names the part.
Aggregation, the figures and the saved run then read from the parts only the rows and
columns they need (:meth:`TraceSet.scored`, :meth:`TraceSet.frame`), so what the combining
process holds is one predictor's columns, never every answer of the run. A frame in memory
(``bench score``, a notebook, the tests) answers the same calls, with the same rows in the
same order: the figures do not depend on where the traces are.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from posbench.scoring.schema import SCORED_BY, scored_mask, scored_of
from posbench.scoring.trace_parts import (
    TEXT,
    Keep,
    concat_parts,
    frame_columns,
    join_pieces,
    part_values,
    read_part,
    read_part_groups,
    rows_per_value,
)

#: what :func:`posbench.scoring.schema.scored_mask` reads
MASK_COLUMNS = SCORED_BY
#: on disk, a predictor with at most this many rows (~30 min of drives at 20 queries/s;
#: ~25 bytes a row and column, ~10 MB) is read once, every column, and held for the reads
#: of it that follow (aggregation reads a predictor's rows for each figure family): a small
#: run's reads cost one pass over the parts, not one per family. A larger predictor is read
#: from the parts each time, so what is held never grows with drive hours.
HOLD_ROWS = 50_000
#: how many predictors' rows are held at most (a predictor, its baseline and cv)
HOLD_PREDICTORS = 3


def as_trace_set(traces: TraceSet | pd.DataFrame) -> TraceSet:
    """``traces`` as a :class:`TraceSet` (a frame is wrapped, not copied)."""
    return traces if isinstance(traces, TraceSet) else TraceSet(traces)


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
        #: per part, its drives in order (read once, for :meth:`drives` and drive reads)
        self._part_drives: list[list[str]] | None = None
        #: in memory: the drive column's codes and names (:func:`pandas.factorize`, once)
        self._drive_codes: tuple[np.ndarray, list[str]] | None = None
        #: on disk: rows per predictor of the parts looked at so far, by part index (None: a
        #: row group holds several predictors)
        self._part_counts: dict[int, dict[str, int] | None] = {}
        #: on disk: predictors found too large to hold, or in parts that cannot say
        self._not_held: set[str] = set()
        #: on disk: small predictors' rows, read once (:data:`HOLD_ROWS`), last used last
        self._held: dict[str, pd.DataFrame] = {}

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
        self,
        columns: Sequence[str] | None = None,
        predictor: str | None = None,
        drive: str | None = None,
        rows: Keep | None = None,
    ) -> pd.DataFrame:
        """Rows (of ``predictor`` only, and of ``drive`` only, given them) with ``columns``
        (None: all), text columns as categoricals. On disk, this reads them: ask for what
        you need (a drive's rows are read from the parts that hold it only). ``rows``: only
        the rows it keeps, chosen before they become a frame (called with a getter of the
        columns asked for as numpy arrays, text as ``str``; :func:`read_part`)."""
        if self._frame is not None:
            df = self._frame
            if df.empty and df.columns.empty:  # no traces at all: the columns asked for
                return pd.DataFrame(columns=list(columns or []))
            keep = None
            if predictor is not None and not df.empty:
                keep = (df["predictor"] == predictor).to_numpy()
            if drive is not None and not df.empty:
                codes, names = self._codes()
                mine = codes == (names.index(drive) if drive in names else -2)
                keep = mine if keep is None else keep & mine
            if keep is not None:
                df = df.loc[keep]
            if columns is not None:
                df = df[_present(columns, df.columns)] if not df.empty else df
            return lean_traces(df if rows is None else _kept(df, rows))
        if predictor is not None and drive is None:
            held = self._held_rows(predictor)
            if held is not None:  # a new frame: the caller may add columns to it
                if rows is not None:
                    held = _kept(held, rows)
                if columns is None:
                    return held.copy(deep=False)
                return held[_present(columns, held.columns)]
        cols = None if columns is None else _present(columns, self.columns)
        parts = self.parts
        if drive is not None:
            parts = self.parts_with(drive) or self.parts[:1]
        bound = self.row_bound(predictor) if predictor is not None and drive is None else None
        read = (read_part(p, cols, predictor, drive, keep=rows) for p in parts)
        joined = join_pieces((f for f in read if len(f)), bound)
        if joined.columns.empty and parts:  # no rows: the first part's columns, empty
            return read_part(parts[0], cols, predictor, drive).reset_index(drop=True).iloc[:0]
        return joined

    def _held_rows(self, predictor: str) -> pd.DataFrame | None:
        """On disk: ``predictor``'s rows, every column, in memory, when it has at most
        :data:`HOLD_ROWS` (read once, then held; see there); else None."""
        if predictor in self._held:
            self._held[predictor] = self._held.pop(predictor)  # last used last
            return self._held[predictor]
        if predictor in self._not_held:
            return None
        n, parts = 0, []
        for i, path in enumerate(self.parts):  # until the rows exceed HOLD_ROWS, no further
            counts = self._part_count(i)
            if counts is None or n + counts.get(predictor, 0) > HOLD_ROWS:
                self._not_held.add(predictor)
                return None
            if predictor in counts:
                n += counts[predictor]
                parts.append(path)
        if n == 0:
            self._not_held.add(predictor)
            return None
        held = concat_parts([read_part(p, None, predictor) for p in parts])
        self._held[predictor] = held
        while len(self._held) > HOLD_PREDICTORS:
            del self._held[next(iter(self._held))]
        return held

    def row_bound(self, predictor: str) -> int | None:
        """How many rows ``predictor`` has (its scored rows are at most these), from the
        parts' row groups without reading them (or counted in a frame in memory); None
        where a part's row group holds several predictors."""
        if self._frame is not None:
            if self._frame.empty:
                return 0
            return int((self._frame["predictor"] == predictor).sum())
        n = 0
        for i in range(len(self.parts)):
            counts = self._part_count(i)
            if counts is None:
                return None
            n += counts.get(predictor, 0)
        return n

    def _part_count(self, i: int) -> dict[str, int] | None:
        """Rows per predictor of part ``i`` (:func:`rows_per_value`, read once)."""
        if i not in self._part_counts:
            self._part_counts[i] = rows_per_value(self.parts[i], "predictor")
        return self._part_counts[i]

    def predictors(self) -> list[str]:
        """The predictors, in the order they first appear (the run's order)."""
        if self._frame is not None:
            df = self._frame
            return [] if df.empty else [str(p) for p in pd.unique(df["predictor"])]
        return list(dict.fromkeys(v for p in self.parts for v in part_values(p, "predictor")))

    def drives(self) -> list[str]:
        """The drives, in the order they first appear (drive order)."""
        if self._frame is not None:
            return [] if self._frame.empty else list(self._codes()[1])
        return list(dict.fromkeys(d for ds in self._drives_per_part() for d in ds))

    def parts_with(self, drive: str) -> tuple[Path, ...]:
        """On disk: the parts that hold rows of ``drive``, in order."""
        held = self._drives_per_part()
        return tuple(p for p, ds in zip(self.parts, held, strict=True) if drive in ds)

    def _codes(self) -> tuple[np.ndarray, list[str]]:
        """In memory: each row's drive as a code into the drive names (in order)."""
        if self._drive_codes is None:
            assert self._frame is not None
            codes, names = pd.factorize(self._frame["drive"])
            self._drive_codes = (np.asarray(codes), [str(n) for n in names])
        return self._drive_codes

    def _drives_per_part(self) -> list[list[str]]:
        """Per part, the drives it holds, in order."""
        if self._part_drives is None:
            self._part_drives = [part_values(p, "drive") for p in self.parts]
        return self._part_drives

    def scored(self, predictor: str, columns: Sequence[str]) -> pd.DataFrame:
        """The scored rows (:func:`~posbench.scoring.schema.scored_mask`) of ``predictor``
        with ``columns`` that exist (all of them when there are no traces at all), its text
        columns as categoricals."""
        cols = [c for c in columns if c in self.columns]
        if self._frame is not None:
            df = self._frame
            if df.empty:
                return pd.DataFrame(columns=list(columns) if df.columns.empty else cols)
            if self._keep is None:
                self._keep = scored_mask(df)
            mine = self._keep & (df["predictor"] == predictor).to_numpy()
            return lean_traces(df.loc[mine, cols])
        if self._held_rows(predictor) is not None:
            df = self.frame([*cols, *MASK_COLUMNS], predictor)
            return df[cols] if df.empty else df.loc[scored_mask(df), cols].reset_index(drop=True)
        # each part's rows filtered as it is read: what is held at once is the scored rows
        # (and one part's), not every row of the predictor and then a copy of the scored
        joined = join_pieces(self.pieces(predictor, cols), self.row_bound(predictor))
        if joined.columns.empty and self.parts:  # none: the first part's columns, empty
            empty = read_part(self.parts[0], [*cols, *MASK_COLUMNS], predictor)
            return _scored_rows(empty, cols).reset_index(drop=True)
        return joined

    def pieces(
        self, predictor: str, columns: Sequence[str], scored: bool = True, plain: bool = False
    ) -> Iterator[pd.DataFrame]:
        """``predictor``'s rows in pieces, in their order: its scored rows (:meth:`scored`),
        or with ``scored`` False every row (:meth:`frame`). On disk, one part's rows at a
        time (a predictor held in memory, and a frame in memory, as one piece; parts without
        a row of it yield none), for figures that reduce each piece to a little (a drawing's
        curve) and need never hold them all. Pieces may differ in a text column's
        categories; ``plain``: on disk, text columns as categoricals of plain ``str``
        categories (:func:`~posbench.scoring.trace_parts.read_part`'s ``plain``: cheaper,
        for figures that read the values only)."""
        if self._frame is not None or self._held_rows(predictor) is not None:
            yield self.scored(predictor, columns) if scored else self.frame(columns, predictor)
            return
        cols = _present(columns, self.columns)
        for path in self.parts:
            if scored:  # the scored rows chosen in Arrow, before they become a frame
                rows = read_part(path, cols, predictor, keep=scored_of, plain=plain)
            else:
                rows = read_part(path, cols, predictor, plain=plain)
            if len(rows):
                yield rows.reset_index(drop=True)

    def drive_pieces(
        self, predictor: str, columns: Sequence[str], scored: bool = True
    ) -> Iterator[pd.DataFrame]:
        """:meth:`pieces` cut at every change of drive: one drive's rows a piece, on disk
        and in memory alike (a frame in memory, or a predictor held, is one piece of many
        drives), for figures summed per drive that must not depend on where the traces
        are."""
        cols = list(dict.fromkeys([*columns, "drive"]))
        for rows in self.pieces(predictor, cols, scored, plain=True):
            if rows.empty:
                continue
            drive = rows["drive"]
            codes = (
                drive.cat.codes.to_numpy()
                if isinstance(drive.dtype, pd.CategoricalDtype)
                else pd.factorize(drive)[0]
            )
            cuts = np.flatnonzero(codes[1:] != codes[:-1]) + 1
            if cuts.size == 0:
                yield rows
                continue
            for a, b in zip([0, *cuts.tolist()], [*cuts.tolist(), len(rows)], strict=True):
                yield rows.iloc[a:b]

    def drive_rows(
        self, drive: str, predictor: str, columns: Sequence[str]
    ) -> Iterator[pd.DataFrame]:
        """``predictor``'s rows of ``drive`` in pieces, in their order: on disk a row group
        at a time (:func:`~posbench.scoring.trace_parts.read_part_groups`), in memory one
        piece; for drawings that send each piece on and need never hold a long drive's
        rows."""
        if self._frame is not None:
            yield self.frame(columns, predictor, drive)
            return
        cols = _present(columns, self.columns)
        for path in self.parts_with(drive):
            for rows in read_part_groups(path, cols, predictor, drive):
                if len(rows):
                    yield rows

    def materialize(self) -> pd.DataFrame:
        """Every row and column in one frame (text columns as written): for small runs and
        for callers that need it all; on disk, this reads every part."""
        if self._frame is not None:
            return self._frame
        import pyarrow.parquet as pq

        return concat_parts([pq.read_table(p).to_pandas() for p in self.parts])

    def write(self, path: Path) -> Path | None:
        """Every row into one Parquet file ``path``; None when there are no rows. From parts,
        their row groups as they are, one at a time (one drive's rows of one predictor
        each, at most :data:`~posbench.scoring.part_writer.GROUP_ROWS` rows: memory bounded
        by a row group, and a saved run's reads of one predictor or drive choose its row
        groups by their statistics)."""
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
                    with pq.ParquetFile(p) as part:
                        for g in range(part.num_row_groups):
                            table = part.read_row_group(g)
                            if table.num_rows:
                                writer.write_table(table.cast(schema))
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
        return path


def _scored_rows(rows: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    """The scored rows of ``rows`` (:func:`~posbench.scoring.schema.scored_mask`), ``columns``
    only."""
    return rows[columns] if rows.empty else rows.loc[scored_mask(rows), columns]


def _present(columns: Sequence[str], have: Iterable[object]) -> list[str]:
    """``columns`` that are in ``have``, in their order, each once."""
    present = set(have)
    return list(dict.fromkeys(c for c in columns if c in present))


def lean_traces(traces: pd.DataFrame) -> pd.DataFrame:
    """``traces`` with its :data:`TEXT` columns as categoricals (the same values), for
    aggregation and the figures: every row filter then copies small integer codes instead
    of strings (on the shared data ~0.5-0.9 CPU-s less aggregation and ~0.2-0.3 less per
    figure process; results and files the same to the bit). Saved traces keep their text
    columns."""
    cols = {
        c: "category"
        for c in TEXT
        if c in traces.columns and not isinstance(traces[c].dtype, pd.CategoricalDtype)
    }
    return traces.astype(cols) if cols else traces


def _kept(df: pd.DataFrame, rows: Keep) -> pd.DataFrame:
    """The rows of ``df`` that ``rows`` keeps (its text columns given as ``str`` values)."""
    return df.loc[np.asarray(rows(frame_columns(df)), dtype=bool)]
