"""A run's trace parts on disk, read: one Parquet file per drive task, in row groups of one
predictor each (written by :mod:`posbench.scoring.part_writer`), read one predictor or drive
at a time (:func:`read_part`) or a row group at a time (:func:`read_part_groups`), what a
part holds told by its row groups' statistics (:func:`part_values`,
:func:`rows_per_value`), and frames read from several parts joined (:func:`concat_parts`).
The view over a run's traces, in memory or in parts, is
:class:`posbench.scoring.trace_set.TraceSet`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.scoring.schema import SCORED_BY

#: the text columns that aggregation and figures filter and group by, again and again: read
#: as categoricals (dictionary-encoded), small codes instead of strings
TEXT = ("dataset", "drive", "predictor")
#: what a ``keep`` of :func:`read_part` may read beside the columns asked for (it chooses
#: the scored rows: :func:`posbench.scoring.schema.scored_of`)
KEEP_READS = SCORED_BY


#: a choice of rows (:func:`read_part`'s ``keep``): called with a getter of columns (name ->
#: numpy array, None where there is no such column), it returns the mask of the rows to keep
Keep = Callable[[Callable[[str], np.ndarray | None]], np.ndarray]
#: a read of more rows than this in several row groups makes its choice of rows a row group
#: at a time (:func:`read_part`): what is held is one group's rows, not all of them
CHOOSE_BY_GROUP_ABOVE_ROWS = 1 << 16


def read_file(path: str | Path) -> pd.DataFrame:
    """A whole Parquet file as a frame, as ``pandas.read_parquet`` gives it, read through
    ``pyarrow.parquet.ParquetFile`` (``read_parquet`` goes through pyarrow's dataset layer,
    which keeps about 0.5 MB per file read: see :func:`read_part`)."""
    import pyarrow.parquet as pq

    with pq.ParquetFile(path) as pf:
        return pf.read(use_pandas_metadata=True).to_pandas()


def read_part(
    path: str | Path,
    columns: Sequence[str] | None = None,
    predictor: str | None = None,
    drive: str | None = None,
    keep: Keep | None = None,
    plain: bool = False,
) -> pd.DataFrame:
    """One part's rows (of ``predictor`` only, and of ``drive`` only, given them), its text
    columns as categoricals; given ``keep``, only the rows it keeps: called with a getter
    of the part's columns as numpy arrays (those asked for and :data:`KEEP_READS`; None for
    a column the part lacks), it returns the mask of the rows to keep, chosen before the
    rows become a frame; with ``plain`` as well, that frame is :func:`_plain_frame`'s.

    The row groups are chosen by their statistics (a part has one row group per predictor)
    and read directly; only a row group that holds several values is read whole and its
    rows filtered. (``pyarrow.parquet.read_table`` with filters goes through the dataset
    API, which keeps about 0.5 MB per file read: over the 384 parts of 64 drive hours,
    190 MB the process never gets back.)"""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = None if columns is None else list(dict.fromkeys(columns))
    wanted = {c: v for c, v in (("predictor", predictor), ("drive", drive)) if v is not None}
    with pq.ParquetFile(path, read_dictionary=[c for c in TEXT if cols is None or c in cols]) as pf:
        if not wanted and keep is None:
            return pf.read(columns=cols, use_pandas_metadata=True).to_pandas()
        groups, exact = _row_groups_of(pf.metadata, wanted)
        extra = [] if cols is None else [c for c in wanted if c not in cols and not exact]
        if keep is not None and cols is not None:
            have = pf.schema_arrow.names
            extra += [c for c in KEEP_READS if c in have and c not in cols]
        read = None if cols is None else [*cols, *extra]
        if not groups:  # no rows: the columns as the whole part types them (categories too)
            return pf.read(columns=cols, use_pandas_metadata=True).to_pandas().iloc[:0]
        table: Any = None
        chosen: Any = None
        many = len(groups) > 1 and _rows_in(pf.metadata, groups) > CHOOSE_BY_GROUP_ABOVE_ROWS
        if exact and keep is not None and many:  # many rows: chosen a row group at a time
            chosen = pa.concat_tables(
                [
                    _kept_rows(pf.read_row_group(g, columns=read, use_pandas_metadata=True), keep)
                    for g in groups
                ]
            )
        else:
            table = pf.read_row_groups(groups, columns=read, use_pandas_metadata=True)
    if exact and (keep is not None or plain):  # only the rows chosen become a frame
        if chosen is None:
            chosen = table if keep is None else _kept_rows(table, keep)
            del table
        chosen = chosen if cols is None else chosen.select(cols)
        return _plain_frame(chosen) if plain else chosen.to_pandas()
    df = table.to_pandas()
    del table
    if exact:
        return df
    mask = np.ones(len(df), dtype=bool)
    for c, v in wanted.items():
        mask &= (df[c] == v).to_numpy(dtype=bool)
    if keep is not None:
        mask &= keep(frame_columns(df))
    return df.loc[mask, cols if cols is not None else df.columns].reset_index(drop=True)


def read_part_groups(
    path: str | Path, columns: Sequence[str], predictor: str, drive: str
) -> Iterator[pd.DataFrame]:
    """One part's rows of ``predictor`` and ``drive`` a row group at a time, in order, text
    columns as categoricals: a part written by
    :class:`~posbench.scoring.part_writer.PartWriter` has row groups of one predictor of at
    most :data:`~posbench.scoring.part_writer.GROUP_ROWS` rows, so a drawing that sends each
    piece on holds no more than that. Where a row group holds other rows too, the part's
    rows at once (:func:`read_part`)."""
    import pyarrow.parquet as pq

    cols = list(dict.fromkeys(columns))
    with pq.ParquetFile(path, read_dictionary=[c for c in TEXT if c in cols]) as pf:
        groups, exact = _row_groups_of(pf.metadata, {"predictor": predictor, "drive": drive})
        if exact:
            for g in groups:
                yield pf.read_row_group(g, columns=cols, use_pandas_metadata=True).to_pandas()
            return
    yield read_part(path, cols, predictor, drive)


def _plain_frame(table: Any) -> pd.DataFrame:
    """An Arrow table as a frame of numpy columns, its dictionary columns as categoricals of
    plain ``str`` categories (``to_pandas`` builds each categorical's categories as a pandas
    string index, ~0.5 ms a column and read: the figures that read a run one drive at a time
    read thousands). Values the same; dtypes of text columns differ from ``to_pandas``'s."""
    import pyarrow as pa
    import pyarrow.compute as pc

    out: dict[str, Any] = {}
    for name, col in zip(table.column_names, table.columns, strict=True):
        arr = col.combine_chunks() if col.num_chunks != 1 else col.chunk(0)
        if pa.types.is_dictionary(arr.type):
            codes = pc.fill_null(arr.indices, -1).to_numpy(zero_copy_only=False)
            cats = pd.Index(arr.dictionary.to_pylist(), dtype=object)
            out[name] = pd.Categorical.from_codes(codes, dtype=pd.CategoricalDtype(cats))
        else:
            out[name] = arr.to_numpy(zero_copy_only=False)
    return pd.DataFrame(out, copy=False)


