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
    """A read table with its file and a way to name rows. A CSV is held whole (``df``, a pandas
    DataFrame); a Parquet file is read one column at a time (:meth:`column`), so that a long
    drive's table (millions of rows, most cells empty) is never held whole; ``df`` reads it
    whole where a caller wants that."""

    def __init__(
        self,
        path: Path,
        is_csv: bool,
        columns: list[str],
        n_rows: int,
        frame: pd.DataFrame | None = None,
        parquet: Any = None,
        stored_names: dict[str, str] | None = None,
    ) -> None:
        self.path = path
        self.is_csv = is_csv
        self.columns = columns  # stripped, lower-case
        self.n_rows = n_rows
        self._frame = frame
        self._parquet = parquet  # a pyarrow.parquet.ParquetFile
        self._stored = stored_names or {}  # lower-case name -> the name in the file

    @property
    def df(self) -> pd.DataFrame:
        """The whole table (read once, kept)."""
        if self._frame is None:
            import pandas as pd

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
            header = pd.read_csv(path, nrows=0).columns  # text columns by any case or spacing
            text = {c: str for c in header if str(c).strip().lower() in text_columns}
            df = pd.read_csv(path, skip_blank_lines=False, dtype=text, low_memory=False)
        except pd.errors.EmptyDataError:
            raise DataError(path, "empty file") from None
        except pd.errors.ParserError as e:
            raise DataError(path, _parser_error(str(e))) from None
        except UnicodeDecodeError as e:
            raise DataError(path, f"not a text CSV file: {e}") from None
        df.columns = [str(c).strip().lower() for c in df.columns]
        tab = TableFile(path, True, list(df.columns), len(df), frame=df)
    dup = sorted({c for c in tab.columns if tab.columns.count(c) > 1})
    if dup:
        raise DataError(path, f"duplicate columns: {', '.join(dup)}")
    return tab


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
