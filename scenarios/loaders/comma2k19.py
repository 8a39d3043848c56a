"""comma2k19 segments: u-blox GNSS, phone IMU, CAN speed and the fused global pose.

A segment folder ``<route>/<segment>/`` holds NumPy arrays saved without the
``.npy`` suffix (read with ``allow_pickle=False``); every ``t`` array and
``global_pose/frame_times`` share one clock (seconds since device boot;
``frame_gps_times`` maps it to GPS time with a constant offset, spread < 1 us).

Streams built (t = 0 is the earliest sample of any stream used):

- gps: ``processed_log/GNSS/live_gnss_ublox`` (value columns lat [deg], lon [deg],
  speed [m/s], utc_ms, alt [m], bearing [deg]); no accuracy column, so
  ``gps.accuracy`` is None (the u-blox hAcc is not in the processed log; ``raw_gnss_ublox``
  has per-satellite pseudorange standard deviations, which give a position accuracy
  only with the satellite geometry, not in the layout). **Time lag**:
  the u-blox fixes are logged ~0.1 s after the epoch they describe (the
  comma2k19 README says so). This loader subtracts ``gnss_lag_s`` (default 0.1 s,
  the README figure, chosen *without* looking at the truth) from the fix times.
  Measured on ``b0c9d2329ad1606b_2018-08-02--08-34-47/40`` against global_pose
  (least-squares time shift of the fix positions along the interpolated truth
  track): 0.082 s; residual RMS 0.46 m, mostly a constant 0.39 m east offset
  (antenna vs. pose origin). Median fix-to-truth distance: 1.43 m uncorrected,
  0.53 m with the 0.1 s correction. The fix's own ``utc_ms`` stamp, mapped
  through frame_gps_times, would imply a 0.20 s lag and is *not* used (it fits
  the truth worse: median 2.2 m). The figure measured on each segment is stored
  in ``meta.extra["gnss_lag_measured_s"]`` for information only.
- imu: ``processed_log/IMU/accelerometer`` and ``gyro`` (axes forward, right, down)
  converted to forward, left, up: ax = a_fwd, ay = -a_right, yaw_rate = -w_down.
  The gyro is linearly interpolated to the accelerometer times (in the data seen
  the two share their time stamps exactly, so nothing is changed). yaw = None:
  the phone IMU has no heading (truth has one).
- speed: ``processed_log/CAN/speed`` [m/s].
- truth: ``global_pose`` 20 Hz: frame_positions (ECEF) -> local about the first
  GNSS fix; yaw from frame_orientations (quaternion w, x, y, z, body -> ECEF;
  body x = forward): the body x axis in ECEF rotated into ENU at the origin,
  yaw = atan2(north, east). Checked: agrees with the direction of frame_velocities
  to a median of 0.9 deg; the body y axis points right, z down. v = |frame_velocities|.
  With ``projection="mercator"`` the truth goes ECEF -> lat/lon (pymap3d) -> mercator
  so both streams share one frame.

Refused (:class:`DataError` naming the array file and its row, 0-based): a NaN or infinite
value in a column a stream uses (lat, lon; accelerometer forward and right; gyro down; CAN
speed; global_pose positions, orientations, velocities), and times that fail
:func:`~posbench.scenarios.time_axis.check_stream_times` (unit, gaps).
"""

from __future__ import annotations

from pathlib import Path

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
from posbench.scenarios.projection import ecef_to_local, to_local, validate_latlon
from posbench.scenarios.time_axis import check_stream_times

GNSS_LAG_S = 0.1
GPS_UNIX_OFFSET_S = 315964800.0  # 1980-01-06 in Unix time
GPS_UTC_LEAP_S = 18.0  # GPS - UTC from 2017-01-01 (comma2k19 was recorded in 2018)