def _rows_in(meta: Any, groups: Sequence[int]) -> int:
    """How many rows the row ``groups`` of a part (its metadata) hold."""
    return sum(meta.row_group(g).num_rows for g in groups)


def _kept_rows(table: Any, keep: Keep) -> Any:
    """The rows of Arrow ``table`` that ``keep`` keeps."""
    return table.filter(keep(_arrow_columns(table)))


def frame_columns(df: pd.DataFrame) -> Callable[[str], np.ndarray | None]:
    """A getter of a frame's columns as numpy arrays (None: no such column), as a
    :data:`Keep` reads them."""
    return lambda c: df[c].to_numpy() if c in df.columns else None


def _arrow_columns(table: Any) -> Callable[[str], np.ndarray | None]:
    """A getter of an Arrow table's columns as numpy arrays (None: no such column)."""
    names = set(table.column_names)

    def column(name: str) -> np.ndarray | None:
        if name not in names:
            return None
        out: np.ndarray = table.column(name).to_numpy(zero_copy_only=False)
        return out

    return column


def _row_groups_of(meta: Any, wanted: dict[str, str]) -> tuple[list[int], bool]:
    """The row groups of a part (its metadata) that may hold rows with the ``wanted``
    values (column -> value), and whether every row of them does (each group's statistics
    say it holds that one value)."""
    names = meta.schema.names
    groups, exact = [], True
    for i in range(meta.num_row_groups):
        group = meta.row_group(i)
        holds_all = True
        for c, v in wanted.items():
            if c not in names:
                holds_all = False
                continue
            stats = group.column(names.index(c)).statistics
            one = single_value(stats)
            if one is not None and one != v:
                break  # a group of another value
            if one is None and stats is not None and stats.has_min_max:
                lo, hi = (
                    x.decode() if isinstance(x, bytes) else str(x) for x in (stats.min, stats.max)
                )
                if not lo <= v <= hi:
                    break
            holds_all = holds_all and one == v
        else:
            groups.append(i)
            exact = exact and holds_all
    return groups, exact


