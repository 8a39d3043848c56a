"""Small helpers shared by the baseline predictors: frame rotation, angle wrapping,
a preallocated buffer of recent fixes, configuration checks.

Frames: vehicle (x forward, y left) and local ENU (x east, y north); yaw [rad] is
the vehicle's heading in ENU (0 = east, counter-clockwise positive). Plain floats
on purpose: these run at IMU rate, where numpy's per-call overhead dominates.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.scenarios.errors import DataError
from posbench.scenarios.text import quoted

TWO_PI = 2.0 * math.pi
#: the range of every baseline's ``cov_scale`` (kf, ekf, cv and their banks): what their
#: constructors accept, and what ``bench tune`` holds a calibrated scale in
COV_SCALE_RANGE = (1e-6, 1e6)


def wrap_angle(a: float) -> float:
    """Angle a [rad] wrapped to [-pi, pi)."""
    return (a + math.pi) % TWO_PI - math.pi


def vehicle_to_world(ax: float, ay: float, yaw: float) -> tuple[float, float]:
    """Rotate a vehicle-frame vector (x forward, y left) by yaw [rad] into ENU."""
    c = math.cos(yaw)
    s = math.sin(yaw)
    return c * ax - s * ay, s * ax + c * ay


def finite(v: float) -> bool:
    """True for a finite float (NaN / inf mark missing values)."""
    return math.isfinite(v)


def check_config(owner: str, **checks: tuple[float, float, float]) -> None:
    """Raise :class:`DataError` unless each ``name=(value, low, high)`` has low <= value <= high."""
    for name, (value, low, high) in checks.items():
        if not (isinstance(value, int | float) and low <= value <= high):
            raise DataError(None, f"{owner}: {name}={quoted(value)} must be in [{low}, {high}]")


class FixBuffer:
    """The most recent GNSS fixes in preallocated arrays (oldest first).

    ``t``, ``x``, ``y`` expose contiguous views of the stored fixes. Appending is
    O(1) amortised: when the backing store is full, the newest ``capacity`` fixes
    are moved to its start.
    """

    def __init__(self, capacity: int = 64) -> None:
        self.capacity = int(capacity)
        self._data = np.empty((3, 2 * self.capacity))
        self.n = 0
        self._start = 0

    def clear(self) -> None:
        self.n = 0
        self._start = 0

    def append(self, t: float, x: float, y: float) -> None:
        end = self._start + self.n
        if end == self._data.shape[1]:
            keep = min(self.n, self.capacity - 1)
            self._data[:, :keep] = self._data[:, end - keep : end]
            self._start, self.n, end = 0, keep, keep
        self._data[0, end] = t
        self._data[1, end] = x
        self._data[2, end] = y
        if self.n < self.capacity:
            self.n += 1
        else:
            self._start += 1

    @property
    def t(self) -> np.ndarray:
        return self._data[0, self._start : self._start + self.n]

    @property
    def x(self) -> np.ndarray:
        return self._data[1, self._start : self._start + self.n]

    @property
    def y(self) -> np.ndarray:
        return self._data[2, self._start : self._start + self.n]

    def xy_from(self, i: int) -> np.ndarray:
        """Positions of the fixes from view index i to the newest, shape (n - i, 2) (a view)."""
        return self._data[1:3, self._start + i : self._start + self.n].T

    def xy_rows_from(self, i: int) -> np.ndarray:
        """Positions of the fixes from view index i to the newest as rows x, y: shape
        (2, n - i), a view with contiguous rows."""
        return self._data[1:3, self._start + i : self._start + self.n]

    def last(self, k: int = 1) -> tuple[float, float, float]:
        """The k-th newest fix (k = 1: newest) as (t, x, y)."""
        i = self._start + self.n - k
        d = self._data
        return float(d[0, i]), float(d[1, i]), float(d[2, i])

    def last_velocity(self) -> tuple[float, float] | None:
        """Velocity [m/s] from the two newest fixes; None with fewer than two fixes or no
        time between them."""
        if self.n < 2:
            return None
        t0, x0, y0 = self.last(2)
        t1, x1, y1 = self.last(1)
        dt = t1 - t0
        if not dt > 0.0:
            return None
        return (x1 - x0) / dt, (y1 - y0) / dt

    def window_start(self, span_s: float, min_points: int = 1) -> int:
        """Index (into the views) of the oldest fix such that the fixes from it to the
        newest cover at least ``span_s`` seconds and number at least ``min_points``
        (all fixes when the history is shorter)."""
        if self.n == 0:
            return 0
        t = self.t
        i = int(np.searchsorted(t, t[-1] - span_s, side="right")) - 1
        i = min(max(i, 0), max(self.n - min_points, 0))
        return i
