"""CSV / Parquet tables: the format users export their own drives to.

Long format: one row per sample, the column ``stream`` says which stream it
belongs to; columns a stream does not use are left empty. Column names are
case-insensitive; surrounding spaces are ignored.

=============  ====================  =========  =====================================
column         used by stream        unit       required?
=============  ====================  =========  =====================================
``stream``     all                   -          yes: one of gps, imu, speed, truth
``t``          all                   s          ``t`` or ``t_ns`` (any origin)
``t_ns``       all                   int ns     preferred over ``t`` when both exist
``lat``        gps, truth            deg        ``lat`` + ``lon`` or ``x`` + ``y``
``lon``        gps, truth            deg        (WGS-84)
``x``          gps, truth            m          local metres (east-like, e.g. ENU)
``y``          gps, truth            m          local metres (north-like)
``accuracy``   gps, truth            m          optional: per-axis 1-sigma (east = north)
``ax``         imu                   m/s^2      yes for imu rows (vehicle x forward)
``ay``         imu                   m/s^2      yes for imu rows (vehicle y left)
``yaw``        imu, truth            rad        optional (ENU: 0 = east, CCW +)
``yaw_rate``   imu                   rad/s      optional (CCW +, about up)
``v``          speed, truth          m/s        yes for speed rows, optional for truth
=============  ====================  =========  =====================================

``accuracy`` is the fix's stated horizontal accuracy as the standard deviation of each of
x and y (not a radius, not a 95 % figure: divide a CEP50 by 1.1774, a 2DRMS by 2.83, a
horizontal RMS by 1.414); an empty cell or NaN means "not stated". Predictors get it as
``observe_gps(..., sigma=)``.

Wide GPS-only files: without a ``stream`` column every row is a GPS fix
(columns ``t`` or ``t_ns``, ``lat``/``lon`` or ``x``/``y``, optional ``accuracy``).

Positions: if every gps and truth row has ``lat`` and ``lon``, they are projected
(``projection``, about the first GPS fix, else the first truth row) and
``meta.projection`` is that projection; otherwise, if every such row has ``x`` and
``y``, those metres are used as given (``meta.projection = "source"``; GPS lat/lon,
where complete, are kept as attributes). Times: t = 0 is the earliest row of any
stream; ``meta.epoch_s`` is that time if it looks like Unix time (> 1e8 s, i.e.
after 1973), else NaN. Rows of a stream are sorted by time and exact duplicate
stamps dropped, with a warning (:func:`posbench.scenarios.cleaning.clean_index`). Blank CSV
lines are dropped with a warning. Unknown columns are ignored with a warning.

Errors (:class:`DataError`, naming the file): empty file, missing required columns,
unknown ``stream`` values, non-numeric or missing required cells, an infinite cell in any
column, truncated / malformed CSV. Rows are named by CSV line number (header = line 1) or,
for Parquet, by 1-based data row.

Time axis (:mod:`posbench.scenarios.time_axis`, after sorting): a stream whose median step
is implausible for its kind is refused with the unit ``t`` evidently has (e.g. ``t looks
like milliseconds, not seconds (the gps stream's median step is 200, a 5 Hz stream in
milliseconds ...)``): it is not converted, a wrong guess would be silently wrong; a gap over
:data:`~posbench.scenarios.time_axis.MAX_GAP_S` inside a stream is refused naming the line
where it starts; all streams together may span at most
:data:`~posbench.scenarios.time_axis.MAX_SPAN_S`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, overload

import numpy as np

from posbench.scenarios.cleaning import clean_index, take
from posbench.scenarios.drive import (
    MAX_POSITION_M,
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.table_file import TableFile, numeric_column, read_table_file
from posbench.scenarios.projection import to_local, validate_latlon
from posbench.scenarios.time_axis import check_stream_times

if TYPE_CHECKING:  # pandas is imported when a table is read or written
    import pandas as pd

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
UNIX_MIN_S = 1e8

#: a stream's rows (indices into the table, in file order) and its cells of each column it
#: uses: ``cells[(stream, column)]``
Cells = dict[tuple[str, str], np.ndarray]


def _times(
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
    if np.any(missing):
        i = int(np.flatnonzero(missing)[0])
        raise DataError(
            tab.path,
            f"{tab.where(i)}, column {col!r}: missing or non-finite value; "
            f"{int(missing.sum())} such rows in all",
        )
    t0 = float(t[keep].min())
    return {k: t[r] - t0 for k, r in rows.items()}, t0


def _need_cells(
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


def _stream_codes(tab: TableFile, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
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


def _check_columns(tab: TableFile, present_streams: set[str]) -> None:
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


def _stream_cells(tab: TableFile, keep: np.ndarray, rows: dict[str, np.ndarray]) -> Cells:
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
    return cells


def _first_row(rows: dict[str, np.ndarray], masks: dict[str, np.ndarray]) -> int:
    """The first table row (in file order) among each stream's rows where its mask holds."""
    return min(int(rows[s][np.flatnonzero(m)[0]]) for s, m in masks.items() if m.any())


