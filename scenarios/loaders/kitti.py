"""KITTI raw drives: the OXTS RT3003 GPS/IMU solution as a :class:`Drive`.

Layout read (KITTI's own)::

    <date>_drive_<nnnn>_sync/oxts/timestamps.txt     one ``YYYY-MM-DD HH:MM:SS.fffffffff`` a line
    <date>_drive_<nnnn>_sync/oxts/dataformat.txt     column names, one ``name: description`` a line
    <date>_drive_<nnnn>_sync/oxts/data/NNNNNNNNNN.txt one line of 30 numbers per sample

Line ``i`` of ``timestamps.txt`` (0-based) belongs to ``data/<i:010d>.txt``.

Streams built (all from the one OXTS solution, 10 Hz):

- truth: x, y [m] (``posbench.scenarios.projection.to_local`` about the first fix), yaw [rad]
  = OXTS ``yaw``, v [m/s] = hypot(vf, vl), accuracy [m] = ``pos_accuracy``;
- gps: the same fixes (lat, lon, x, y, accuracy = ``pos_accuracy``); the runner
  usually replaces it with a degraded draw from the truth. ``pos_accuracy`` is one number
  for north and east (dataformat.txt: "velocity accuracy (north/east in m)", a typo for
  position); it is read as the per-axis 1-sigma of :class:`GpsStream` unchanged (the
  literal reading: the figure holds for north and for east). Had KITTI folded the
  OXTS north and east sigmas into their root-sum-square, this over-states by <= sqrt(2);
  the layout does not say which;
- imu: ax = ``af``, ay = ``al`` (vehicle frame, forward / left, m/s^2, parallel to
  the earth surface), yaw = OXTS ``yaw``, yaw_rate = ``wu`` (rad/s about up);
- speed: v = ``vf`` [m/s].

Yaw convention: dataformat.txt says "heading, 0 = east, positive = counter clockwise",
i.e. already the ENU yaw of :mod:`posbench.scenarios.drive`. Checked on the 46 drives of
``../shared/data/kitti_raw``: wherever the car moves faster than 3 m/s the direction
of travel atan2(dy, dx) from the ENU positions agrees with OXTS yaw to a median of
0.1 - 1.2 degrees on every drive with good truth; only 2011_09_26_drive_0093 (median
pos_accuracy 21 m, flagged ``truth_poor``) disagrees (35 degrees), because its
positions, not its yaw, are poor (tests/scenarios/test_loader_kitti.py asserts < 10 degrees).

Times: ``timestamps.txt`` holds naive wall-clock stamps (KITTI does not state the
time zone); they are read as UTC, so ``meta.epoch_s`` may be off by whole hours.
Intervals jitter around 0.1 s (0.06 - 0.13 s seen); ``meta.extra`` counts
``time_gaps`` (interval > 1.5 x median) and ``time_jitter`` (|interval - median|
> 10 ms).
"""

from __future__ import annotations

import os
import warnings as _warnings
from pathlib import Path

import numpy as np

