"""Loader for the paper's route pickles (``aslan/*.pickle``, authors' ``pickled_bags/``).

A pickle is ``{window_index: window}``; windows overlap (stride mostly one fix).
A window holds ``tstamps`` (8 fix times, int ns since the Unix epoch),
``ground_truth`` (8, 2) fixes [m, route frame, origin (0, 0)], ``ACCEL`` tuples
``(t_ns as str, ax, ay)`` [m/s^2, vehicle frame], ``theta`` [rad] at the
window's last fix, plus ``X``/``Y`` (untimed raw positions) and the previous
window's fixes (``old_tstamps``, ``ground_truth_old``). It is read with
:mod:`posbench.scenarios.safe_pickle` (NumPy arrays and containers only).

What was measured on the 15 routes in ``shared/data/aslan`` (ad-hoc scripts; the
route-level checks are repeated in tests/scenarios/test_loader_aslan.py) and what the
loader does about it:

- Fixes: union over windows of ``(tstamps, ground_truth)``. No stamp ever maps
  to two positions (checked; counted in warnings if it happens). 35 fixes come
  < 1 ms (3-31 us) after the previous one; they are a stale re-publication of
  the fix before, paired with a half-updated fix, and would imply km/s speeds:
  the later one of each pair is dropped (counted). 335 fixes repeat the previous
  position exactly (stale GPS, 20-180 ms later, median 99 ms); they are kept, as the
  paper saw them, and counted in warnings.
- IMU: union of ``ACCEL``. 24 % of samples (25 023 of 102 438) come < 0.5 ms
  after the previous one, 99 % of them with identical values: duplicated
  messages, dropped (counted). |a| is < 4 m/s^2 for 99.9 % of samples, then
  nothing between 15 and 30; 351 isolated single-sample glitches of 30-500 m/s^2
  are dropped (|a| > :data:`ACCEL_GLITCH_MPS2`, counted). After cleaning the
  nominal rate is 50 Hz (median interval 20 ms), but with gaps: 77 064 samples
  over 2130 s is 36 Hz effective, 33 % of the time lies in intervals > 40 ms
  (p95 60 ms, max 0.9 s).
- Yaw: ``theta`` is in the route frame with ENU convention (0 = +x,
  counter-clockwise positive): against ``atan2`` of the fix track's direction
  (+-0.4 s, speed > 2 m/s) the median offset is 0.000 rad (|median| <= 0.003 on
  every route), MAD 0.005-0.010 rad; no sign flip or quarter-turn offset. But it
  is *not* an independent IMU heading: in 86-97 % of windows (last step > 0.4 m)
  it equals ``atan2`` of the window's last two fixes to < 1e-3 rad, i.e. a GPS
  course. It is known only at its window's last fix, so the IMU ``yaw`` column
  holds the latest ``theta`` (zero-order hold, NaN before the first window
  ends); interpolating between windows would leak the next fix's direction
  into the samples before it.
- ``X``/``Y``: 23 269 untimed raw positions (0-25 per window, median 2) lying on
  the segment between the window's last two fixes (median 0.44 of the way,
  0.9 cm off it). Not used: without time stamps they cannot be placed in time
  without inventing stamps, and they are a denser GPS than the benchmark's
  premise of slow fixes; the count is kept in ``meta.extra``.
- Positions are metres already (projection ``"source"``, origin lat/lon NaN);
  there is no independent truth (the paper scored against a cubic fitted
  through past and future fixes) and no speed stream.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, ImuStream
from posbench.scenarios.errors import DataError
from posbench.scenarios.safe_pickle import safe_load
from posbench.scenarios.time_axis import check_stream_times

#: |a| [m/s^2] above which an ACCEL sample is a glitch (3 g; real samples < 15 m/s^2).
ACCEL_GLITCH_MPS2 = 30.0
#: a sample closer than this [s] to the previous one is a duplicate message.
BURST_S = 1e-3

#: Empirical fix intervals [s] of all 15 routes, as loaded (after dropping the
#: 35 sub-millisecond duplicates): quantiles 0, 5, 10, ..., 100 % of the 10 406
#: intervals. Measured with
#: ``python -c "from posbench.scenarios.loaders.aslan import fix_interval_quantiles as q;
#: print(q('../shared/data/aslan'))"``. p5 122 ms, p25 197, p50 200, p75 202,
#: p95 264, max 1002 ms (min 17 ms). Draw intervals by inverse-CDF interpolation
#: (``np.interp(u, np.linspace(0, 1, 21), ASLAN_FIX_INTERVAL_QUANTILES_S)``).
ASLAN_FIX_INTERVAL_QUANTILES_S = np.array(
    [
        0.016759,
        0.121838,
        0.176081,
        0.180101,
        0.196006,
        0.197184,
        0.198696,
        0.199131,
        0.199443,
        0.199715,
        0.199934,
        0.200098,
        0.200369,
        0.200667,
        0.201004,
        0.201672,
        0.203134,
        0.217133,
        0.220959,
        0.263626,
        1.002175,
    ]
)

_REQUIRED = ("tstamps", "ground_truth", "ACCEL", "theta")


def _windows(raw: Any, path: Path) -> list[tuple[Any, dict]]:
    """The windows in index order, each checked for the keys the loader needs."""
    if not isinstance(raw, dict) or not raw:
        raise DataError(
            path,
            "not a route pickle: expected a non-empty dict "
            f"{{window_index: window}}, got {type(raw).__name__}",
        )
    try:
        keys = sorted(raw)
    except TypeError:
        keys = list(raw)
    out = []
    for k in keys:
        w = raw[k]
        if not isinstance(w, dict):
            raise DataError(path, f"window {k!r}: expected a dict, got {type(w).__name__}")
        missing = [n for n in _REQUIRED if n not in w]
        if missing:
            raise DataError(path, f"window {k!r}: missing key(s) {', '.join(missing)}")
        out.append((k, w))
    return out


def _fix_rows(windows: list[tuple[Any, dict]], path: Path) -> tuple[np.ndarray, np.ndarray]:
    """All windows' fixes concatenated: stamps [int ns] (n,), positions [m] (n, 2)."""
    ts, ps = [], []
    for k, w in windows:
        try:
            t = np.asarray(w["tstamps"], dtype=np.int64).reshape(-1)
            p = np.asarray(w["ground_truth"], dtype=float)
        except (TypeError, ValueError, OverflowError) as exc:
            raise DataError(
                path,
                f"window {k!r}: tstamps / ground_truth are not numbers "
                f"({type(exc).__name__}: {exc})",
            ) from None
        if p.ndim != 2 or p.shape != (t.size, 2):
            raise DataError(
                path,
                f"window {k!r}: ground_truth has shape {p.shape}, "
                f"expected ({t.size}, 2) to match tstamps",
            )
        _refuse_nonfinite(p, path, k, "ground_truth")
        ts.append(t)
        ps.append(p)
    return np.concatenate(ts), np.concatenate(ps)