def _load(path: Path, ndim: tuple[int, ...], ncols: int | None = None) -> np.ndarray:
    if not path.is_file():
        raise DataError(path, "file missing")
    try:
        with open(path, "rb") as fh:
            a = np.load(fh, allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise DataError(path, f"not a NumPy array file: {e}") from None
    if a.ndim not in ndim or (ncols is not None and a.ndim == 2 and a.shape[1] < ncols):
        raise DataError(path, f"unexpected array shape {a.shape}")
    return np.asarray(a, dtype=np.float64)


def _series(folder: Path, ncols: int) -> tuple[np.ndarray, np.ndarray]:
    t = _load(folder / "t", (1,))
    v = _load(folder / "value", (1, 2), ncols)
    if v.ndim == 1:
        v = v[:, None]
    if v.shape[0] != t.size:
        raise DataError(folder / "value", f"{v.shape[0]} rows but t has {t.size}")
    return t, v


def _refuse_nonfinite(values: np.ndarray, path: Path, names: tuple[str, ...]) -> None:
    """Refuse the first row of ``values`` (columns ``names``) holding a NaN or infinity,
    naming the array file, the row (0-based) and the column."""
    bad = ~np.all(np.isfinite(values), axis=1)
    if not np.any(bad):
        return
    i = int(np.flatnonzero(bad)[0])
    j = int(np.flatnonzero(~np.isfinite(values[i]))[0])
    raise DataError(
        path,
        f"row {i}, {names[j]}: non-finite value {float(values[i, j])!r}; "
        f"{int(bad.sum())} such row{'s' * (int(bad.sum()) != 1)} in all",
    )


def _checked(
    t: np.ndarray, folder: Path, kind: str, what: str, warnings: list[str], name: str = "t"
) -> tuple[np.ndarray, np.ndarray]:
    """The times [s] in ``folder / name`` cleaned (:func:`clean_index`) and checked
    (:func:`~posbench.scenarios.time_axis.check_stream_times`, naming rows of that file), and
    the kept rows' indices."""
    t, kept = clean_index(t, what, warnings)
    check_stream_times(t, kind, folder / name, lambda i: f"row {int(kept[i])}")
    return t, kept


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (w, x, y, z) -> (N, 3, 3) rotation matrices."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def ecef_yaw(quat: np.ndarray, lat0: float, lon0: float) -> np.ndarray:
    """Yaw [rad, ENU at (lat0, lon0), 0 = east, CCW] of the body x axis of ECEF quaternions."""
    fwd = quat_to_rotmat(quat)[:, :, 0]  # body x in ECEF
    la, lo = np.radians(lat0), np.radians(lon0)
    east = np.array([-np.sin(lo), np.cos(lo), 0.0])
    north = np.array([-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)])
    return np.arctan2(fwd @ north, fwd @ east)


def measure_gnss_lag(
    t_fix: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    t_truth: np.ndarray,
    xt: np.ndarray,
    yt: np.ndarray,
    span: float = 0.5,
) -> float:
    """Time shift [s] L minimising sum |fix(t) - truth(t - L)|^2 (positive = fixes late)."""
    from scipy.optimize import minimize_scalar

    inside = (t_fix > t_truth[0] + span) & (t_fix < t_truth[-1])
    if inside.sum() < 10:
        return float("nan")
    tf, xf, yf = t_fix[inside], x[inside], y[inside]

    def cost(lag: float) -> float:
        return float(
            np.mean(
                (xf - np.interp(tf - lag, t_truth, xt)) ** 2
                + (yf - np.interp(tf - lag, t_truth, yt)) ** 2
            )
        )

    res = minimize_scalar(cost, bounds=(-span, span), method="bounded", options={"xatol": 1e-4})
    return float(res.x)


