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
Each input is one compiled call (numba) on the tracker's state array: this runs at IMU
rate. Every input is idempotent per time stamp (a fix or rate at the time already seen is
ignored), so filters of one bank can share a tracker, each feeding it.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import kernel
from posbench.predictors.kalman.copying import copy_attrs

#: the state array: heading [rad], its variance [rad^2], its time [s], the yaw integrated
#: since the start [rad], the newest yaw rate [rad/s], the newest fix's time [s], and the
#: anchor of the next chord (t [s], x, y [m], var [m^2], yaw integrated then [rad])
H, VAR, T, TURNED, RATE, FIX_T, A_T, A_X, A_Y, A_VAR, A_TURNED = range(11)
TWO_PI = 2.0 * math.pi


@kernel
def _wrap(a: float) -> float:
    """``_geometry.wrap_angle``: a [rad] wrapped to [-pi, pi)."""
    return (a + math.pi) % TWO_PI - math.pi


@kernel
def _advance(st: np.ndarray, t: float, rate_psd: float, hold_psd: float) -> None:
    if not t > st[T]:
        if st[T] != st[T]:
            st[T] = t
        return
    dt = t - st[T]
    if math.isfinite(st[RATE]):
        turn = st[RATE] * dt
        st[TURNED] += turn
        if st[H] == st[H]:
            st[H] = _wrap(st[H] + turn)
        st[VAR] += rate_psd * dt
    else:
        st[VAR] += hold_psd * dt
    st[T] = t


@kernel
def observe_rate(
    st: np.ndarray, t: float, yaw_rate: float, rate_psd: float, hold_psd: float
) -> None:
    """:meth:`CourseHeading.observe_rate` on the state array."""
    _advance(st, t, rate_psd, hold_psd)
    st[RATE] = yaw_rate if math.isfinite(yaw_rate) else math.nan


@kernel
def observe_fix(
    st: np.ndarray,
    t: float,
    x: float,
    y: float,
    var: float,
    gate: float,
    max_chord_s: float,
    rate_psd: float,
    hold_psd: float,
) -> None:
    """:meth:`CourseHeading.observe_fix` on the state array."""
    if t == st[FIX_T]:
        return
    st[FIX_T] = t
    _advance(st, t, rate_psd, hold_psd)
    if not (t - st[A_T] <= max_chord_s):  # no anchor yet, or too old
        st[A_T], st[A_X], st[A_Y], st[A_VAR], st[A_TURNED] = t, x, y, var, st[TURNED]
        return
    dx, dy = x - st[A_X], y - st[A_Y]
    d2 = dx * dx + dy * dy
    v = st[A_VAR] + var
    if d2 < gate * gate * v:
        return
    course = math.atan2(dy, dx) + 0.5 * (st[TURNED] - st[A_TURNED])  # midpoint -> now
    var_c = v / d2
    if st[H] != st[H] or not math.isfinite(st[VAR]):
        st[H], st[VAR] = _wrap(course), var_c
    else:
        k = st[VAR] / (st[VAR] + var_c)
        st[H] = _wrap(st[H] + k * _wrap(course - st[H]))
        st[VAR] = (1.0 - k) * st[VAR]
    st[A_T], st[A_X], st[A_Y], st[A_VAR], st[A_TURNED] = t, x, y, var, st[TURNED]


@kernel
def heading_at(st: np.ndarray, t: float, rate_psd: float, hold_psd: float) -> tuple[float, float]:
    """:meth:`CourseHeading.heading` on the state array."""
    if st[H] != st[H]:
        return math.nan, math.inf
    dt = max(t - st[T], 0.0)
    if math.isfinite(st[RATE]):
        return _wrap(st[H] + st[RATE] * dt), math.sqrt(st[VAR] + rate_psd * dt)
    return st[H], math.sqrt(st[VAR] + hold_psd * dt)


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

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = ("gate", "max_chord_s", "rate_psd", "hold_psd", "_st")

    def __deepcopy__(self, memo: dict) -> CourseHeading:
        """A copy with its own state array."""
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new._st = self._st.copy()
        return new

    def reset(self) -> None:
        st = np.full(11, math.nan)
        st[VAR] = math.inf  # no heading yet
        st[TURNED] = st[A_TURNED] = 0.0
        self._st = st

    @property
    def state(self) -> np.ndarray:
        """The state array (:data:`H`...), for kernels that feed the tracker."""
        return self._st

    @property
    def h(self) -> float:
        """The heading [rad] at the newest input (NaN before the first usable chord)."""
        return float(self._st[H])

    @property
    def var(self) -> float:
        """Its variance [rad^2]."""
        return float(self._st[VAR])

    def observe_rate(self, t: float, yaw_rate: float) -> None:
        """Gyro yaw rate [rad/s] at t [s] (NaN: none)."""
        observe_rate(self._st, t, yaw_rate, self.rate_psd, self.hold_psd)

    def observe_fix(self, t: float, x: float, y: float, var: float) -> None:
        """A fix at (x, y) [m, ENU] with per-axis variance var [m^2]."""
        observe_fix(
            self._st, t, x, y, var, self.gate, self.max_chord_s, self.rate_psd, self.hold_psd
        )

    def heading(self, t: float) -> tuple[float, float]:
        """(heading [rad], its standard deviation [rad]) at t [s] >= the newest input's
        time, by the newest yaw rate; (NaN, inf) before the first usable chord."""
        return heading_at(self._st, t, self.rate_psd, self.hold_psd)
