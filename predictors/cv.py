"""Constant-velocity extrapolation from recent GNSS fixes (the simplest baseline).

Velocity [m/s] comes from the last two fixes (``window_s = 0``) or from a
least-squares line through the fixes of the last ``window_s`` seconds;
``position_at(t)`` extrapolates from the newest fix: p_last + v (t - t_last).
IMU and speed are ignored. Units: seconds, metres (local ENU).

Expected error on a circle of radius R at speed v with fixes every T seconds,
horizon h after the newest fix: the two-fix chord velocity lags the tangent by
half a fix interval, so the error is ~ v^2 h (h + T) / (2 R) (v^2 h^2 / (2 R)
for the exact tangent velocity).
"""

from __future__ import annotations

import math

import numpy as np

from predictors._geometry import FixBuffer, check_config
from predictors.base import Predictor

NAN2 = (math.nan, math.nan)


class ConstantVelocity(Predictor):
    """Constant velocity from the last two fixes or a line fit over ``window_s`` seconds.

    Args:
        window_s: 0 -> velocity from the last two fixes; > 0 -> least-squares slope of
            the fixes whose times lie within ``window_s`` [s] of the newest fix
            (at least two fixes are used).
    """

    name = "cv"

    def __init__(self, window_s: float = 0.0) -> None:
        check_config("cv", window_s=(window_s, 0.0, 60.0))
        self.window_s = float(window_s)
        self._buf = FixBuffer(256)
        self.reset()

    def config(self) -> dict:
        return {"window_s": self.window_s}

    def reset(self) -> None:
        self._buf.clear()
        self._t = math.nan
        self._x = math.nan
        self._y = math.nan
        self._vx = 0.0
        self._vy = 0.0

    def observe_gps(self, t: float, x: float, y: float) -> None:
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        buf = self._buf
        buf.append(t, x, y)
        self._t, self._x, self._y = t, x, y
        if buf.n < 2:
            self._vx = self._vy = 0.0
            return
        if self.window_s <= 0.0:
            v = buf.last_velocity()
            if v is not None:
                self._vx, self._vy = v
            return
        i = max(0, min(int(buf.n) - 2, _first_within(buf, self.window_s)))
        ts, xs, ys = buf.t[i:], buf.x[i:], buf.y[i:]
        tc = ts - ts.mean()
        den = float(tc @ tc)
        if den > 0.0:
            self._vx = float(tc @ xs) / den
            self._vy = float(tc @ ys) / den

    def position_at(self, t: float) -> tuple[float, float]:
        if self._t != self._t:  # NaN: no fix yet
            return NAN2
        dt = t - self._t
        return self._x + self._vx * dt, self._y + self._vy * dt


def _first_within(buf: FixBuffer, span_s: float) -> int:
    """Index of the oldest fix whose time is within span_s of the newest."""
    t = buf.t
    return int(np.searchsorted(t, t[-1] - span_s, side="left"))