def _position_frame(tab: TableFile, rows: dict[str, np.ndarray], cells: Cells) -> str:
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


def _opt(a: np.ndarray | None) -> np.ndarray | None:
    return None if a is None or not np.any(np.isfinite(a)) else a


@overload
def _kept(col: np.ndarray, kept: np.ndarray) -> np.ndarray: ...
@overload
def _kept(col: None, kept: np.ndarray) -> None: ...
@overload
def _kept(col: np.ndarray | None, kept: np.ndarray) -> np.ndarray | None: ...
def _kept(col: np.ndarray | None, kept: np.ndarray) -> np.ndarray | None:
    """:func:`~posbench.scenarios.cleaning.take` without a copy where every sample is kept in
    order (a clean stream: the usual case), for cells read here and held by nobody else."""
    if col is not None and kept.size == col.size and np.array_equal(kept, np.arange(kept.size)):
        return col
    return take(col, kept)


def load_table(path: Path, projection: str = "enu") -> Drive:
    """Load a long-format (or wide GPS-only) CSV / Parquet table; see the module docstring.
    A Parquet file is read one column at a time, each stream keeping only its own cells."""
    path = Path(path)
    warnings: list[str] = []
    tab = read_table_file(path)
    if tab.n_rows == 0:
        raise DataError(path, "no data rows (only a header)")
    codes, keep = _stream_codes(tab, warnings)
    if not keep.any():
        raise DataError(path, "no data rows (only blank lines)")
    rows = {s: np.flatnonzero((codes == i) & keep) for i, s in enumerate(STREAMS)}
    del codes
    present = {s for s, r in rows.items() if r.size}
    _check_columns(tab, present)
    ignored = [c for c in tab.columns if c not in KNOWN]
    if ignored:
        warnings.append(f"table: ignored unknown columns {', '.join(ignored)}")

    cells = _stream_cells(tab, keep, rows)
    t_of, t_origin = _times(tab, keep, rows)
    n_kept = int(keep.sum())
    del keep

    def col(s: str, c: str) -> np.ndarray | None:
        """Stream ``s``'s cells of column ``c``, handed over (None: not in the file)."""
        return cells.pop((s, c), None)

    for s, req in REQUIRED.items():
        for c in req:
            if rows[s].size:
                _need_cells(tab, rows[s], ~np.isfinite(cells[(s, c)]), c, s)

    frame = _position_frame(tab, rows, cells) if rows["gps"].size + rows["truth"].size else "xy"
    origin_lat = origin_lon = float("nan")
    proj = "source"
    xs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if frame == "latlon":
        for s in ("gps", "truth"):
            if rows[s].size:
                validate_latlon(cells[(s, "lat")], cells[(s, "lon")], str(path), what=f"{s} row")
        first = "gps" if rows["gps"].size else "truth"
        i0 = int(np.argmin(t_of[first]))
        origin_lat, origin_lon = float(cells[(first, "lat")][i0]), float(cells[(first, "lon")][i0])
        proj = projection
        for s in ("gps", "truth"):
            if rows[s].size:
                xs[s] = to_local(
                    cells[(s, "lat")], cells[(s, "lon")], origin_lat, origin_lon, projection
                )
            else:
                xs[s] = (np.empty(0), np.empty(0))
    else:
        for s in ("gps", "truth"):
            xs[s] = (
                (cells[(s, "x")], cells[(s, "y")]) if rows[s].size else (np.empty(0), np.empty(0))
            )

    cells.pop(("truth", "lat"), None), cells.pop(("truth", "lon"), None)  # served x/y only

    t_col, t_unit = ("t_ns", "nanoseconds") if "t_ns" in tab.columns else ("t", "seconds")

    def clean(s: str) -> tuple[np.ndarray, np.ndarray]:
        """Stream ``s``'s times [s] cleaned and checked (:mod:`~posbench.scenarios.time_axis`),
        and the kept ones' indices into its rows."""
        r = rows[s]
        t, kept = clean_index(t_of.pop(s), f"table {s}", warnings)
        check_stream_times(
            t, s, path, lambda i: tab.where(int(r[kept[i]])), what=t_col, unit=t_unit
        )
        return t, kept

    lat_g, lon_g = col("gps", "lat"), col("gps", "lon")
    if (
        lat_g is None
        or lon_g is None
        or not (np.all(np.isfinite(lat_g)) and np.all(np.isfinite(lon_g)))
    ):
        lat_g = lon_g = None  # kept only when every fix has them
    t, kept = clean("gps")
    x, y = xs.pop("gps")
    gps = GpsStream(
        t,
        _kept(x, kept),
        _kept(y, kept),
        lat=_kept(lat_g, kept),
        lon=_kept(lon_g, kept),
        accuracy=_opt(_kept(col("gps", "accuracy"), kept)),
    )

    imu = speed = truth = None
    if rows["imu"].size:
        t, kept = clean("imu")
        imu = ImuStream(
            t,
            _kept(cells.pop(("imu", "ax")), kept),  # required: checked above
            _kept(cells.pop(("imu", "ay")), kept),
            yaw=_opt(_kept(col("imu", "yaw"), kept)),
            yaw_rate=_opt(_kept(col("imu", "yaw_rate"), kept)),
        )
    if rows["speed"].size:
        t, kept = clean("speed")
        speed = SpeedStream(t, _kept(cells.pop(("speed", "v")), kept))
    if rows["truth"].size:
        t, kept = clean("truth")
        x, y = xs.pop("truth")
        truth = TruthStream(
            t,
            _kept(x, kept),
            _kept(y, kept),
            yaw=_opt(_kept(col("truth", "yaw"), kept)),
            v=_opt(_kept(col("truth", "v"), kept)),
            accuracy=_opt(_kept(col("truth", "accuracy"), kept)),
        )

    epoch = t_origin if t_origin > UNIX_MIN_S else float("nan")
    meta = DriveMeta(
        name=path.stem,
        source=str(path),
        format="table",
        epoch_s=epoch,
        origin_lat=origin_lat,
        origin_lon=origin_lon,
        projection=proj,
        time_source="t_ns column" if "t_ns" in tab.columns else "t column",
        warnings=warnings,
        extra={"rows": n_kept},
    )
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)