def load_comma_segment(
    path: Path,
    projection: str = "enu",
    gnss_lag_s: float = GNSS_LAG_S,
) -> Drive:
    """Load one comma2k19 segment folder as a :class:`Drive` (see the module docstring).

    Args:
        path: ``<route>/<segment>`` folder holding ``processed_log/`` and ``global_pose/``.
        projection: ``"enu"`` (default) or ``"mercator"``, about the first GNSS fix.
        gnss_lag_s: seconds subtracted from the u-blox fix times (0 to keep them raw).
    """
    path = Path(path)
    warnings: list[str] = []
    log = path / "processed_log"
    gnss_dir = log / "GNSS" / "live_gnss_ublox"
    t_g, g = _series(gnss_dir, 6)
    _refuse_nonfinite(g[:, :2], gnss_dir / "value", ("lat", "lon"))
    t_g, kept = _checked(t_g, gnss_dir, "gps", "gnss", warnings)
    if t_g.size == 0:
        raise DataError(gnss_dir, "no GNSS fixes")
    lat, lon = take(g[:, 0], kept), take(g[:, 1], kept)
    validate_latlon(lat, lon, str(gnss_dir / "value"))
    lat0, lon0 = float(lat[0]), float(lon[0])
    t_g = t_g - gnss_lag_s

    imu_dir = log / "IMU"
    t_a, acc = _series(imu_dir / "accelerometer", 3)
    t_w, gyr = _series(imu_dir / "gyro", 3)
    _refuse_nonfinite(acc[:, :2], imu_dir / "accelerometer" / "value", ("forward", "right"))
    _refuse_nonfinite(gyr[:, 2:3], imu_dir / "gyro" / "value", ("down",))
    t_a, kept = _checked(t_a, imu_dir / "accelerometer", "imu", "imu accelerometer", warnings)
    ac = {"f": take(acc[:, 0], kept), "r": take(acc[:, 1], kept)}
    t_w, kept = _checked(t_w, imu_dir / "gyro", "imu", "imu gyro", warnings)
    wc = {"d": take(gyr[:, 2], kept)}
    if t_w.size and not (t_w.size == t_a.size and np.array_equal(t_w, t_a)):
        warnings.append("imu: gyro interpolated linearly to the accelerometer times")
    yaw_rate = (
        -np.interp(t_a, t_w, wc["d"], left=np.nan, right=np.nan)
        if t_w.size
        else np.full(t_a.size, np.nan)
    )
    ax, ay = ac["f"], -ac["r"]

    t_s, sp = _series(log / "CAN" / "speed", 1)
    _refuse_nonfinite(sp[:, :1], log / "CAN" / "speed" / "value", ("speed",))
    t_s, kept = _checked(t_s, log / "CAN" / "speed", "speed", "can speed", warnings)
    sc = {"v": take(sp[:, 0], kept)}

    pose = path / "global_pose"
    t_p = _load(pose / "frame_times", (1,))
    pos = _load(pose / "frame_positions", (2,), 3)
    quat = _load(pose / "frame_orientations", (2,), 4)
    vel = _load(pose / "frame_velocities", (2,), 3)
    for arr, nm, used in (
        (pos, "frame_positions", ("x", "y", "z")),
        (quat, "frame_orientations", ("w", "x", "y", "z")),
        (vel, "frame_velocities", ("x", "y", "z")),
    ):
        if arr.shape[0] != t_p.size:
            raise DataError(pose / nm, f"{arr.shape[0]} rows but frame_times has {t_p.size}")
        _refuse_nonfinite(arr[:, : len(used)], pose / nm, used)
    t_p, idx = _checked(t_p, pose, "truth", "global_pose", warnings, "frame_times")
    pos, quat, vel = pos[idx], quat[idx], vel[idx]
    if projection == "enu":
        xt, yt = ecef_to_local(pos, lat0, lon0)
    else:
        import pymap3d

        plat, plon, _ = pymap3d.ecef2geodetic(pos[:, 0], pos[:, 1], pos[:, 2])
        xt, yt = to_local(np.asarray(plat), np.asarray(plon), lat0, lon0, projection)
    x, y = to_local(lat, lon, lat0, lon0, projection)
    yaw_t = ecef_yaw(quat, lat0, lon0)
    v_t = np.linalg.norm(vel, axis=1)

    # one origin: the earliest sample of any stream
    starts = [a[0] for a in (t_g, t_a, t_s, t_p) if a.size]
    t0 = float(min(starts))
    extra: dict = {"gnss_lag_applied_s": gnss_lag_s}
    extra["gnss_lag_measured_s"] = measure_gnss_lag(t_g + gnss_lag_s, x, y, t_p, xt, yt)
    epoch = float("nan")
    gps_times = pose / "frame_gps_times"
    if gps_times.is_file():
        gw = _load(gps_times, (2,), 2)
        if gw.shape[0] == idx.size:
            gw = gw[idx]
            off = gw[:, 0] * 604800.0 + gw[:, 1] + GPS_UNIX_OFFSET_S - GPS_UTC_LEAP_S - t_p
            epoch = float(np.median(off) + t0)
            extra["boot_to_unix_spread_s"] = float(np.ptp(off))

    name = f"{path.parent.name}/{path.name}"
    meta = DriveMeta(
        name=name,
        source=str(path),
        format="comma2k19",
        epoch_s=epoch,
        origin_lat=lat0,
        origin_lon=lon0,
        projection=projection,
        time_source="device boot clock (processed_log t); epoch from "
        "global_pose/frame_gps_times, GPS-UTC = 18 s",
        warnings=warnings,
        extra=extra,
    )
    return Drive(
        meta=meta,
        gps=GpsStream(t_g - t0, x, y, lat=lat, lon=lon),
        imu=ImuStream(t_a - t0, ax, ay, yaw=None, yaw_rate=yaw_rate),
        speed=SpeedStream(t_s - t0, sc["v"]),
        truth=TruthStream(t_p - t0, xt, yt, yaw=yaw_t, v=v_t),
    )