def part_values(path: Path, column: str) -> list[str]:
    """The values of text ``column`` in part ``path``, in the order they first appear: from
    each row group's statistics where they hold one value (a part has one row group per
    predictor, and one drive), else read from that row group's column alone."""
    import pyarrow.parquet as pq

    out: dict[str, None] = {}
    with pq.ParquetFile(path, read_dictionary=[column]) as pf:
        if column not in pf.schema_arrow.names:
            return []
        j = pf.metadata.schema.names.index(column)
        for i in range(pf.metadata.num_row_groups):
            value = single_value(pf.metadata.row_group(i).column(j).statistics)
            if value is not None:
                out[value] = None
            else:  # dictionary codes: cheap to read, one row group at a time
                col = pf.read_row_group(i, columns=[column]).column(0).to_pandas()
                out.update(dict.fromkeys(str(v) for v in pd.unique(col.dropna())))
    return list(out)


def rows_per_value(path: Path, column: str) -> dict[str, int] | None:
    """Rows per value of text ``column`` in part ``path``, from its row groups' statistics;
    None when a row group holds more than one value (or has no statistics)."""
    import pyarrow.parquet as pq

    out: dict[str, int] = {}
    meta = pq.ParquetFile(path).metadata
    names = meta.schema.names
    if column not in names:
        return None
    j = names.index(column)
    for i in range(meta.num_row_groups):
        group = meta.row_group(i)
        if group.num_rows == 0:
            continue
        value = single_value(group.column(j).statistics)
        if value is None:
            return None
        out[value] = out.get(value, 0) + group.num_rows
    return out


def single_value(stats: Any) -> str | None:
    """The one value a row group's column holds, from its statistics (pyarrow's
    ``Statistics``); None when it holds several or has no statistics."""
    if stats is None or not stats.has_min_max or stats.min != stats.max:
        return None
    v = stats.min
    return v.decode() if isinstance(v, bytes) else str(v)


def text_values(column: pd.Series, as_str: bool = False) -> np.ndarray:
    """A text column's values as a numpy object array. A categorical's are its categories
    taken by code, one shared string per category: pandas' own ``to_numpy()`` (and
    ``astype(str)``) builds a new string for every row of a ``str`` categorical, about 60
    bytes a row, which for a predictor's rows of a long run is tens of MB at a time.
    ``as_str``: the categories as ``str`` (as ``astype(str)`` gives them); missing values
    are NaN either way (as pandas 3's ``str`` columns keep them)."""
    if not isinstance(column.dtype, pd.CategoricalDtype):
        plain: np.ndarray = column.astype(str).to_numpy() if as_str else column.to_numpy()
        return plain
    cats = column.cat.categories
    values = [str(v) for v in cats] if as_str else list(cats)
    table = np.array([*values, np.nan], dtype=object)
    taken: np.ndarray = table[column.cat.codes.to_numpy()]  # code -1 (missing): last entry
    return taken


