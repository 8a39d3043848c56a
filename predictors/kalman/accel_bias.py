"""Accelerometer bias [m/s^2, vehicle frame] from the velocity the fixes show.

Why not from the IMU innovations of the filter that uses the IMU: at 50-100 Hz the IMU
dominates that filter's acceleration state, so its innovations stay near zero whatever the
bias (the bias turns into a velocity drift that the fixes keep correcting). Here the
reference is independent of the IMU: a fixes-only constant-acceleration filter
(``CaFilter2D``, white jerk ``REF_JERK_PSD``).

Over a window between two fixes ``[t0, t1]`` (at least ``min_window_s``), the IMU's
velocity change rotated into ENU by the heading ``h`` is ``dv_imu = int R(h) a dt`` while
the reference's is ``dv_ref = v_ref(t1) - v_ref(t0)``. A constant vehicle-frame bias ``b``
adds ``M b`` with ``M = int R(h) dt`` (a scaled rotation: ``M'M = (C^2 + S^2) I`` with
``C = int cos h dt``, ``S = int sin h dt``), so ``d = dv_imu - dv_ref = M b + noise``.
Recursive least squares with exponential forgetting (time constant ``tau_s``) gives
``b = sum(lambda M' d) / sum(lambda (C^2 + S^2))``. Mount tilt, gravity leakage on a slope
and offsets are such biases; the reference's velocity noise averages out over windows.
Inputs are idempotent per time stamp, so filters of one bank can share an estimator.
"""

from __future__ import annotations

import math

from posbench.predictors.kalman import ca_rows as kb
from posbench.predictors.kalman.copying import copy_attrs

#: white jerk of the fixes-only reference [m^2/s^5] (smooth: its velocity is what counts)
REF_JERK_PSD = 4.0
#: the reference's prior velocity / acceleration sigma at its first fix [m/s, m/s^2]
REF_INIT_VEL_SIGMA, REF_INIT_ACC_SIGMA = 15.0, 3.0


class AccelBiasEstimator:
    """Vehicle-frame accelerometer bias from IMU velocity changes against a fixes-only
    filter's (module docstring).

    Args:
        tau_s: forgetting time constant [s] (the bias may drift with temperature, slope).
        min_window_s, max_window_s: a window spans fixes at least ``min_window_s`` [s]
            apart; one longer than ``max_window_s`` (an outage) or with a sample of unknown
            heading is dropped.
    """

    def __init__(
        self, tau_s: float = 30.0, min_window_s: float = 2.0, max_window_s: float = 10.0
    ) -> None:
        self.tau_s = float(tau_s)
        self.min_window_s = float(min_window_s)
        self.max_window_s = float(max_window_s)
        self._ref = kb.new_rows(1)  # the fixes-only reference filter
        self.reset()

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = (
        "tau_s",
        "min_window_s",
        "max_window_s",
        "_ref",
        "_ready",
        "_t_ref",
        "_w0",
        "_v0",
        "_dv",
        "_c",
        "_s",
        "_valid",
        "_t_imu",
        "_a",
        "_g",
        "bias",
    )

    def __deepcopy__(self, memo: dict) -> AccelBiasEstimator:
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new._ref = self._ref.copy()
        new._dv = list(self._dv)
        return new

    def reset(self) -> None:
        self._ready = False
        self._t_ref = math.nan  # time of the reference's state [s]
        self._w0 = math.nan  # window start (a fix time) [s]
        self._v0 = (0.0, 0.0)  # reference velocity there [m/s]
        self._open(math.nan)
        self._a = 0.0  # sum lambda (C^2 + S^2) [s^2]
        self._g = (0.0, 0.0)  # sum lambda M' d [m/s * s]
        self.bias = (0.0, 0.0)

    def _open(self, t: float) -> None:
        self._w0 = t
        self._dv = [0.0, 0.0]
        self._c = self._s = 0.0
        self._valid = True
        self._t_imu = t

    def observe_imu(self, t: float, ax: float, ay: float, heading: float) -> None:
        """A raw IMU sample (x forward, y left) [m/s^2] at t [s] with the heading [rad, ENU]
        it is rotated by (NaN: unknown, the window is dropped)."""
        dt = t - self._t_imu
        self._t_imu = t
        if not (dt > 0.0) or self._w0 != self._w0:
            return
        if not (math.isfinite(heading) and math.isfinite(ax) and math.isfinite(ay)) or dt > 0.5:
            self._valid = False
            return
        c, s = math.cos(heading), math.sin(heading)
        self._dv[0] += (c * ax - s * ay) * dt
        self._dv[1] += (s * ax + c * ay) * dt
        self._c += c * dt
        self._s += s * dt

    def observe_fix(self, t: float, x: float, y: float, var: float) -> None:
        """A fix at (x, y) [m, ENU] with per-axis variance var [m^2]."""
        if t == self._t_ref:
            return
        ref = self._ref
        if not self._ready:
            kb.init_rows(ref, 1, t, x, y, var, REF_INIT_VEL_SIGMA**2, REF_INIT_ACC_SIGMA**2)
            self._ready, self._t_ref = True, t
            return
        v = kb.fix_one(ref, 0, t, x, y, var, REF_JERK_PSD)  # predicts only forward
        self._t_ref = max(t, self._t_ref)
        span = t - self._w0
        if span == span and span < self.min_window_s and self._valid:
            return  # keep collecting
        if span == span and self._valid and span <= self.max_window_s:
            C, S = self._c, self._s
            dx = self._dv[0] - (v[0] - self._v0[0])
            dy = self._dv[1] - (v[1] - self._v0[1])
            lam = math.exp(-span / self.tau_s)
            self._a = lam * self._a + C * C + S * S
            gx, gy = self._g
            self._g = (lam * gx + C * dx + S * dy, lam * gy - S * dx + C * dy)
            if self._a > 0.0:
                self.bias = (self._g[0] / self._a, self._g[1] / self._a)
        self._open(t)
        self._v0 = v
