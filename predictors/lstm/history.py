"""The fix and IMU histories a step of the ``lstm`` (and ``hybrid``) predictors fits:
append-only ring buffers of float64 rows (times [s] first), and the window of the fused
step (:mod:`posbench.predictors.lstm.fused`) at the newest fix."""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right

import numpy as np

from posbench.predictors.lstm.features import gps_substitute_imu
from posbench.predictors.lstm.fused import FusedStep
from posbench.predictors.lstm.resample import (
    ACCEL_GLITCH,
    GRID_OFFSETS,
    MIN_SPAN_S,
    eval_poly,
    fit_poly,
)

FIX_CAP = 512
IMU_CAP = 8192


class RowBuffer:
    """Append-only float64 rows with a capacity; keeps the newest half when full.

    ``t`` mirrors the first column (times [s], increasing) as a list of floats, for
    :mod:`bisect` searches (~10x cheaper than ``np.searchsorted`` on one value)."""

    def __init__(self, cap: int, k: int) -> None:
        self.a = np.empty((cap, k))
        self.n = 0
        self.t: list[float] = []

    def append(self, row: tuple) -> None:
        if self.n == self.a.shape[0]:
            h = self.a.shape[0] // 2
            self.a[:h] = self.a[self.n - h : self.n]
            del self.t[: self.n - h]
            self.n = h
        self.a[self.n] = row
        self.t.append(float(row[0]))
        self.n += 1

    def pop(self) -> None:
        """Drop the newest row."""
        self.n -= 1
        self.t.pop()

    def clear(self) -> None:
        self.n = 0
        self.t.clear()

    def view(self) -> np.ndarray:
        return self.a[: self.n]


class ImuHistory(RowBuffer):
    """The IMU samples a step fits: rows t [s], ax, ay [m/s^2, vehicle frame], yaw [rad,
    unwrapped across samples; NaN if unknown], in time order. ``t_yaw_nan`` is the time [s]
    of the newest sample without yaw (windows older than it use the yaw)."""

    def __init__(self, cap: int = IMU_CAP) -> None:
        super().__init__(cap, 4)
        self._yaw_raw = math.nan
        self._yaw_u = math.nan
        self.t_yaw_nan = -math.inf

    def add(self, t: float, ax: float, ay: float, yaw: float) -> None:
        """One sample; dropped if ax or ay is not finite or beyond ACCEL_GLITCH, or if it is
        not newer than the newest kept sample."""
        if not (math.isfinite(ax) and math.isfinite(ay)) or max(abs(ax), abs(ay)) > ACCEL_GLITCH:
            return
        if self.n and t <= self.t[-1]:
            return
        if math.isfinite(yaw):
            if math.isfinite(self._yaw_u):
                self._yaw_u += (yaw - self._yaw_raw + math.pi) % (2 * math.pi) - math.pi
            else:
                self._yaw_u = yaw
            self._yaw_raw = yaw
            yu = self._yaw_u
        else:
            yu = math.nan
            self.t_yaw_nan = t
        self.append((t, ax, ay, yu))


def fit_fused_window(f: FusedStep, fb: RowBuffer, im: ImuHistory, t_end: float) -> bool:
    """The fused step's window at the newest fix (time ``t_end`` [s], the last row of ``fb``):
    the fixes spanning >= MIN_SPAN_S and the IMU samples within them, fitted by ``f.fit``.
    False (nothing fitted) when the window has fewer than 4 fixes or spans < MIN_SPAN_S."""
    tl = fb.t
    end = fb.n - 1
    start = max(bisect_right(tl, t_end - MIN_SPAN_S) - 1, 0)
    t0 = tl[start]
    if end - start < 3 or t_end - t0 < MIN_SPAN_S:
        return False
    imu = None
    yaw_ok = True
    if im.n > 3:
        it = im.t
        i0 = bisect_left(it, t0)
        i1 = bisect_right(it, t_end)
        if i1 - i0 > 3:
            imu = im.a[i0:i1]
            yaw_ok = im.t_yaw_nan < it[i0]
    f.fit(fb.a[start : end + 1], imu, t_end, yaw_ok)
    return True


def fit_window(tt: np.ndarray, y: np.ndarray, t_ref: float, scale: float, fit: str) -> np.ndarray:
    """The cubic (coefficients in ``(t - t_ref) / scale``) through a window's samples
    ``y`` at times ``tt`` [s]: closed form (``fit="closed"``) or the paper's L-BFGS
    regression (``"lbfgs"``)."""
    if fit == "lbfgs":
        from posbench.predictors.cubic import fit_cubic_lbfgs

        return fit_cubic_lbfgs(tt, y, t_ref=t_ref, scale=scale).coef
    return fit_poly(tt, y, t_ref, scale)


def imu_on_grid(
    im: ImuHistory, t0: float, t_end: float, coef: np.ndarray, scale: float, fit: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ax, ay [m/s^2, vehicle frame] and yaw [rad] on the grid ending at ``t_end`` [s]: a
    cubic through the IMU samples over [t0, t_end], or the stand-ins of the GPS curve
    ``coef`` (in ``(t - t_end) / scale``) where the IMU (or its yaw) is missing."""
    a = im.view()
    vals = None
    if a.shape[0] > 3:
        ti = a[:, 0]
        i0 = int(np.searchsorted(ti, t0, side="left"))
        i1 = int(np.searchsorted(ti, t_end, side="right"))
        if i1 - i0 > 3:
            tt = ti[i0:i1]
            sc = max(t_end - t0, 1e-3)
            yv = a[i0:i1, 1:] if im.t_yaw_nan < tt[0] else a[i0:i1, 1:3]
            vals = eval_poly(fit_window(tt, yv, t_end, sc, fit), GRID_OFFSETS / sc)
    if vals is not None and vals.shape[1] == 3:
        return vals[:, 0], vals[:, 1], vals[:, 2]
    sax, say, syaw = gps_substitute_imu(coef, scale, GRID_OFFSETS / scale)
    if vals is not None:
        return vals[:, 0], vals[:, 1], syaw
    return sax, say, syaw
