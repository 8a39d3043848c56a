"""The :class:`Drive` model: one recording as time-stamped numpy streams.

Conventions (all streams):
- times ``t`` are float64 seconds from the drive's start (``meta.epoch_s`` is
  the absolute Unix time of t = 0), strictly increasing;
- positions are local metres in the drive's projection (default ENU about the
  first fix: x east, y north);
- vehicle-frame accelerations: x forward, y left, m/s^2;
- yaw in radians, ENU convention (0 = east, counter-clockwise positive);
- optional columns are ``None`` when the source does not have them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from posbench.scenarios.errors import DataError
from posbench.scenarios.time_axis import check_span


def _f64(a: Any) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64))


def _opt(a: Any) -> np.ndarray | None:
    return None if a is None else _f64(a)


def _check(name: str, t: np.ndarray, cols: dict[str, np.ndarray | None]) -> None:
    if t.ndim != 1:
        raise ValueError(f"{name}.t must be 1-D")
    for key, col in cols.items():
        if col is not None and col.shape != t.shape:
            raise ValueError(f"{name}.{key} has shape {col.shape}, expected {t.shape}")
    if t.size and not np.all(np.isfinite(t)):
        raise ValueError(f"{name}.t has non-finite times")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise ValueError(f"{name}.t is not strictly increasing")


@dataclass(frozen=True)
class GpsStream:
    """GNSS fixes. t [s], x/y [m, local frame], lat/lon [deg], accuracy [m].

    ``accuracy`` is the fix's stated horizontal accuracy as a **per-axis 1-sigma standard
    deviation [m]**: the error of x (east) and of y (north) are each taken as zero-mean with
    this standard deviation, equal on both axes and uncorrelated (covariance
    ``accuracy**2 * I2`` [m^2], ENU). It is what the source *states*, not a measured error.
    NaN marks a fix without a stated accuracy; ``None`` a stream without any. Per source:
    ROS NavSatFix ``sqrt((cov[0] + cov[4]) / 2)`` (NaN when ``position_covariance_type`` is
    UNKNOWN); KITTI OXTS ``pos_accuracy``; CSV/Parquet column ``accuracy``; the
    degradation profiles (:mod:`posbench.scenarios.degrade`) their stated sigma; comma2k19 and the
    paper's routes: none.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lat: np.ndarray | None = None
    lon: np.ndarray | None = None
    accuracy: np.ndarray | None = None

    def __post_init__(self) -> None:
        for k in ("t", "x", "y"):
            object.__setattr__(self, k, _f64(getattr(self, k)))
        for k in ("lat", "lon", "accuracy"):
            object.__setattr__(self, k, _opt(getattr(self, k)))
        _check(
            "gps",
            self.t,
            {"x": self.x, "y": self.y, "lat": self.lat, "lon": self.lon, "accuracy": self.accuracy},
        )

    def __len__(self) -> int:
        return int(self.t.size)

    def take(self, idx: np.ndarray) -> GpsStream:
        """A sub-stream of the fixes selected by a boolean mask or index array."""
        return GpsStream(
            self.t[idx],
            self.x[idx],
            self.y[idx],
            None if self.lat is None else self.lat[idx],
            None if self.lon is None else self.lon[idx],
            None if self.accuracy is None else self.accuracy[idx],
        )


