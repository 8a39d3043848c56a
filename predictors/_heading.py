"""Heading of a vehicle whose IMU states no yaw, from the course between fixes and the gyro.

Why not the direction of a filter's velocity: at walking speed, or with fixes a metre
apart in noise, that direction is mostly noise; a filter that rotates its IMU into the
world with it feeds its own error back (a ground robot at 1 m/s lost 7x to constant
velocity that way). Here the course is taken only from two fixes far enough apart that
their noise cannot turn it: the displacement ``d`` must exceed ``gate`` x its own
standard deviation ``sqrt(var_a + var_b)`` (the fixes' stated or assumed variances), so
the course's angular variance ``(var_a + var_b) / d^2`` is at most ``1 / gate^2``. Slow
platforms simply wait longer for such a pair (up to ``max_chord_s``).

In between, a 1-D Kalman filter carries the heading [rad, ENU, 0 = east, counter-
clockwise] with the yaw rate [rad/s] when the IMU gives one (variance growing by
``rate_psd`` per second), else holds it (``hold_psd``). A chord's course is the heading at
its midpoint: it is moved to the newest fix by the yaw integrated since then, then fused.
Pure floats: this runs at IMU rate. Every input is idempotent per time stamp (a fix or
rate at the time already seen is ignored), so filters of one bank can share a tracker,
each feeding it.
"""

from __future__ import annotations

import math

from posbench.predictors._copying import copy_attrs
from posbench.predictors._geometry import wrap_angle


class CourseHeading:
    """Heading from fix chords and the gyro (module docstring).

    Args:
        gate: a chord counts when its length is at least ``gate`` x its standard deviation.
        max_chord_s: a chord older than this [s] without enough displacement is dropped
            (the platform stood or crawled): the next starts at the newest fix.
        rate_psd: heading variance growth [rad^2/s] while the yaw rate is integrated.
        hold_psd: heading variance growth [rad^2/s] without a yaw rate.
    """

    def __init__(
        self,
        gate: float = 3.0,
        max_chord_s: float = 10.0,
        rate_psd: float = 1e-3,
        hold_psd: float = 0.05,
    ) -> None:
        self.gate = float(gate)
        self.max_chord_s = float(max_chord_s)
        self.rate_psd = float(rate_psd)
        self.hold_psd = float(hold_psd)
        self.reset()

    #: every instance attribute, for :func:`~posbench.predictors._copying.copy_attrs`
    _ATTRS = (
        "gate",
        "max_chord_s",
        "rate_psd",
        "hold_psd",
        "h",
        "var",
        "t",
        "_turned",
        "_rate",
        "_fix_t",
        "_anchor",
    )

    def __deepcopy__(self, memo: dict) -> CourseHeading:
        """A copy (every attribute is an immutable value)."""
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        return new

    def reset(self) -> None:
        self.h = math.nan  # heading [rad]
        self.var = math.inf  # its variance [rad^2]
        self.t = math.nan  # time of h [s]
        self._turned = 0.0  # yaw integrated since the start [rad]
        self._rate = math.nan  # newest yaw rate [rad/s]
        self._fix_t = math.nan  # time of the newest fix [s]
        self._anchor = (math.nan, math.nan, math.nan, math.nan, 0.0)  # t, x, y, var, turned

    def _advance(self, t: float) -> None:
        if not t > self.t:
            if self.t != self.t:
                self.t = t
            return
        dt = t - self.t
        if math.isfinite(self._rate):
            turn = self._rate * dt
            self._turned += turn
            if self.h == self.h:
                self.h = wrap_angle(self.h + turn)
            self.var += self.rate_psd * dt
        else:
            self.var += self.hold_psd * dt
        self.t = t

    def observe_rate(self, t: float, yaw_rate: float) -> None:
        """Gyro yaw rate [rad/s] at t [s] (NaN: none)."""
        self._advance(t)
        self._rate = yaw_rate if math.isfinite(yaw_rate) else math.nan

    def observe_fix(self, t: float, x: float, y: float, var: float) -> None:
        """A fix at (x, y) [m, ENU] with per-axis variance var [m^2]."""
        if t == self._fix_t:
            return
        self._fix_t = t
        self._advance(t)
        ta, xa, ya, va, turned_a = self._anchor
        if not (t - ta <= self.max_chord_s):  # no anchor yet, or too old
            self._anchor = (t, x, y, var, self._turned)
            return
        dx, dy = x - xa, y - ya
        d2 = dx * dx + dy * dy
        v = va + var
        if d2 < self.gate * self.gate * v:
            return
        course = math.atan2(dy, dx) + 0.5 * (self._turned - turned_a)  # midpoint -> now
        var_c = v / d2
        if self.h != self.h or not math.isfinite(self.var):
            self.h, self.var = wrap_angle(course), var_c
        else:
            k = self.var / (self.var + var_c)
            self.h = wrap_angle(self.h + k * wrap_angle(course - self.h))
            self.var = (1.0 - k) * self.var
        self._anchor = (t, x, y, var, self._turned)

    def heading(self, t: float) -> tuple[float, float]:
        """(heading [rad], its standard deviation [rad]) at t [s] >= the newest input's
        time, by the newest yaw rate; (NaN, inf) before the first usable chord."""
        if self.h != self.h:
            return math.nan, math.inf
        dt = max(t - self.t, 0.0)
        if math.isfinite(self._rate):
            return wrap_angle(self.h + self._rate * dt), math.sqrt(self.var + self.rate_psd * dt)
        return self.h, math.sqrt(self.var + self.hold_psd * dt)