def _accel_rows(windows: list[tuple[Any, dict]], path: Path) -> tuple[np.ndarray, np.ndarray]:
    """All windows' ACCEL tuples concatenated: stamps [int ns] (n,), (ax, ay) [m/s^2] (n, 2)."""
    ts: list[int] = []
    vals: list[tuple[float, float]] = []
    for k, w in windows:
        rows: list[tuple[float, float]] = []
        for i, row in enumerate(w["ACCEL"]):
            try:
                t_s, ax, ay = row
                ts.append(int(t_s))
                rows.append((float(ax), float(ay)))
            except (TypeError, ValueError):
                raise DataError(
                    path, f"window {k!r}: ACCEL row {i} is not (t_ns, ax, ay): {row!r}"
                ) from None
        _refuse_nonfinite(np.asarray(rows, dtype=float).reshape(-1, 2), path, k, "ACCEL (ax, ay)")
        vals.extend(rows)
    return np.asarray(ts, dtype=np.int64), np.asarray(vals, dtype=float).reshape(-1, 2)


def _refuse_nonfinite(values: np.ndarray, path: Path, window: Any, what: str) -> None:
    """Refuse the first row of ``values`` (one window's ``what``) holding a NaN or infinity,
    naming the window and the row."""
    bad = ~np.all(np.isfinite(values.reshape(len(values), -1)), axis=1)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        shown = ", ".join(repr(float(a)) for a in values[i].reshape(-1))
        raise DataError(path, f"window {window!r}: {what} row {i} is not finite ({shown})")


