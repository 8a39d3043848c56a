"""A run's trace parts on disk: one Parquet file per drive task (:func:`write_part`, one row
group per predictor), read one predictor or drive at a time (:func:`read_part`), what a part
holds told by its row groups' statistics (:func:`part_values`, :func:`rows_per_value`), and
frames read from several parts joined (:func:`concat_parts`). The view over a run's traces,
in memory or in parts, is :class:`posbench.scoring.trace_set.TraceSet`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

#: the text columns that aggregation and figures filter and group by, again and again: read
#: as categoricals (dictionary-encoded), small codes instead of strings
TEXT = ("dataset", "drive", "predictor")


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
    path: str | Path,
    columns: Sequence[str] | None = None,
    predictor: str | None = None,
    drive: str | None = None,
) -> pd.DataFrame:
    """One part's rows (of ``predictor`` only, and of ``drive`` only, given them), its text
    columns as categoricals."""
    import pyarrow.parquet as pq

    cols = None if columns is None else list(dict.fromkeys(columns))
    wanted = (("predictor", predictor), ("drive", drive))
    filters = [(c, "==", v) for c, v in wanted if v is not None] or None
    table = pq.read_table(
        path,
        columns=cols,
        filters=filters,
        read_dictionary=[c for c in TEXT if cols is None or c in cols],
    )
    return table.to_pandas()


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
