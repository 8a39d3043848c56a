"""The paper's cubic regression alone: fit x(t), y(t) with a third-order polynomial
over the most recent fixes and evaluate (extrapolate) it at the query time.

The fit (closed-form least squares: :func:`posbench.predictors._cubic_xy.fit_cubic_xy`, the
normal equations of :func:`posbench.predictors.cubic.fit_cubic` in plain floats) uses the
newest fixes covering at least ``span_s`` seconds (paper: "at least a 2-second
interval", about 10 fixes at 5 Hz). It is refitted on each fix, so a query costs
one Horner evaluation. With fewer than ``min_points`` fixes it falls back to
constant velocity from the last two fixes. Extrapolation is not capped: that is
the paper's method, up to ``extrapolate_s`` seconds after the newest fix; beyond (a
long GPS outage) the position continues in a straight line with the cubic's velocity at
that point, since a cubic extrapolated for tens of seconds grows as t^3 (hundreds of
metres, at "speeds" above any car's). At standstill (latest wheel/CAN speed below ``stop_speed``,
paper: 0.15 km/h) the newest fix is held, as the paper does, because a cubic
through static noisy points extrapolates noise. Units: s, m (ENU), m/s.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._cubic_xy import Cubic, fit_cubic_xy
from posbench.predictors._geometry import FixBuffer, check_config
from posbench.predictors.base import Predictor
from posbench.predictors.cubic import fit_cubic

NAN2 = (math.nan, math.nan)
KMH = 1.0 / 3.6


class PolyExtrapolator(Predictor):
    """Cubic regression over recent fixes, extrapolated.

    Args:
        span_s: the fit uses the newest fixes covering at least this many seconds.
        min_points: fewer fixes than this -> constant-velocity fallback (>= 4 for a cubic).
        max_points: cap on the number of fixes in a fit (high-rate GNSS).
        stop_speed: speed [m/s] below which the vehicle is taken as stationary.
        extrapolate_s: the cubic is extrapolated this long [s] after the newest fix, then
            continued linearly (``inf``: never, the paper's uncapped cubic).
    """

    name = "poly"

    def __init__(
        self,
        span_s: float = 2.0,
        min_points: int = 4,
        max_points: int = 50,
        stop_speed: float = 0.15 * KMH,
        extrapolate_s: float = 2.0,
    ) -> None:
        check_config(
            "poly",
            span_s=(span_s, 0.0, 60.0),
            min_points=(min_points, 4, 1000),
            max_points=(max_points, min_points, 1000),
            stop_speed=(stop_speed, 0.0, 10.0),
            extrapolate_s=(extrapolate_s, 0.0, math.inf),
        )
        self.span_s = float(span_s)
        self.min_points = int(min_points)
        self.max_points = int(max_points)
        self.stop_speed = float(stop_speed)
        self.extrapolate_s = float(extrapolate_s)
        self._buf = FixBuffer(max(64, 2 * self.max_points))
        self.reset()

    def config(self) -> dict:
        return {
            "span_s": self.span_s,
            "min_points": self.min_points,
            "max_points": self.max_points,
            "stop_speed": self.stop_speed,
            "extrapolate_s": self.extrapolate_s,
        }

    def reset(self) -> None:
        self._buf.clear()
        self._t = self._x = self._y = math.nan
        self._speed = math.nan
        self._cubic = False
        self._vx = self._vy = 0.0
        # polynomial in s = (t - t_ref) / scale: x = cx0 + cx1 s + cx2 s^2 + cx3 s^3
        self._cx = (0.0, 0.0, 0.0, 0.0)
        self._cy = (0.0, 0.0, 0.0, 0.0)
        self._t_ref = 0.0
        self._inv_scale = 1.0

    def observe_speed(self, t: float, v: float) -> None:
        self._speed = v

    def observe_gps(self, t: float, x: float, y: float) -> None:  # type: ignore[override]  # three-argument form on purpose: no sigma passed (accepts_sigma)
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        buf = self._buf
        buf.append(t, x, y)
        self._t, self._x, self._y = t, x, y
        i = max(buf.window_start(self.span_s, self.min_points), buf.n - self.max_points)
        if buf.n - i < self.min_points:
            self._cubic = False
            v = buf.last_velocity()
            if v is not None:
                self._vx, self._vy = v
            return
        self._cx, self._cy, self._t_ref, self._inv_scale = self._fit(buf.t[i:], buf.xy_rows_from(i))
        self._cubic = True

    def _fit(self, t: np.ndarray, xy: np.ndarray) -> tuple[Cubic, Cubic, float, float]:
        """(cx, cy, t_ref, inv_scale) of the least-squares cubics through the window (times
        t [s] (n,), positions xy [m] as rows (2, n)):
        :func:`posbench.predictors._cubic_xy.fit_cubic_xy`, or ``fit_cubic`` (lstsq, minimum norm)
        for a window with fewer than four distinct times."""
        fit = fit_cubic_xy(t, xy)
        if fit is not None:
            return fit
        f = fit_cubic(t, xy.T)
        c = f.coef
        return (
            tuple(c[:, 0].tolist()),
            tuple(c[:, 1].tolist()),
            f.t_ref,
            1.0 / f.scale,
        )

    def position_at(self, t: float) -> tuple[float, float]:
        if self._t != self._t:
            return NAN2
        if self._speed < self.stop_speed:  # False when no speed was given (NaN)
            return self._x, self._y
        if not self._cubic:
            dt = t - self._t
            return self._x + self._vx * dt, self._y + self._vy * dt
        cx, cy = self._cx, self._cy
        t_cap = self._t + self.extrapolate_s
        if t > t_cap:  # long outage: straight on from the cubic at t_cap
            s = (t_cap - self._t_ref) * self._inv_scale
            ds = (t - t_cap) * self._inv_scale
            return (
                ((cx[3] * s + cx[2]) * s + cx[1]) * s
                + cx[0]
                + ((3 * cx[3] * s + 2 * cx[2]) * s + cx[1]) * ds,
                ((cy[3] * s + cy[2]) * s + cy[1]) * s
                + cy[0]
                + ((3 * cy[3] * s + 2 * cy[2]) * s + cy[1]) * ds,
            )
        s = (t - self._t_ref) * self._inv_scale
        return (
            ((cx[3] * s + cx[2]) * s + cx[1]) * s + cx[0],
            ((cy[3] * s + cy[2]) * s + cy[1]) * s + cy[0],
        )
