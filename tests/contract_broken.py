"""Predictors that break one clause of the contract each (for tests/bench/test_contract.py and
``bench check tests.contract_broken:LookAhead``), on a plain constant-velocity core.

Each bug is one a plugin author could write: peeking at the runner's drive in memory, a
``reset()`` that forgets to reset, a heading normalised by a speed that can be zero, a
covariance assembled with the wrong sign.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from posbench.predictors.base import Predictor
from posbench.replay.prepare import PreparedDrive

NAN2 = (math.nan, math.nan)


class Cv(Predictor):
    """Constant velocity from the last two fixes; the last fix alone is held."""

    name = "contract-cv"

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.t0 = self.x0 = self.y0 = math.nan  # the fix before the newest
        self.t1 = self.x1 = self.y1 = math.nan  # the newest fix

    def observe_gps(self, t: float, x: float, y: float) -> None:
        self.t0, self.x0, self.y0 = self.t1, self.x1, self.y1
        self.t1, self.x1, self.y1 = t, x, y

    def velocity(self) -> tuple[float, float]:
        dt = self.t1 - self.t0
        return (self.x1 - self.x0) / dt, (self.y1 - self.y0) / dt

    def position_at(self, t: float) -> tuple[float, float]:
        if self.t1 != self.t1:
            return NAN2
        if self.t0 != self.t0:
            return self.x1, self.y1
        vx, vy = self.velocity()
        return self.x1 + vx * (t - self.t1), self.y1 + vy * (t - self.t1)


def _drive_in_caller() -> PreparedDrive | None:
    """The first :class:`PreparedDrive` held by a caller's local variable (the runner's
    ``replay(predictor, prep, ...)`` has one)."""
    f = sys._getframe(2)
    while f is not None:
        for v in f.f_locals.values():
            if isinstance(v, PreparedDrive):
                return v
        f = f.f_back
    return None


class LookAhead(Cv):
    """Cheats: finds the drive being replayed in its caller's frame and, when a fix after the
    newest one it was given exists there, interpolates towards it instead of extrapolating."""

    name = "contract-look-ahead"

    def position_at(self, t: float) -> tuple[float, float]:
        prep = _drive_in_caller()
        if prep is not None and self.t1 == self.t1:
            i = int(np.searchsorted(prep.gps.t, self.t1, side="right"))
            if i < len(prep.gps):
                tn, xn, yn = prep.gps.t[i], prep.gps.x[i], prep.gps.y[i]
                w = (t - self.t1) / (tn - self.t1)
                return self.x1 + w * (xn - self.x1), self.y1 + w * (yn - self.y1)
        return super().position_at(t)


class NoReset(Cv):
    """``reset()`` does nothing: the state set in ``__init__`` carries over to the next drive."""

    name = "contract-no-reset"

    def __init__(self) -> None:
        super().reset()

    def reset(self) -> None:
        pass


class NanAtStandstill(Cv):
    """Extrapolates along the unit heading times the speed: 0 / 0 = NaN once two fixes
    coincide (a standing car with exact fixes)."""

    name = "contract-nan-at-standstill"

    def position_at(self, t: float) -> tuple[float, float]:
        if self.t1 != self.t1 or self.t0 != self.t0:
            return super().position_at(t)
        vx, vy = (np.float64(v) for v in self.velocity())
        speed = np.hypot(vx, vy)
        ux, uy = vx / speed, vy / speed
        dt = t - self.t1
        return float(self.x1 + ux * speed * dt), float(self.y1 + uy * speed * dt)


class WithCovariance(Cv):
    """Reports ``covariance_at(t)`` [m^2]: fix noise plus a variance growing with the horizon."""

    name = "contract-covariance"
    sigma = 0.05  # fix noise [m]

    def covariance_at(self, t: float) -> np.ndarray:
        h = max(0.0, t - self.t1) if self.t1 == self.t1 else 0.0
        s2 = self.sigma**2 * (1.0 + 4.0 * h * h)
        return np.array([[s2, 0.3 * s2], [0.3 * s2, s2]])


class BadCovariance(WithCovariance):
    """The cross term with the wrong scale: correlation 3 instead of 0.3, not a covariance."""

    name = "contract-bad-covariance"

    def covariance_at(self, t: float) -> np.ndarray:
        c = super().covariance_at(t)
        c[0, 1] = c[1, 0] = 10.0 * c[0, 1]
        return c


class NotAPredictor:
    """Has the methods but does not derive from Predictor (``bench check`` refuses it)."""

    def reset(self) -> None:
        pass
