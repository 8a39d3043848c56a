"""Reading a CSV or Parquet file as a table whose rows are named as the user sees them.

:func:`read_table_file` reads a CSV file (column names stripped and lower-cased, the named
text columns kept as text), or opens a Parquet file to be read one column at a time, as a
:class:`TableFile`, which names a data row by its CSV line (header = line 1) or its 1-based
Parquet row; :func:`numeric_column` reads a column as float64. Every problem is a
:class:`~posbench.scenarios.errors.DataError` naming the file and, where there is one, the
line and column. Used by the drive tables (:mod:`posbench.scenarios.loaders.table`) and by
the offline answers files.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from posbench.scenarios.errors import DataError

if TYPE_CHECKING:  # pandas is imported when a table is read
    import pandas as pd


class TableFile:
    """A read table with its file and a way to name rows. A CSV is held as its columns (read in
    chunks of rows); a Parquet file is read one column at a time (:meth:`column`), so that a
    long drive's table (millions of rows, most cells empty) is never held whole; ``df`` is
    the whole table where a caller wants that."""

    def __init__(
        self,
        path: Path,
        is_csv: bool,
        columns: list[str],
        n_rows: int,
        series: dict[str, pd.Series] | None = None,
        parquet: Any = None,
        stored_names: dict[str, str] | None = None,
    ) -> None:
        self.path = path
        self.is_csv = is_csv
        self.columns = columns  # stripped, lower-case
        self.n_rows = n_rows
        self._series = series
        self._frame: pd.DataFrame | None = None
        self._parquet = parquet  # a pyarrow.parquet.ParquetFile
        self._stored = stored_names or {}  # lower-case name -> the name in the file

    @property
    def df(self) -> pd.DataFrame:
        """The whole table (read once, kept)."""
        if self._frame is None:
            import pandas as pd

            if self._series is not None:
                self._frame = pd.DataFrame(self._series)
                return self._frame
            try:
                df = pd.read_parquet(self.path)
            except Exception as e:  # pyarrow raises several types for damaged files
                raise DataError(self.path, _parquet_error(e)) from None
            df.columns = [str(c).strip().lower() for c in df.columns]
            self._frame = df
        return self._frame

    def column(self, name: str) -> pd.Series:
        """Column ``name`` (stripped, lower-case) as a pandas Series; a Parquet file's text
        columns as categoricals."""
        if self._series is not None:
            return self._series[name]
        if self._frame is not None or self._parquet is None:
            return self.df[name]
        try:
            arr = self._parquet.read(columns=[self._stored[name]], use_threads=False).column(0)
        except Exception as e:  # a damaged column chunk
            raise DataError(self.path, _parquet_error(e)) from None
        out = arr.to_pandas()
        del arr
        import pyarrow as pa

        pa.default_memory_pool().release_unused()  # the column's buffers back to the system
        return out

    def release(self, name: str) -> None:
        """Let column ``name`` go where it is held (a CSV's): its reader is done with it."""
        if self._series is not None and self._frame is None:
            self._series.pop(name, None)

    def where(self, i: int) -> str:
        """Name data row ``i`` (0-based) as the user sees it."""
        return f"line {i + 2}" if self.is_csv else f"row {i + 1}"


def read_table_file(path: Path, text_columns: tuple[str, ...] = ("stream",)) -> TableFile:
    """Read a CSV (``text_columns``, named in lower case, kept as text) or open a Parquet file
    (its columns read when asked for, ``text_columns`` as categoricals); column names stripped
    and lower-cased. Raises :class:`DataError` (naming the file and the line) when it is
    missing, empty, damaged or has duplicate columns."""
    import pandas as pd

    if not path.is_file():
        raise DataError(path, "file missing")
    if path.stat().st_size == 0:
        raise DataError(path, "empty file")
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        tab = _open_parquet(path, text_columns)
    else:
        try:
            names, series = _read_csv_columns(path, text_columns)
        except pd.errors.EmptyDataError:
            raise DataError(path, "empty file") from None
        except pd.errors.ParserError as e:
            raise DataError(path, _parser_error(str(e))) from None
        except UnicodeDecodeError as e:
            raise DataError(path, f"not a text CSV file: {e}") from None
        n_rows = len(next(iter(series.values()))) if series else 0
        tab = TableFile(path, True, names, n_rows, series=series)
    dup = sorted({c for c in tab.columns if tab.columns.count(c) > 1})
    if dup:
        raise DataError(path, f"duplicate columns: {', '.join(dup)}")
    return tab


#: CSV rows parsed at a time: the parser's working memory is a chunk's, not the file's
CSV_CHUNK_ROWS = 1 << 18


def _read_csv_columns(
    path: Path, text_columns: tuple[str, ...]
) -> tuple[list[str], dict[str, pd.Series]]:
    """A CSV file's column names (stripped, lower-case, in file order, duplicates kept) and its
    columns as pandas infers them for the whole file, parsed :data:`CSV_CHUNK_ROWS` rows at a
    time (``text_columns`` kept as text), each filled into an array sized for the file: the
    file is held once, as its columns."""
    import pandas as pd

    header = pd.read_csv(path, nrows=0).columns  # text columns by any case or spacing
    names = [str(c).strip().lower() for c in header]
    if len(set(names)) < len(names):
        return names, {}  # refused by the caller: duplicate columns
    text = {c: str for c in header if str(c).strip().lower() in text_columns}
    capacity = _line_count(path)
    cols = {n: _Column(capacity) for n in names}
    with pd.read_csv(path, skip_blank_lines=False, dtype=text, chunksize=CSV_CHUNK_ROWS) as rd:
        for chunk in rd:
            for stored, name in zip(chunk.columns, names, strict=True):
                cols[name].add(chunk[stored])
    return names, {n: cols.pop(n).series() for n in names}


def _line_count(path: Path) -> int:
    """The file's newlines, plus one: at least its data rows."""
    n = 1
    with path.open("rb") as f:
        while buf := f.read(1 << 24):
            n += buf.count(b"\n")
    return n


class _Column:
    """One CSV column, chunk by chunk: numbers (and object cells) into one array sized for the
    whole file, widened as pandas would widen the whole file's column (int and float to
    float, booleans beside anything else to object); a text column as its pieces."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.arr: np.ndarray | None = None
        self.n = 0
        self.pieces: list[pd.Series] = []

    def add(self, col: pd.Series) -> None:
        import pandas as pd

        if self.pieces or not isinstance(col.dtype, np.dtype):
            if self.arr is not None:  # numbers so far, text from here: those as a piece
                self.pieces.append(pd.Series(self.arr[: self.n]))
                self.arr = None
            self.pieces.append(col.reset_index(drop=True))
            return
        vals = col.to_numpy()
        if self.arr is None:
            self.capacity = max(self.capacity, vals.size)
            self.arr = np.empty(self.capacity, dtype=vals.dtype)
        elif vals.dtype != self.arr.dtype or self.n + vals.size > self.capacity:
            # wider, or longer than the newlines said (lines that end in a lone CR)
            kinds = {vals.dtype.kind, self.arr.dtype.kind}
            wide = object if len(kinds) > 1 and "b" in kinds else np.result_type(self.arr, vals)
            if self.n + vals.size > self.capacity:
                self.capacity = max(2 * self.capacity, self.n + vals.size)
            wider = np.empty(self.capacity, dtype=wide)
            wider[: self.n] = self.arr[: self.n]
            self.arr = wider
        self.arr[self.n : self.n + vals.size] = vals
        self.n += vals.size

    def series(self) -> pd.Series:
        import pandas as pd

        if self.pieces:
            return pd.concat(self.pieces, ignore_index=True)
        return pd.Series(self.arr[: self.n] if self.arr is not None else np.empty(0), copy=False)


def _open_parquet(path: Path, text_columns: tuple[str, ...]) -> TableFile:
    """A Parquet file's schema and row count; its data columns only (a stored pandas index is
    the frame's index, not a column, as pandas reads it)."""
    import pyarrow.parquet as pq

    try:
        schema = pq.read_schema(path)
        index = {
            c for c in (schema.pandas_metadata or {}).get("index_columns", []) if isinstance(c, str)
        }
        stored = [n for n in schema.names if n not in index]
        text = [n for n in stored if n.strip().lower() in text_columns]
        pf = pq.ParquetFile(path, read_dictionary=text)
        n_rows = pf.metadata.num_rows
    except Exception as e:  # pyarrow raises several types for damaged files
        raise DataError(path, _parquet_error(e)) from None
    names = [n.strip().lower() for n in stored]
    return TableFile(
        path, False, names, n_rows, parquet=pf, stored_names=dict(zip(names, stored, strict=True))
    )


def _parquet_error(e: Exception) -> str:
    return f"cannot read Parquet: {str(e).splitlines()[0] if str(e) else type(e).__name__}"


def _parser_error(msg: str) -> str:
    """Turn a pandas ParserError into 'line N: ...' (file line numbers, header = 1)."""
    msg = msg.strip().replace("Error tokenizing data. C error: ", "")
    m = re.search(r"in line (\d+), saw (\d+)", msg)
    if m:
        exp = re.search(r"Expected (\d+) fields", msg)
        n_exp = exp.group(1) if exp else "?"
        return (
            f"line {m.group(1)}: malformed CSV, expected {n_exp} fields, saw {m.group(2)} "
            "(truncated or damaged file?)"
        )
    m = re.search(r"starting at row (\d+)", msg)
    if m:  # pandas counts rows from 0 including the header
        return f"line {int(m.group(1)) + 1}: malformed CSV, quoted field never closed ({msg})"
    return f"malformed CSV: {msg}"


def numeric_column(tab: TableFile, col: str) -> np.ndarray:
    """Column ``col`` as float64 (empty cells NaN); :class:`DataError` naming the first
    non-numeric cell."""
    import pandas as pd

    s = tab.column(col)
    if pd.api.types.is_bool_dtype(s.dtype):
        raise DataError(tab.path, f"column {col!r}: booleans, expected numbers")
    if pd.api.types.is_numeric_dtype(s.dtype):
        return s.to_numpy(dtype=np.float64, na_value=np.nan)
    txt = s.astype("string").str.strip()
    num = pd.to_numeric(txt, errors="coerce")
    bad = num.isna() & txt.notna() & (txt != "")
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise DataError(tab.path, f"{tab.where(i)}, column {col!r}: not a number: {s.iloc[i]!r}")
    return num.to_numpy(dtype=np.float64, na_value=np.nan)
