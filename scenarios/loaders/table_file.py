"""Reading a CSV or Parquet file as a table whose rows are named as the user sees them.

:func:`read_table_file` reads the file (column names stripped and lower-cased, the named text
columns kept as text) into a :class:`TableFile`, which names a data row by its CSV line
(header = line 1) or its 1-based Parquet row; :func:`numeric_column` reads a column as
float64. Every problem is a :class:`~posbench.scenarios.errors.DataError` naming the file
and, where there is one, the line and column. Used by the drive tables
(:mod:`posbench.scenarios.loaders.table`) and by the offline answers files.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from posbench.scenarios.errors import DataError

if TYPE_CHECKING:  # pandas is imported when a table is read
    import pandas as pd


class TableFile:
    """A read table (``df``, a pandas DataFrame) with its file and a way to name rows."""

    def __init__(self, path: Path, df: pd.DataFrame, is_csv: bool) -> None:
        self.path = path
        self.df = df
        self.is_csv = is_csv

    def where(self, i: int) -> str:
        """Name data row ``i`` (0-based) as the user sees it."""
        return f"line {i + 2}" if self.is_csv else f"row {i + 1}"


def read_table_file(path: Path, text_columns: tuple[str, ...] = ("stream",)) -> TableFile:
    """Read a CSV (``text_columns``, named in lower case, kept as text) or Parquet file; column
    names stripped and lower-cased. Raises :class:`DataError` (naming the file and the line) when it
    is missing, empty, damaged or has duplicate columns."""
    import pandas as pd

    if not path.is_file():
        raise DataError(path, "file missing")
    if path.stat().st_size == 0:
        raise DataError(path, "empty file")
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        try:
            df = pd.read_parquet(path)
        except Exception as e:  # pyarrow raises several types for damaged files
            raise DataError(path, f"cannot read Parquet: {str(e).splitlines()[0]}") from None
        is_csv = False
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
        is_csv = True
    df.columns = [str(c).strip().lower() for c in df.columns]
    dup = sorted({c for c in df.columns if list(df.columns).count(c) > 1})
    if dup:
        raise DataError(path, f"duplicate columns: {', '.join(dup)}")
    return TableFile(path, df, is_csv)


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

    s = tab.df[col]
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
