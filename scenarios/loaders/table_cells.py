"""A drive table's cells, read and checked one column at a time (the table of
:mod:`posbench.scenarios.loaders.table`): each row's stream, each stream's rows and its cells
of the columns it uses, its times. Every bad cell is a :class:`DataError` naming its line
(CSV) or row (Parquet) and column, and how many such rows there are in all."""

from __future__ import annotations

import numpy as np

from posbench.scenarios.drive import MAX_POSITION_M
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.table_file import TableFile, numeric_column

STREAMS = ("gps", "imu", "speed", "truth")
NUMERIC = ("t", "t_ns", "lat", "lon", "x", "y", "accuracy", "ax", "ay", "yaw", "yaw_rate", "v")
KNOWN = ("stream", *NUMERIC)
REQUIRED = {"imu": ("ax", "ay"), "speed": ("v",)}
#: the columns each stream takes from its rows (the times apart)
USES = {
    "gps": ("lat", "lon", "x", "y", "accuracy"),
    "imu": ("ax", "ay", "yaw", "yaw_rate"),
    "speed": ("v",),
    "truth": ("lat", "lon", "x", "y", "yaw", "v", "accuracy"),
}
#: a stream's rows (indices into the table, in file order) and its cells of each column it
#: uses: ``cells[(stream, column)]``
Cells = dict[tuple[str, str], np.ndarray]


def stream_times(
    tab: TableFile, keep: np.ndarray, rows: dict[str, np.ndarray]
) -> tuple[dict[str, np.ndarray], float]:
    """Each stream's times [s] relative to the earliest kept row, and that row's absolute
    time [s].

    An integer ``t_ns`` column is differenced in int64 so Unix-epoch stamps keep ns
    precision (a ``t_ns`` column with empty cells is read as float: ~0.4 us steps).
    """
    import pandas as pd

    col = "t_ns" if "t_ns" in tab.columns else "t"
    if col == "t_ns":
        s = tab.column(col)
        if pd.api.types.is_integer_dtype(s.dtype):
            ns = s.to_numpy(dtype=np.int64)
            ns0 = int(ns[keep].min())
            return {k: (ns[r] - ns0).astype(np.float64) / 1e9 for k, r in rows.items()}, ns0 / 1e9
        t = numeric_column(tab, col) / 1e9
    else:
        t = numeric_column(tab, col)
    missing = ~np.isfinite(t) & keep
    if np.any(missing):  # named as need_cells names them (the kept rows' index built only here)
        need_cells(tab, np.flatnonzero(keep), missing[keep], col)
    t0 = float(t[keep].min())
    return {k: t[r] - t0 for k, r in rows.items()}, t0


def need_cells(
    tab: TableFile, rows: np.ndarray, missing: np.ndarray, col: str, what: str = ""
) -> None:
    if np.any(missing):
        i = int(rows[np.flatnonzero(missing)[0]])
        extra = f" (required for {what} rows)" if what else ""
        raise DataError(
            tab.path,
            f"{tab.where(i)}, column {col!r}: missing or non-finite "
            f"value{extra}; {int(missing.sum())} such rows in all",
        )


def _blank_rows(tab: TableFile) -> np.ndarray:
    """Rows with every cell empty (a blank CSV line), one column at a time (done at the first
    column with no empty cell, usually ``stream``)."""
    blank = np.ones(tab.n_rows, dtype=bool)
    for c in sorted(tab.columns, key=lambda c: c != "stream"):
        blank &= tab.column(c).isna().to_numpy()
        if not blank.any():
            break
    return blank


