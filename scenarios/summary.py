"""What is in a drive, at a glance: pure figures for ``bench data inspect``."""

from __future__ import annotations

from typing import Any

import numpy as np

from posbench.scenarios.drive import Drive

STANDSTILL_MPS = 0.15 / 3.6  # the paper's 0.15 km/h


def _path_length(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.hypot(np.diff(x), np.diff(y)).sum()) if x.size > 1 else 0.0


def _speed_series(drive: Drive) -> np.ndarray:
    """Best available speed samples [m/s]: CAN/wheel, truth v, else positions differenced
    over >= 0.5 s."""
    if drive.speed is not None and len(drive.speed):
        return drive.speed.v
    if drive.truth is not None and drive.truth.v is not None:
        return drive.truth.v
    src = drive.truth if drive.truth is not None else drive.gps
    if len(src) < 2:
        return np.empty(0)
    # displacement over at least 0.5 s: a stale repeated fix followed by a fresh one a few
    # milliseconds later must not read as a 70 m/s jump
    j = np.searchsorted(src.t, src.t + 0.5)
    ok = j < len(src)
    i, j = np.flatnonzero(ok), j[ok]
    return np.hypot(src.x[j] - src.x[i], src.y[j] - src.y[i]) / (src.t[j] - src.t[i])


def drive_label_shares(drive: Drive, step_s: float = 0.1) -> dict[str, float]:
    """Share [0..1] of the drive's time per scenario label, labelled every ``step_s`` from
    the truth (or the drive's own fixes where it has none) and the wheel speed if any."""
    from posbench.scenarios.labels import LABELS, label_shares, label_times

    track = drive.truth if drive.truth is not None else drive.gps
    if len(track) < 8:
        return {lab: float("nan") for lab in LABELS}
    tq = np.arange(track.t[0], track.t[-1], step_s)
    sp = drive.speed
    labels = label_times(
        tq,
        track.t,
        track.x,
        track.y,
        speed_t=None if sp is None else sp.t,
        speed_v=None if sp is None else sp.v,
    )
    return label_shares(labels)


def summarize_drive(drive: Drive) -> dict[str, Any]:
    """Figures for one drive: duration [s], distance [m], fix count and interval
    percentiles [ms], IMU rate [Hz], speed range [m/s], fraction stopped, share of each
    scenario label, truth and its median accuracy [m], warnings."""
    gps = drive.gps
    dt_ms = np.diff(gps.t) * 1e3
    q = (
        (np.percentile(dt_ms, [5, 50, 95]).tolist() + [float(dt_ms.max())])
        if dt_ms.size
        else [float("nan")] * 4
    )
    track = drive.truth if drive.truth is not None else gps
    v = _speed_series(drive)
    imu_rate = (
        float((len(drive.imu) - 1) / (drive.imu.t[-1] - drive.imu.t[0]))
        if drive.imu is not None and len(drive.imu) > 1
        else 0.0
    )
    return {
        "name": drive.name,
        "format": drive.meta.format,
        "source": drive.meta.source,
        "duration_s": drive.duration_s,
        "distance_m": _path_length(track.x, track.y),
        "gps_count": len(gps),
        "gps_interval_ms": {"p5": q[0], "p50": q[1], "p95": q[2], "max": q[3]},
        "imu_rate_hz": imu_rate,
        "imu_has_yaw": bool(drive.imu is not None and drive.imu.yaw is not None),
        "has_speed": drive.speed is not None,
        "speed_mps": {
            "min": float(np.min(v)) if v.size else float("nan"),
            "max": float(np.max(v)) if v.size else float("nan"),
        },
        "fraction_stopped": float(np.mean(v < STANDSTILL_MPS)) if v.size else float("nan"),
        "label_shares": drive_label_shares(drive),
        "has_truth": drive.truth is not None,
        "truth_median_accuracy_m": drive.truth_median_accuracy_m,
        "projection": drive.meta.projection,
        "time_source": drive.meta.time_source,
        "warnings": list(drive.meta.warnings),
    }