def drive_to_frame(drive: Drive) -> pd.DataFrame:
    """A :class:`Drive` as a long-format ``pandas.DataFrame`` (the schema above).

    Times are written as ``t`` [s] from the drive start; positions as ``x``/``y`` in
    the drive's frame, plus ``lat``/``lon`` for GPS rows when the drive has them.
    """
    import pandas as pd

    parts = []

    def add(name: str, t: np.ndarray, **cols: np.ndarray | None) -> None:
        d = {"stream": np.full(t.size, name, dtype=object), "t": t}
        d.update({k: v for k, v in cols.items() if v is not None})
        parts.append(pd.DataFrame(d))

    g = drive.gps
    add("gps", g.t, x=g.x, y=g.y, lat=g.lat, lon=g.lon, accuracy=g.accuracy)
    if drive.imu is not None:
        m = drive.imu
        add("imu", m.t, ax=m.ax, ay=m.ay, yaw=m.yaw, yaw_rate=m.yaw_rate)
    if drive.speed is not None:
        add("speed", drive.speed.t, v=drive.speed.v)
    if drive.truth is not None:
        tr = drive.truth
        add("truth", tr.t, x=tr.x, y=tr.y, yaw=tr.yaw, v=tr.v, accuracy=tr.accuracy)
    df = pd.concat(parts, ignore_index=True)
    cols = [c for c in KNOWN if c in df.columns]
    return df[cols].sort_values("t", kind="stable").reset_index(drop=True)


def write_table(drive: Drive, path: Path) -> None:
    """Write a drive in the long format; ``.parquet``/``.pq`` as Parquet, else CSV."""
    path = Path(path)
    df = drive_to_frame(drive)
    if path.suffix.lower() in (".parquet", ".pq"):
        df.to_parquet(path, index=False)
    else:
        df.to_csv(path, index=False, float_format="%.17g")