def stream_codes(tab: TableFile, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(each row's index into :data:`STREAMS`, -1 for none; mask of rows kept); blank CSV
    lines are dropped with a warning."""
    import pandas as pd

    blank = _blank_rows(tab)
    if blank.any():
        warnings.append(f"table: dropped {int(blank.sum())} blank lines")
    if "stream" not in tab.columns:
        warnings.append("table: no 'stream' column, every row read as a GPS fix")
        return np.zeros(tab.n_rows, dtype=np.int8), ~blank
    # each distinct value cleaned once, the rows sharing its code (a long drive has millions
    # of rows and a handful of streams)
    stream = tab.column("stream")
    codes, uniques = pd.factorize(stream)
    cleaned = pd.Series(np.asarray(uniques, dtype=object), dtype=object)
    cleaned = cleaned.astype("string").str.strip().str.lower().fillna("")
    index = {s: i for i, s in enumerate(STREAMS)}
    lookup = np.array([*(index.get(v, -1) for v in cleaned), -1], dtype=np.int8)
    found = lookup[codes]  # missing (code -1): the last entry, -1
    unknown = (found < 0) & ~blank
    if unknown.any():
        i = int(np.flatnonzero(unknown)[0])
        raise DataError(
            tab.path,
            f"{tab.where(i)}, column 'stream': unknown stream "
            f"{stream.iloc[i]!r} (expected one of "
            f"{', '.join(STREAMS)}); {int(unknown.sum())} such rows",
        )
    return found, ~blank


def check_columns(tab: TableFile, present_streams: set[str]) -> None:
    cols = set(tab.columns)
    missing: list[str] = []
    if not ({"t", "t_ns"} & cols):
        missing.append("t (or t_ns)")
    for s in ("imu", "speed"):
        if s in present_streams:
            missing += [f"{c} (for {s} rows)" for c in REQUIRED[s] if c not in cols]
    pos = present_streams & {"gps", "truth"}
    if pos and not ({"lat", "lon"} <= cols or {"x", "y"} <= cols):
        missing.append(f"lat and lon, or x and y (for {' and '.join(sorted(pos))} rows)")
    if missing:
        raise DataError(tab.path, f"missing required column(s): {'; '.join(missing)}")


def _refuse_infinite(tab: TableFile, keep: np.ndarray, c: str, v: np.ndarray) -> None:
    """Refuse an infinite cell in numeric column ``c`` (an empty cell means "not given"; no
    value is infinite), naming its line."""
    inf = np.isinf(v) & keep
    if np.any(inf):
        i = int(np.flatnonzero(inf)[0])
        raise DataError(
            tab.path,
            f"{tab.where(i)}, column {c!r}: infinite value {float(v[i])!r}; "
            f"{int(inf.sum())} such row{'s' * (int(inf.sum()) != 1)} in all",
        )


def _refuse_far(tab: TableFile, keep: np.ndarray, c: str, v: np.ndarray) -> None:
    """Refuse an x or y cell farther than :data:`~posbench.scenarios.drive.MAX_POSITION_M`
    from the origin (no vehicle can be there), naming its line."""
    far = (np.abs(v) > MAX_POSITION_M) & keep
    if np.any(far):
        i = int(np.flatnonzero(far)[0])
        n = int(far.sum())
        raise DataError(
            tab.path,
            f"{tab.where(i)}, column {c!r}: {float(v[i]):g} m is no position: more "
            f"than {MAX_POSITION_M:g} m from the origin, farther than any point on Earth; "
            f"{n} such row{'s' * (n != 1)} in all",
        )


def stream_cells(tab: TableFile, keep: np.ndarray, rows: dict[str, np.ndarray]) -> Cells:
    """Every numeric column read one at a time (non-numeric, infinite and impossible x/y
    cells refused), and each stream's cells of the columns it uses kept: the whole table's
    columns are never held at once."""
    cells: Cells = {}
    for c in NUMERIC:
        if c not in tab.columns or c == "t_ns":
            continue
        v = numeric_column(tab, c)
        _refuse_infinite(tab, keep, c, v)
        if c in ("x", "y"):
            _refuse_far(tab, keep, c, v)
        for s, r in rows.items():
            if c in USES[s]:
                cells[(s, c)] = v[r]
        if c != "t":  # the times are read again by stream_times, not held across the others
            tab.release(c)
    return cells


def _first_row(rows: dict[str, np.ndarray], masks: dict[str, np.ndarray]) -> int:
    """The first table row (in file order) among each stream's rows where its mask holds."""
    return min(int(rows[s][np.flatnonzero(m)[0]]) for s, m in masks.items() if m.any())


def position_frame(tab: TableFile, rows: dict[str, np.ndarray], cells: Cells) -> str:
    """'latlon' or 'xy': which columns every gps/truth row fills."""
    pos = {s: rows[s] for s in ("gps", "truth")}

    def complete(a: str, b: str) -> dict[str, np.ndarray]:
        out = {}
        for s, r in pos.items():
            if (s, a) in cells and (s, b) in cells:
                out[s] = np.isfinite(cells[(s, a)]) & np.isfinite(cells[(s, b)])
            else:
                out[s] = np.zeros(r.size, dtype=bool)
        return out

    ll, xy = complete("lat", "lon"), complete("x", "y")
    if all(m.all() for m in ll.values()):
        return "latlon"
    if all(m.all() for m in xy.values()):
        return "xy"
    neither = {s: ~ll[s] & ~xy[s] for s in pos}
    if any(m.any() for m in neither.values()):
        i = _first_row(pos, neither)
        raise DataError(tab.path, f"{tab.where(i)}: position row has neither lat/lon nor x/y")
    i = _first_row(pos, {s: ~m for s, m in ll.items()})
    raise DataError(
        tab.path,
        f"{tab.where(i)}: some position rows give only x/y and others "
        "only lat/lon; use one frame for all gps and truth rows",
    )