from posbench.scenarios.cleaning import clean_index, take
from posbench.scenarios.drive import (
    FIXES_FROM_TRUTH,
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.projection import to_local, validate_latlon
from posbench.scenarios.time_axis import check_stream_times

#: KITTI's documented column order (used when dataformat.txt is missing).
OXTS_COLUMNS = (
    "lat",
    "lon",
    "alt",
    "roll",
    "pitch",
    "yaw",
    "vn",
    "ve",
    "vf",
    "vl",
    "vu",
    "ax",
    "ay",
    "az",
    "af",
    "al",
    "au",
    "wx",
    "wy",
    "wz",
    "wf",
    "wl",
    "wu",
    "pos_accuracy",
    "vel_accuracy",
    "navstat",
    "numsats",
    "posmode",
    "velmode",
    "orimode",
)
POOR_TRUTH_M = 1.0
_NEEDED = ("lat", "lon", "yaw", "vf", "vl", "af", "al", "wu", "pos_accuracy")


def _oxts_dir(path: Path) -> Path:
    if path.name == "oxts" and (path / "timestamps.txt").is_file():
        return path
    return path / "oxts"


def _drive_name(oxts: Path) -> str:
    return oxts.parent.name if oxts.name == "oxts" else oxts.name


def _read_lines(path: Path) -> list[str]:
    if not path.is_file():
        raise DataError(path, "file missing")
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(path, f"cannot read: {e}") from None
    return text.splitlines()


def read_dataformat(path: Path, warnings: list[str]) -> tuple[str, ...]:
    """Column names from dataformat.txt, or KITTI's standard order (with a warning).

    KITTI's own file lists the z acceleration as a second ``ay`` (a typo); names are
    taken by position where they disagree with the standard order.
    """
    if not path.is_file():
        warnings.append(f"kitti: {path.name} missing; assumed the standard 30 OXTS columns")
        return OXTS_COLUMNS
    names = [ln.split(":", 1)[0].strip() for ln in _read_lines(path) if ln.strip()]
    if len(names) != len(OXTS_COLUMNS):
        raise DataError(path, f"expected {len(OXTS_COLUMNS)} column names, found {len(names)}")
    differ = [(i, n) for i, n in enumerate(names) if n != OXTS_COLUMNS[i]]
    # the published file has "ay" where "az" belongs (line 14); anything else is unexpected
    if any((i, n) != (13, "ay") for i, n in differ):
        i, n = next((i, n) for i, n in differ if (i, n) != (13, "ay"))
        raise DataError(path, f"line {i + 1}: column {n!r} where {OXTS_COLUMNS[i]!r} was expected")
    return OXTS_COLUMNS


def parse_timestamps(path: Path) -> np.ndarray:
    """Unix times [s, float64] from a KITTI timestamps.txt; NaN for blank lines.

    Trailing blank lines are ignored; an unparsable line raises :class:`DataError`
    naming it. Stamps are naive and read as UTC.
    """
    lines = _read_lines(path)
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise DataError(path, "no time stamps (empty file)")
    stripped = [ln.strip() for ln in lines]
    blank = np.array([not s for s in stripped])
    vals = [s if s else "NaT" for s in stripped]
    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            ns = np.array(vals, dtype="datetime64[ns]")
    except ValueError:
        for k, s in enumerate(vals):
            try:
                with _warnings.catch_warnings():
                    _warnings.simplefilter("ignore")
                    np.datetime64(s, "ns")
            except ValueError:
                raise DataError(
                    path,
                    f"line {k + 1}: cannot parse time stamp {s!r} "
                    "(expected YYYY-MM-DD HH:MM:SS.fffffffff)",
                ) from None
        raise  # pragma: no cover - the loop finds the bad line
    t = ns.astype(np.int64).astype(np.float64) / 1e9
    t[blank | np.isnat(ns)] = np.nan
    return t


def _parse_data_files(
    data_dir: Path, n: int, ncol: int, warnings: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Read data/NNNNNNNNNN.txt for samples 0..n-1: (values (n, ncol) with NaN rows,
    present mask)."""
    if not data_dir.is_dir():
        raise DataError(data_dir, "folder missing (expected oxts/data/NNNNNNNNNN.txt)")
    names = {e.name for e in os.scandir(data_dir) if e.name.endswith(".txt")}
    texts: list[str] = []
    present = np.zeros(n, dtype=bool)
    empty = 0
    for i in range(n):
        name = f"{i:010d}.txt"
        if name not in names:
            continue
        with open(data_dir / name, "rb") as fh:
            txt = fh.read().decode("ascii", errors="replace")
        if not txt.strip():
            empty += 1
            continue
        present[i] = True
        texts.append(txt)
    extra = len(names) - int(present.sum()) - empty
    missing = n - int(present.sum()) - empty
    if missing:
        warnings.append(
            f"kitti: {missing} data files missing for listed time stamps; samples dropped"
        )
    if empty:
        warnings.append(f"kitti: {empty} empty data files; samples dropped")
    if extra > 0:
        warnings.append(f"kitti: {extra} data files without a time stamp line ignored")
    if not texts:
        raise DataError(data_dir, "no readable OXTS data files")
    vals = _fast_parse(texts, ncol)
    if vals is None:  # find and name the bad file / line
        for file_no, txt in zip(np.flatnonzero(present), texts, strict=True):
            _parse_one(data_dir / f"{file_no:010d}.txt", txt, ncol)
        raise DataError(data_dir, "cannot parse OXTS data")  # pragma: no cover
    out = np.full((n, ncol), np.nan)
    out[present] = vals
    return out, present


def _fast_parse(texts: list[str], ncol: int) -> np.ndarray | None:
    """All files' numbers at once; None if any file is not exactly one row of ``ncol`` numbers."""
    counts = [len(t.split()) for t in texts]
    if any(c != ncol for c in counts):
        return None
    try:
        flat = np.array(" ".join(texts).split(), dtype=np.float64)
    except ValueError:
        return None
    return flat.reshape(len(texts), ncol)


def _parse_one(path: Path, txt: str, ncol: int) -> np.ndarray:
    rows = [(k + 1, ln) for k, ln in enumerate(txt.splitlines()) if ln.strip()]
    if len(rows) != 1:
        raise DataError(
            path,
            f"line {rows[1][0]}: expected one line of {ncol} numbers, "
            f"found {len(rows)} non-blank lines",
        )
    lineno, ln = rows[0]
    fields = ln.split()
    if len(fields) != ncol:
        raise DataError(path, f"line {lineno}: expected {ncol} numbers, found {len(fields)}")
    for j, f in enumerate(fields):
        try:
            float(f)
        except ValueError:
            raise DataError(
                path, f"line {lineno}, column {j + 1} ({OXTS_COLUMNS[j]}): not a number: {f!r}"
            ) from None
    return np.array(fields, dtype=float)


def _refuse_nonfinite(
    data: np.ndarray, present: np.ndarray, ci: dict[str, int], data_dir: Path
) -> None:
    """Refuse the first present sample with a NaN or infinite value in a column the streams
    use (:data:`_NEEDED`), naming its data file and column."""
    cols = [ci[c] for c in _NEEDED]
    bad = present & ~np.all(np.isfinite(data[:, cols]), axis=1)
    if not np.any(bad):
        return
    i = int(np.flatnonzero(bad)[0])
    j = next(c for c in cols if not np.isfinite(data[i, c]))
    raise DataError(
        data_dir / f"{i:010d}.txt",
        f"column {j + 1} ({OXTS_COLUMNS[j]}): non-finite value {float(data[i, j])!r}; "
        f"{int(bad.sum())} such sample{'s' * (int(bad.sum()) != 1)} in all",
    )


def _count_time_irregularity(t: np.ndarray) -> tuple[int, int, float]:
    """(gaps, jittered intervals, median interval [s]) of sorted times."""
    if t.size < 3:
        return 0, 0, float("nan")
    dt = np.diff(t)
    med = float(np.median(dt))
    gaps = int(np.sum(dt > 1.5 * med))
    jitter = int(np.sum(np.abs(dt - med) > 0.010))
    return gaps, jitter, med


def load_kitti_drive(path: Path, projection: str = "enu") -> Drive:
    """Load one KITTI raw drive folder (or its ``oxts`` folder) as a :class:`Drive`.

    Args:
        path: ``<date>_drive_<nnnn>_sync`` folder or its ``oxts`` sub-folder.
        projection: ``"enu"`` (default) or ``"mercator"``, about the first fix.
    Returns:
        Drive with gps, imu, speed and truth streams (t [s] from the first sample).
    Raises:
        DataError: missing timestamps / data, unparsable lines, invalid lat/lon, a NaN or
            infinite value in a column the streams use (naming the data file), times that
            fail :func:`~posbench.scenarios.time_axis.check_stream_times` (naming the line
            of timestamps.txt).
    """
    path = Path(path)
    oxts = _oxts_dir(path)
    name = _drive_name(oxts)
    warnings: list[str] = []
    cols = read_dataformat(oxts / "dataformat.txt", warnings)
    ts_path = oxts / "timestamps.txt"
    t_abs = parse_timestamps(ts_path)
    data, present = _parse_data_files(oxts / "data", t_abs.size, len(cols), warnings)

    ci = {c: i for i, c in enumerate(cols)}
    # validate over all listed samples (absent ones as a harmless 0, 0) so that the
    # index in the message is the data file's number
    lat_all = np.where(present, data[:, ci["lat"]], 0.0)
    lon_all = np.where(present, data[:, ci["lon"]], 0.0)
    bad = (
        ~np.isfinite(lat_all)
        | ~np.isfinite(lon_all)
        | (np.abs(lat_all) > 90)
        | (np.abs(lon_all) > 180)
    )
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        validate_latlon(lat_all, lon_all, str(oxts / "data" / f"{i:010d}.txt"), what="oxts sample")
    _refuse_nonfinite(data, present, ci, oxts / "data")
    lines = np.flatnonzero(present)  # each kept sample's line in timestamps.txt, 0-based
    t_abs = t_abs[present]
    data = data[present]

    t_abs, idx = clean_index(t_abs, "kitti oxts", warnings)
    columns = {c: take(data[:, ci[c]], idx) for c in _NEEDED}
    if t_abs.size == 0:
        raise DataError(ts_path, "no samples with a valid time stamp")
    epoch = float(t_abs[0])
    t = t_abs - epoch
    check_stream_times(t, "gps", ts_path, lambda k: f"line {int(lines[idx[k]]) + 1}")
    gaps, jitter, med_dt = _count_time_irregularity(t)
    if gaps:
        warnings.append(
            f"kitti oxts: {gaps} time gaps longer than 1.5 x the median interval ({med_dt:.3f} s)"
        )

    lat, lon = columns["lat"], columns["lon"]
    x, y = to_local(lat, lon, float(lat[0]), float(lon[0]), projection)
    acc = columns["pos_accuracy"]
    vf, vl = columns["vf"], columns["vl"]
    yaw = columns["yaw"]

    extra: dict = {
        "time_gaps": gaps,
        "time_jitter": jitter,
        "median_dt_s": med_dt,
        "truth_poor": False,
        "truth_source": "OXTS RT3003 GPS/IMU solution",
    }
    finite_acc = acc[np.isfinite(acc)]
    med_acc = float(np.median(finite_acc)) if finite_acc.size else float("nan")
    extra["truth_median_accuracy_m"] = med_acc
    if med_acc > POOR_TRUTH_M:
        warnings.append(
            f"poor truth accuracy: median pos_accuracy {med_acc:.2f} m > {POOR_TRUTH_M:.0f} m"
        )
        extra["truth_poor"] = True

    meta = DriveMeta(
        fix_source=FIXES_FROM_TRUTH,
        name=name,
        source=str(path),
        format="kitti",
        epoch_s=epoch,
        origin_lat=float(lat[0]),
        origin_lon=float(lon[0]),
        projection=projection,
        time_source="oxts/timestamps.txt (naive wall clock, read as UTC)",
        warnings=warnings,
        extra=extra,
    )
    gps = GpsStream(t, x, y, lat=lat, lon=lon, accuracy=acc)
    imu = ImuStream(t, columns["af"], columns["al"], yaw=yaw, yaw_rate=columns["wu"])
    speed = SpeedStream(t, vf)
    truth = TruthStream(t, x, y, yaw=yaw, v=np.hypot(vf, vl), accuracy=acc)
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)
