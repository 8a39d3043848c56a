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
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.table_cells import (
    KNOWN,
    REQUIRED,
    STREAMS,
    check_columns,
    need_cells,
    position_frame,
    stream_cells,
    stream_codes,
    stream_times,
)
from posbench.scenarios.loaders.table_file import read_table_file
from posbench.scenarios.projection import to_local, validate_latlon
from posbench.scenarios.time_axis import check_stream_times

if TYPE_CHECKING:  # pandas is imported when a table is read or written
    import pandas as pd

UNIX_MIN_S = 1e8


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
    codes, keep = stream_codes(tab, warnings)
    if not keep.any():
        raise DataError(path, "no data rows (only blank lines)")
    rows = {s: np.flatnonzero((codes == i) & keep) for i, s in enumerate(STREAMS)}
    del codes
    present = {s for s, r in rows.items() if r.size}
    check_columns(tab, present)
    ignored = [c for c in tab.columns if c not in KNOWN]
    if ignored:
        warnings.append(f"table: ignored unknown columns {', '.join(ignored)}")

    cells = stream_cells(tab, keep, rows)
    t_of, t_origin = stream_times(tab, keep, rows)
    n_kept = int(keep.sum())
    del keep

    def col(s: str, c: str) -> np.ndarray | None:
        """Stream ``s``'s cells of column ``c``, handed over (None: not in the file)."""
        return cells.pop((s, c), None)

    for s, req in REQUIRED.items():
        for c in req:
            if rows[s].size:
                need_cells(tab, rows[s], ~np.isfinite(cells[(s, c)]), c, s)

    frame = position_frame(tab, rows, cells) if rows["gps"].size + rows["truth"].size else "xy"
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