@dataclass(frozen=True)
class ImuStream:
    """IMU samples. ax/ay [m/s^2, vehicle frame x fwd, y left], yaw [rad, ENU], yaw_rate [rad/s]."""

    t: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    yaw: np.ndarray | None = None
    yaw_rate: np.ndarray | None = None

    def __post_init__(self) -> None:
        for k in ("t", "ax", "ay"):
            object.__setattr__(self, k, _f64(getattr(self, k)))
        for k in ("yaw", "yaw_rate"):
            object.__setattr__(self, k, _opt(getattr(self, k)))
        _check(
            "imu",
            self.t,
            {"ax": self.ax, "ay": self.ay, "yaw": self.yaw, "yaw_rate": self.yaw_rate},
        )

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class SpeedStream:
    """Vehicle speed (CAN / wheel), v [m/s]."""

    t: np.ndarray
    v: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _f64(self.t))
        object.__setattr__(self, "v", _f64(self.v))
        _check("speed", self.t, {"v": self.v})

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class TruthStream:
    """Independent reference track: x/y [m, local frame], yaw [rad, ENU], v [m/s]."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray | None = None
    v: np.ndarray | None = None
    accuracy: np.ndarray | None = None

    def __post_init__(self) -> None:
        for k in ("t", "x", "y"):
            object.__setattr__(self, k, _f64(getattr(self, k)))
        for k in ("yaw", "v", "accuracy"):
            object.__setattr__(self, k, _opt(getattr(self, k)))
        _check(
            "truth",
            self.t,
            {"x": self.x, "y": self.y, "yaw": self.yaw, "v": self.v, "accuracy": self.accuracy},
        )

    def __len__(self) -> int:
        return int(self.t.size)


#: a position farther than this from a drive's origin [m] is no position: farther than any
#: point on Earth (its diameter is 1.3e7 m); a loader refuses it, as ``bench score`` refuses
#: such answers
MAX_POSITION_M = 1e9


def far_position(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[int, str, int] | None:
    """The first sample of a track with a coordinate beyond :data:`MAX_POSITION_M` (index,
    ``"x"`` or ``"y"``, how many such samples in all), or None."""
    far_x, far_y = np.abs(x) > MAX_POSITION_M, np.abs(y) > MAX_POSITION_M
    far = far_x | far_y
    if not far.any():
        return None
    i = int(np.flatnonzero(far)[0])
    return i, "x" if far_x[i] else "y", int(far.sum())


def refuse_far_positions(drive: Drive, path: Any) -> None:
    """Raise a :class:`DataError` for ``path`` naming the first fix or truth sample of
    ``drive`` beyond :data:`MAX_POSITION_M` of its origin (a loader's last check)."""
    for what, s in (("fix", drive.gps), ("truth sample", drive.truth)):
        if s is None or not len(s):
            continue
        found = far_position(s.t, s.x, s.y)
        if found is not None:
            i, axis, n = found
            value = float(getattr(s, axis)[i])
            raise DataError(
                path,
                f"{what} at t={float(s.t[i]):.3f} s: {axis} = {value:g} m is no position: "
                f"more than {MAX_POSITION_M:g} m from the drive's origin, farther than any "
                f"point on Earth; {n} such {what}{'s' * (n != 1)} in all",
            )


#: ``DriveMeta.fix_source``: the fixes come from a receiver independent of the truth
FIXES_RECEIVER = "receiver"
#: ``DriveMeta.fix_source``: the fixes are the truth's positions or were simulated from it
FIXES_FROM_TRUTH = "truth"


@dataclass
class DriveMeta:
    """Where a drive came from and what a loader did to it.

    ``epoch_s`` is the Unix time [s] of t = 0 (NaN when unknown); ``origin_lat`` /
    ``origin_lon`` [deg] the local frame's origin (NaN for sources already in metres);
    ``projection`` is ``"enu"`` or ``"mercator"`` (or ``"source"`` when the data came
    in metres); ``warnings`` counts everything a loader removed, re-ordered or doubts.
    ``fix_source`` says where the GPS fixes come from: :data:`FIXES_RECEIVER` (a receiver
    of their own, independent of the truth: they are what a run scores by default) or
    :data:`FIXES_FROM_TRUTH` (the fixes are the truth's own positions, as KITTI's OXTS, or
    were simulated from it, as the synthetic drives: a run draws its fixes from the truth).
    """

    name: str
    source: str
    format: str
    epoch_s: float = float("nan")
    origin_lat: float = float("nan")
    origin_lon: float = float("nan")
    projection: str = "enu"
    time_source: str = ""
    warnings: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    fix_source: str = "receiver"


@dataclass(frozen=True)
class Drive:
    """One recording: GPS (required), IMU, speed and truth streams, plus metadata.

    Its streams together span at most :data:`~posbench.scenarios.time_axis.MAX_SPAN_S`
    (:func:`~posbench.scenarios.time_axis.check_span`, a :class:`DataError` otherwise), which
    bounds every array sized by a drive's span.
    """

    meta: DriveMeta
    gps: GpsStream
    imu: ImuStream | None = None
    speed: SpeedStream | None = None
    truth: TruthStream | None = None

    def __post_init__(self) -> None:
        if len(self.gps) == 0 and self.truth is None:
            raise DataError(self.meta.source, "drive has no GPS fixes")
        streams = {"gps": self.gps, "imu": self.imu, "speed": self.speed, "truth": self.truth}
        check_span({k: s.t for k, s in streams.items() if s is not None}, self.meta.source)

    @property
    def name(self) -> str:
        return self.meta.name

    @property
    def duration_s(self) -> float:
        """Time span [s] covered by any stream."""
        ends = [
            s.t[-1]
            for s in (self.gps, self.imu, self.speed, self.truth)
            if s is not None and len(s)
        ]
        starts = [
            s.t[0] for s in (self.gps, self.imu, self.speed, self.truth) if s is not None and len(s)
        ]
        return float(max(ends) - min(starts)) if ends else 0.0

    @property
    def fix_count(self) -> int:
        """The drive's GPS fixes."""
        return len(self.gps)

    @property
    def has_truth(self) -> bool:
        """Whether the drive holds a truth stream."""
        return self.truth is not None

    @property
    def fixes_from_truth(self) -> bool:
        """Whether the drive's GPS fixes are no receiver of their own: the loader says they
        are the truth's positions or simulated from it (``meta.fix_source``), the drive has
        truth but no fixes, or every fix lies on the truth (within 1 mm at its time)."""
        if self.truth is None:
            return False
        if self.meta.fix_source == FIXES_FROM_TRUTH or len(self.gps) == 0:
            return True
        if len(self.truth) < 2:
            return False
        inside = (self.gps.t >= self.truth.t[0]) & (self.gps.t <= self.truth.t[-1])
        if not inside.all():
            return False
        dx = self.gps.x - np.interp(self.gps.t, self.truth.t, self.truth.x)
        dy = self.gps.y - np.interp(self.gps.t, self.truth.t, self.truth.y)
        return bool(np.nanmax(np.hypot(dx, dy)) < 1e-3)

    @property
    def truth_median_accuracy_m(self) -> float | None:
        """Median horizontal accuracy [m] of the truth, if the source reports one."""
        if self.truth is None or self.truth.accuracy is None:
            return None
        acc = self.truth.accuracy[np.isfinite(self.truth.accuracy)]
        return float(np.median(acc)) if acc.size else None

    def window(self, t0: float, t1: float) -> Drive:
        """A copy holding only the samples with t0 <= t <= t1 [s] of every stream."""

        def cut(stream: Any) -> Any:
            if stream is None:
                return None
            m = (stream.t >= t0) & (stream.t <= t1)
            kw = {
                f: (None if getattr(stream, f) is None else getattr(stream, f)[m])
                for f in stream.__dataclass_fields__
            }
            return type(stream)(**kw)

        return replace(
            self, gps=cut(self.gps), imu=cut(self.imu), speed=cut(self.speed), truth=cut(self.truth)
        )

    def with_gps(self, gps: GpsStream, note: str | None = None) -> Drive:
        """A copy with another GPS stream (e.g. degraded), noting why in the warnings."""
        meta = replace(self.meta, warnings=list(self.meta.warnings))
        if note:
            meta.warnings.append(note)
        return replace(self, gps=gps, meta=meta)