def category_index(column: pd.Series, table: Sequence[str]) -> np.ndarray:
    """Each row's value of text ``column`` as its index in ``table`` (-1: not in it, or
    missing); int16. A categorical's codes are mapped through its categories: no string
    per row."""
    if isinstance(column.dtype, pd.CategoricalDtype):
        index = {v: i for i, v in enumerate(table)}  # a few names: no pandas Index to build
        mapping = [index.get(str(c), -1) for c in column.cat.categories]
        out: np.ndarray = np.array([*mapping, -1], dtype=np.int16)[column.cat.codes.to_numpy()]
        return out
    found: np.ndarray = pd.Index(table).get_indexer(text_values(column, as_str=True))
    return found.astype(np.int16)


def concat_parts(frames: list[pd.DataFrame]) -> pd.DataFrame:
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


def join_pieces(pieces: Iterable[pd.DataFrame], capacity: int | None) -> pd.DataFrame:
    """Frames read from parts (``pieces``, in order) as one, the same frame that
    :func:`concat_parts` gives on their list, but written piece by piece into columns
    allocated once for at most ``capacity`` rows: at its peak it holds the joined columns
    and one piece, where joining a list holds every piece, a recoded copy of them and the
    result (about three times the frame: at 64 drive hours, 0.6 GB more for one predictor's
    scored rows). Rows past the ones written are never touched, so they cost no memory.
    A column whose type changes between pieces, an unknown ``capacity`` or more rows than
    it: the pieces are joined by :func:`concat_parts` instead (the same frame)."""
    it = iter(pieces)
    first = next(it, None)
    if first is None:
        return pd.DataFrame()
    if capacity is None or len(first) > capacity:
        return concat_parts([first, *it])
    buffers: dict[str, np.ndarray] = {}
    tables: dict[str, tuple[list[object], dict[object, int]]] = {}
    for name, col in first.items():
        if isinstance(col.dtype, pd.CategoricalDtype):
            buffers[str(name)] = np.empty(capacity, dtype=np.int32)
            tables[str(name)] = ([], {})
        else:
            buffers[str(name)] = np.empty(capacity, dtype=col.dtype)
    dtypes = first.dtypes
    kinds = _column_kinds(first)
    rows = 0
    piece: pd.DataFrame | None = first
    while piece is not None:
        if rows + len(piece) > capacity or _column_kinds(piece) != kinds:
            joined = _frame_of(buffers, tables, dtypes, rows)
            return concat_parts([joined, piece, *it])
        span = slice(rows, rows + len(piece))
        for name, col in piece.items():
            if str(name) in tables:
                table, index = tables[str(name)]
                cats = col.cat.categories
                recode = [index.setdefault(c, len(index)) for c in cats]
                table.extend(list(index)[len(table) :])
                mapping = np.array([*recode, -1], dtype=np.int32)
                buffers[str(name)][span] = mapping[col.cat.codes.to_numpy()]
            else:
                buffers[str(name)][span] = col.to_numpy()
        rows = span.stop
        piece = next(it, None)
    return _frame_of(buffers, tables, dtypes, rows)


def _column_kinds(frame: pd.DataFrame) -> list[tuple[str, object]]:
    """Each column's name and dtype, a categorical's as "category" whatever its categories."""
    return [
        (str(n), "category" if isinstance(t, pd.CategoricalDtype) else t)
        for n, t in frame.dtypes.items()
    ]


def _frame_of(
    buffers: dict[str, np.ndarray],
    tables: dict[str, tuple[list[object], dict[object, int]]],
    dtypes: pd.Series,
    rows: int,
) -> pd.DataFrame:
    """The first ``rows`` of :func:`join_pieces`' columns as a frame (views, not copies; a
    categorical's codes in pandas' own width)."""
    data: dict[str, Any] = {}
    for name, buffer in buffers.items():
        if name in tables:
            cats = pd.Index(tables[name][0], dtype=dtypes[name].categories.dtype)
            data[name] = pd.Categorical.from_codes(buffer[:rows], dtype=pd.CategoricalDtype(cats))
        else:
            data[name] = buffer[:rows]
    return pd.DataFrame(data, copy=False)
