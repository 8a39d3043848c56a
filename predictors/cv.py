"""Constant-velocity extrapolation from recent GNSS fixes (the simplest baseline).

Velocity [m/s] comes from the last two fixes (``window_s = 0``) or from a
least-squares line through the fixes of the last ``window_s`` seconds;
``position_at(t)`` extrapolates from the newest fix: p_last + v (t - t_last).
IMU and speed are ignored. Units: seconds, metres (local ENU).

Expected error on a circle of radius R at speed v with fixes every T seconds,
horizon h after the newest fix: the two-fix chord velocity lags the tangent by
half a fix interval, so the error is ~ v^2 h (h + T) / (2 R) (v^2 h^2 / (2 R)
for the exact tangent velocity).

Uncertainty (``covariance_at``), a simple error model, isotropic, per axis:
fix noise ``fix_sigma`` [m] (white) and an unmodelled acceleration ``accel_sigma``
[m/s^2] per axis. With the two-fix velocity over T seconds, extrapolating h seconds past
the newest fix: ``var = fix_sigma^2 ((1 + h/T)^2 + (h/T)^2) + (accel_sigma h (h + T) / 2)^2``
(the first term propagates both fixes' noise through p_last + (p_last - p_prev) h / T, the
second is the chord-velocity lag error above for an acceleration of that size). With a
line fit the velocity variance is ``fix_sigma^2 / sum((t_i - mean t)^2)`` and T is the
window's span. The defaults (``fix_sigma`` 0.06 m, ``accel_sigma`` 1.0 m/s^2) come from
the synthetic development drives' fix noise (0.03 m white + 0.05 m Gauss-Markov) and their
manoeuvres; they are not fitted to any evaluation data. None before the second fix.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._geometry import COV_SCALE_RANGE, FixBuffer, check_config
from posbench.predictors.base import Predictor

NAN2 = (math.nan, math.nan)


class ConstantVelocity(Predictor):
    """Constant velocity from the last two fixes or a line fit over ``window_s`` seconds.

    Args:
        window_s: 0 -> velocity from the last two fixes; > 0 -> least-squares slope of
            the fixes whose times lie within ``window_s`` [s] of the newest fix
            (at least two fixes are used).
        fix_sigma, accel_sigma: the error model's fix noise [m] and unmodelled
            acceleration [m/s^2] (module docstring).
        cov_scale: calibration: ``covariance_at`` reports ``cov_scale`` x the error model's
            variance (1: as the model says); fitted on development drives by
            ``bench tune`` so that 95 % of the 95 % ellipses cover the truth. It never
            changes a position.
    """

    name = "cv"

    def __init__(
        self,
        window_s: float = 0.0,
        fix_sigma: float = 0.06,
        accel_sigma: float = 1.0,
        cov_scale: float = 1.0,
    ) -> None:
        check_config(
            "cv",
            window_s=(window_s, 0.0, 60.0),
            fix_sigma=(fix_sigma, 1e-4, 1e3),
            accel_sigma=(accel_sigma, 0.0, 1e3),
            cov_scale=(cov_scale, *COV_SCALE_RANGE),
        )
        self.window_s = float(window_s)
        self.fix_sigma = float(fix_sigma)
        self.accel_sigma = float(accel_sigma)
        self.cov_scale = float(cov_scale)
        self._buf = FixBuffer(256)
        self.reset()

    def config(self) -> dict:
        return {
            "window_s": self.window_s,
            "fix_sigma": self.fix_sigma,
            "accel_sigma": self.accel_sigma,
            "cov_scale": self.cov_scale,
        }

    def reset(self) -> None:
        self._buf.clear()
        self._t = math.nan
        self._x = math.nan
        self._y = math.nan
        self._vx = 0.0
        self._vy = 0.0
        self._span = math.nan  # T of the error model [s] (NaN: velocity unknown)
        self._var_v_rel = math.nan  # velocity variance / fix_sigma^2 [1/s^2]

    def observe_gps(self, t: float, x: float, y: float) -> None:  # type: ignore[override]  # three-argument form on purpose: no sigma passed (accepts_sigma)
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
                self._span = t - buf.last(2)[0]
                self._var_v_rel = math.nan  # the two-fix formula, see covariance_at
            return
        i = max(0, min(int(buf.n) - 2, _first_within(buf, self.window_s)))
        ts, xs, ys = buf.t[i:], buf.x[i:], buf.y[i:]
        tc = ts - ts.mean()
        den = float(tc @ tc)
        if den > 0.0:
            self._vx = float(tc @ xs) / den
            self._vy = float(tc @ ys) / den
            self._span = float(ts[-1] - ts[0])
            self._var_v_rel = 1.0 / den

    def position_at(self, t: float) -> tuple[float, float]:
        if self._t != self._t:  # NaN: no fix yet
            return NAN2
        dt = t - self._t
        return self._x + self._vx * dt, self._y + self._vy * dt

    def covariance_at(self, t: float) -> np.ndarray | None:
        """2x2 ENU covariance [m^2] of ``position_at(t)`` from the error model of the module
        docstring (isotropic), times ``cov_scale``; None while the velocity is unknown
        (fewer than two fixes)."""
        T = self._span
        if not T > 0.0:
            return None
        h = max(t - self._t, 0.0)
        s2 = self.fix_sigma * self.fix_sigma
        if self._var_v_rel == self._var_v_rel:  # line fit
            var = s2 * (1.0 + h * h * self._var_v_rel)
        else:
            r = h / T
            var = s2 * ((1.0 + r) ** 2 + r * r)
        m = 0.5 * self.accel_sigma * h * (h + T)
        var = (var + m * m) * self.cov_scale
        return np.array(((var, 0.0), (0.0, var)))


def _first_within(buf: FixBuffer, span_s: float) -> int:
    """Index of the oldest fix whose time is within span_s of the newest."""
    t = buf.t
    return int(np.searchsorted(t, t[-1] - span_s, side="left"))