def _checked(
    t_ns: np.ndarray, t0: int, windows: list[tuple[Any, dict]], kind: str, path: Path
) -> np.ndarray:
    """Times [s from ``t0``, ns] of a stream, checked
    (:func:`~posbench.scenarios.time_axis.check_stream_times`, naming the first window that
    holds a sample's stamp)."""
    key = "tstamps" if kind == "gps" else "ACCEL"

    def where(i: int) -> str:
        stamp = int(t_ns[i])
        for k, w in windows:
            stamps = w[key] if kind == "gps" else [r[0] for r in w[key]]
            if any(int(v) == stamp for v in stamps):
                return f"window {k!r} ({key} stamp {stamp} ns)"
        return f"stamp {stamp} ns"  # pragma: no cover - every stamp comes from a window

    t = (t_ns - t0) * 1e-9
    check_stream_times(t, kind, path, where)
    return t


def union_by_stamp(
    t_ns: np.ndarray, vals: np.ndarray, what: str, warnings: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Sort by stamp and keep one row per distinct stamp (the first window's).

    Rows sharing a stamp but not values are counted in ``warnings``.
    """
    if t_ns.size == 0:
        return t_ns, vals
    order = np.argsort(t_ns, kind="stable")
    t, v = t_ns[order], vals[order]
    first = np.ones(t.size, dtype=bool)
    first[1:] = t[1:] != t[:-1]
    group = np.cumsum(first) - 1
    ref = v[first][group]
    differs = ~np.all(np.isclose(v, ref, rtol=0.0, atol=1e-9, equal_nan=True), axis=1)
    if np.any(differs):
        n = np.unique(group[differs]).size
        warnings.append(
            f"{what}: {n} time stamps map to different values in different "
            "windows; kept the earliest window's"
        )
    return t[first], v[first]


def drop_bursts(
    t_ns: np.ndarray, vals: np.ndarray, what: str, warnings: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Drop samples < :data:`BURST_S` after the previous one (duplicated messages)."""
    if t_ns.size < 2:
        return t_ns, vals
    burst = np.zeros(t_ns.size, dtype=bool)
    burst[1:] = np.diff(t_ns) < int(BURST_S * 1e9)
    if np.any(burst):
        same = np.zeros_like(burst)
        same[1:] = np.all(vals[1:] == vals[:-1], axis=1)
        warnings.append(
            f"{what}: dropped {int(burst.sum())} samples < {BURST_S * 1e3:g} ms "
            f"after the previous one (duplicate messages; "
            f"{int((burst & ~same).sum())} with different values)"
        )
    return t_ns[~burst], vals[~burst]


def held_yaw(theta_t_ns: np.ndarray, theta: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
    """Latest ``theta`` [rad] stamped at or before each time in ``t_ns`` (NaN before the first)."""
    idx = np.searchsorted(theta_t_ns, t_ns, side="right") - 1
    out = np.full(t_ns.size, np.nan)
    ok = idx >= 0
    out[ok] = theta[idx[ok]]
    return out


def load_aslan_pickle(path: Path) -> Drive:
    """Read one route pickle into a :class:`Drive`.

    Times: seconds from the earliest fix or IMU sample (``meta.epoch_s`` its Unix
    time). Positions: metres in the route's own frame (origin at the first fix),
    ``projection = "source"``. IMU: ax, ay [m/s^2, vehicle frame x fwd, y left],
    ``yaw`` [rad, route frame, 0 = +x, CCW] = the latest window's ``theta``
    (a GPS course, see the module notes). No speed, no truth.

    Raises:
        DataError: not a route pickle; a NaN or infinite fix position, ACCEL value or
            ``theta`` (naming the window and row); times that fail
            :func:`~posbench.scenarios.time_axis.check_stream_times` (unit, gaps).
    """
    path = Path(path)
    warnings: list[str] = []
    windows = _windows(safe_load(path), path)

    # fixes
    ft, fp = _fix_rows(windows, path)
    ft, fp = union_by_stamp(ft, fp, "gps", warnings)
    ft, fp = drop_bursts(ft, fp, "gps", warnings)
    if ft.size == 0:
        raise DataError(path, "no GPS fixes in any window")
    stale = int(np.all(fp[1:] == fp[:-1], axis=1).sum()) if ft.size > 1 else 0
    if stale:
        warnings.append(
            f"gps: {stale} fixes repeat the previous position exactly (stale GPS, kept)"
        )

    # IMU
    at, av = _accel_rows(windows, path)
    at, av = union_by_stamp(at, av, "imu", warnings)
    at, av = drop_bursts(at, av, "imu", warnings)
    glitch = np.hypot(av[:, 0], av[:, 1]) > ACCEL_GLITCH_MPS2
    if np.any(glitch):
        warnings.append(
            f"imu: dropped {int(glitch.sum())} acceleration glitches with "
            f"|a| > {ACCEL_GLITCH_MPS2:g} m/s^2"
        )
        at, av = at[~glitch], av[~glitch]

    # yaw: theta at each window's last fix, held until the next window's
    th_t = np.asarray(
        [int(w["tstamps"][-1]) for _, w in windows if len(w["tstamps"])], dtype=np.int64
    )
    th = np.asarray([float(w["theta"]) for _, w in windows if len(w["tstamps"])], dtype=float)
    keys = [k for k, w in windows if len(w["tstamps"])]
    if not np.all(np.isfinite(th)):
        i = int(np.flatnonzero(~np.isfinite(th))[0])
        raise DataError(path, f"window {keys[i]!r}: theta is not finite ({float(th[i])!r})")
    th_t, th2 = union_by_stamp(th_t, th[:, None], "yaw", warnings)
    th = th2[:, 0]

    t0 = int(min(ft[0], at[0])) if at.size else int(ft[0])
    n_xy = sum(len(w.get("X", ())) for _, w in windows)
    meta = DriveMeta(
        name=path.stem,
        source=str(path),
        format="aslan",
        epoch_s=t0 / 1e9,
        projection="source",
        time_source="recorded stamps (ns since the Unix epoch)",
        warnings=warnings,
        extra={
            "windows": len(windows),
            "raw_xy_unused": int(n_xy),
            "yaw_source": "theta per window = GPS course (atan2 of the last two fixes), "
            "held from each window's last fix",
        },
    )
    gps = GpsStream(_checked(ft, t0, windows, "gps", path), fp[:, 0], fp[:, 1])
    imu = None
    if at.size:
        t_imu = _checked(at, t0, windows, "imu", path)
        imu = ImuStream(t_imu, av[:, 0], av[:, 1], yaw=held_yaw(th_t, th, at))
    return Drive(meta=meta, gps=gps, imu=imu)


def fix_interval_quantiles(folder: str | Path, n: int = 21) -> np.ndarray:
    """Quantiles (0..100 %, ``n`` of them) of all fix intervals [s] of the pickles
    under ``folder``."""
    from posbench.scenarios.loaders import load

    dts = [np.diff(d.gps.t) for d in load(folder) if d.meta.format == "aslan"]
    return np.quantile(np.concatenate(dts), np.linspace(0.0, 1.0, n))
