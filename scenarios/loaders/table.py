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
from typing import TYPE_CHECKING

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
UNIX_MIN_S = 1e8


def _times(tab: TableFile, rows: np.ndarray) -> tuple[np.ndarray, float]:
    """Times [s] relative to the earliest selected row and that row's absolute time [s].

    An integer ``t_ns`` column is differenced in int64 so Unix-epoch stamps keep ns
    precision (a ``t_ns`` column with empty cells is read as float: ~0.4 us steps).
    """
    import pandas as pd

    df = tab.df
    if "t_ns" in df.columns:
        col = "t_ns"
        if pd.api.types.is_integer_dtype(df["t_ns"].dtype):
            ns = df["t_ns"].to_numpy(dtype=np.int64)[rows]
            ns0 = int(ns.min())
            return (ns - ns0).astype(np.float64) / 1e9, ns0 / 1e9
        t = numeric_column(tab, col)[rows] / 1e9
    else:
        col = "t"
        t = numeric_column(tab, col)[rows]
    _need_cells(tab, rows, ~np.isfinite(t), col)
    t0 = float(t.min())
    return t - t0, t0


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


def _stream_labels(tab: TableFile, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(labels per row, mask of rows kept); blank CSV lines are dropped with a warning."""
    import pandas as pd

    df = tab.df
    blank = df.isna().all(axis=1).to_numpy()
    if blank.any():
        warnings.append(f"table: dropped {int(blank.sum())} blank lines")
    if "stream" not in df.columns:
        labels = np.full(len(df), "gps", dtype=object)
        warnings.append("table: no 'stream' column, every row read as a GPS fix")
        return labels, ~blank
    # each distinct value cleaned once, the rows sharing its string (a long drive has
    # millions of rows and a handful of streams: a new string per row was 420 MB at 8 h)
    codes, uniques = pd.factorize(df["stream"])
    cleaned = pd.Series(uniques, dtype=object).astype("string").str.strip().str.lower()
    table = np.array([*cleaned.fillna("").to_numpy(dtype=object), ""], dtype=object)
    labels = table[codes]  # missing (code -1): the last entry, ""
    unknown = ~np.isin(labels, STREAMS) & ~blank
    if unknown.any():
        i = int(np.flatnonzero(unknown)[0])
        raise DataError(
            tab.path,
            f"{tab.where(i)}, column 'stream': unknown stream "
            f"{df['stream'].iloc[i]!r} (expected one of "
            f"{', '.join(STREAMS)}); {int(unknown.sum())} such rows",
        )
    return labels, ~blank


def _check_columns(tab: TableFile, present_streams: set[str]) -> None:
    cols = set(tab.df.columns)
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


def _refuse_infinite(tab: TableFile, keep: np.ndarray, num: dict[str, np.ndarray]) -> None:
    """Refuse an infinite cell in any numeric column (an empty cell means "not given"; no
    value is infinite), naming its line and column."""
    for c, v in num.items():
        inf = np.isinf(v) & keep
        if np.any(inf):
            i = int(np.flatnonzero(inf)[0])
            raise DataError(
                tab.path,
                f"{tab.where(i)}, column {c!r}: infinite value {float(v[i])!r}; "
                f"{int(inf.sum())} such row{'s' * (int(inf.sum()) != 1)} in all",
            )


def _refuse_far(tab: TableFile, keep: np.ndarray, num: dict[str, np.ndarray]) -> None:
    """Refuse an x or y cell farther than :data:`~posbench.scenarios.drive.MAX_POSITION_M`
    from the origin (no vehicle can be there), naming its line and column."""
    for c in ("x", "y"):
        if c not in num:
            continue
        far = (np.abs(num[c]) > MAX_POSITION_M) & keep
        if np.any(far):
            i = int(np.flatnonzero(far)[0])
            n = int(far.sum())
            raise DataError(
                tab.path,
                f"{tab.where(i)}, column {c!r}: {float(num[c][i]):g} m is no position: more "
                f"than {MAX_POSITION_M:g} m from the origin, farther than any point on Earth; "
                f"{n} such row{'s' * (n != 1)} in all",
            )


def _position_frame(tab: TableFile, rows: np.ndarray, num: dict[str, np.ndarray]) -> str:
    """'latlon' or 'xy': which columns every gps/truth row fills."""

    def complete(a: str, b: str) -> np.ndarray:
        if a not in num or b not in num:
            return np.zeros(rows.size, dtype=bool)
        return np.isfinite(num[a][rows]) & np.isfinite(num[b][rows])

    ll, xy = complete("lat", "lon"), complete("x", "y")
    if ll.all():
        return "latlon"
    if xy.all():
        return "xy"
    neither = ~ll & ~xy
    if neither.any():
        i = int(rows[np.flatnonzero(neither)[0]])
        raise DataError(tab.path, f"{tab.where(i)}: position row has neither lat/lon nor x/y")
    i = int(rows[np.flatnonzero(~ll)[0]])
    raise DataError(
        tab.path,
        f"{tab.where(i)}: some position rows give only x/y and others "
        "only lat/lon; use one frame for all gps and truth rows",
    )


def _opt(a: np.ndarray | None) -> np.ndarray | None:
    return None if a is None or not np.any(np.isfinite(a)) else a


def load_table(path: Path, projection: str = "enu") -> Drive:
    """Load a long-format (or wide GPS-only) CSV / Parquet table; see the module docstring."""
    path = Path(path)
    warnings: list[str] = []
    tab = read_table_file(path)
    df = tab.df
    if len(df) == 0:
        raise DataError(path, "no data rows (only a header)")
    labels, keep = _stream_labels(tab, warnings)
    if not keep.any():
        raise DataError(path, "no data rows (only blank lines)")
    present = {s for s in STREAMS if np.any((labels == s) & keep)}
    _check_columns(tab, present)
    ignored = [c for c in df.columns if c not in KNOWN]
    if ignored:
        warnings.append(f"table: ignored unknown columns {', '.join(ignored)}")

    num = {c: numeric_column(tab, c) for c in NUMERIC if c in df.columns and c != "t_ns"}
    _refuse_infinite(tab, keep, num)
    _refuse_far(tab, keep, num)
    all_rows = np.flatnonzero(keep)
    t_all, t_origin = _times(tab, all_rows)
    t_full = np.full(len(df), np.nan)
    t_full[all_rows] = t_all

    def rows_of(s: str) -> np.ndarray:
        return np.flatnonzero((labels == s) & keep)

    def col(c: str, rows: np.ndarray) -> np.ndarray | None:
        return num[c][rows] if c in num else None

    for s, req in REQUIRED.items():
        r = rows_of(s)
        for c in req:
            if r.size:
                _need_cells(tab, r, ~np.isfinite(num[c][r]), c, s)

    pos_rows = np.flatnonzero(np.isin(labels, ("gps", "truth")) & keep)
    frame = _position_frame(tab, pos_rows, num) if pos_rows.size else "xy"
    origin_lat = origin_lon = float("nan")
    proj = "source"
    xs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if frame == "latlon":
        for s in ("gps", "truth"):
            r = rows_of(s)
            if r.size:
                validate_latlon(num["lat"][r], num["lon"][r], str(path), what=f"{s} row")
        first = rows_of("gps") if rows_of("gps").size else rows_of("truth")
        i0 = first[np.argmin(t_full[first])]
        origin_lat, origin_lon = float(num["lat"][i0]), float(num["lon"][i0])
        proj = projection
        for s in ("gps", "truth"):
            r = rows_of(s)
            xs[s] = to_local(num["lat"][r], num["lon"][r], origin_lat, origin_lon, projection)
    else:
        for s in ("gps", "truth"):
            r = rows_of(s)
            xs[s] = (num["x"][r], num["y"][r]) if r.size else (np.empty(0), np.empty(0))

    t_col, t_unit = ("t_ns", "nanoseconds") if "t_ns" in df.columns else ("t", "seconds")

    def clean(s: str) -> tuple[np.ndarray, np.ndarray]:
        """Stream ``s``'s times [s] cleaned and checked (:mod:`~posbench.scenarios.time_axis`),
        and the kept ones' indices into its rows."""
        r = rows_of(s)
        t, kept = clean_index(t_full[r], f"table {s}", warnings)
        check_stream_times(
            t, s, path, lambda i: tab.where(int(r[kept[i]])), what=t_col, unit=t_unit
        )
        return t, kept

    r = rows_of("gps")
    lat_g, lon_g = col("lat", r), col("lon", r)
    if (
        lat_g is None
        or lon_g is None
        or not (np.all(np.isfinite(lat_g)) and np.all(np.isfinite(lon_g)))
    ):
        lat_g = lon_g = None  # kept only when every fix has them
    t, kept = clean("gps")
    gps = GpsStream(
        t,
        take(xs["gps"][0], kept),
        take(xs["gps"][1], kept),
        lat=take(lat_g, kept),
        lon=take(lon_g, kept),
        accuracy=_opt(take(col("accuracy", r), kept)),
    )

    imu = speed = truth = None
    r = rows_of("imu")
    if r.size:
        t, kept = clean("imu")
        imu = ImuStream(
            t,
            take(num["ax"][r], kept),
            take(num["ay"][r], kept),
            yaw=_opt(take(col("yaw", r), kept)),
            yaw_rate=_opt(take(col("yaw_rate", r), kept)),
        )
    r = rows_of("speed")
    if r.size:
        t, kept = clean("speed")
        speed = SpeedStream(t, take(num["v"][r], kept))
    r = rows_of("truth")
    if r.size:
        t, kept = clean("truth")
        truth = TruthStream(
            t,
            take(xs["truth"][0], kept),
            take(xs["truth"][1], kept),
            yaw=_opt(take(col("yaw", r), kept)),
            v=_opt(take(col("v", r), kept)),
            accuracy=_opt(take(col("accuracy", r), kept)),
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
        time_source="t_ns column" if "t_ns" in df.columns else "t column",
        warnings=warnings,
        extra={"rows": int(keep.sum())},
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
