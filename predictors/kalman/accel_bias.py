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
The IMU side, which runs at IMU rate, is one compiled call (numba) on the estimator's state
array (:func:`observe_imu`), which the kf's IMU step makes inside its own call.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import kernel
from posbench.predictors.kalman import ca_rows as kb
from posbench.predictors.kalman.copying import copy_attrs

#: white jerk of the fixes-only reference [m^2/s^5] (smooth: its velocity is what counts)
REF_JERK_PSD = 4.0
#: the reference's prior velocity / acceleration sigma at its first fix [m/s, m/s^2]
REF_INIT_VEL_SIGMA, REF_INIT_ACC_SIGMA = 15.0, 3.0


#: the state array: the newest IMU sample's time [s]; the window's start (a fix time) [s];
#: the IMU's velocity change over the window [m/s, ENU]; the window's int cos h dt and
#: int sin h dt [s]; whether the window is usable (1 / 0); the bias [m/s^2, vehicle frame]
T_IMU, W0, DVX, DVY, C, S, VALID, BX, BY = range(9)


@kernel
def observe_imu(st: np.ndarray, t: float, ax: float, ay: float, heading: float) -> None:
    """:meth:`AccelBiasEstimator.observe_imu` on the state array."""
    dt = t - st[T_IMU]
    st[T_IMU] = t
    if not (dt > 0.0) or st[W0] != st[W0]:
        return
    if not (math.isfinite(heading) and math.isfinite(ax) and math.isfinite(ay)) or dt > 0.5:
        st[VALID] = 0.0
        return
    c, s = math.cos(heading), math.sin(heading)
    st[DVX] += (c * ax - s * ay) * dt
    st[DVY] += (s * ax + c * ay) * dt
    st[C] += c * dt
    st[S] += s * dt


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
        "_v0",
        "_a",
        "_g",
        "_st",
    )

    def __deepcopy__(self, memo: dict) -> AccelBiasEstimator:
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new._ref = self._ref.copy()
        new._st = self._st.copy()
        return new

    def reset(self) -> None:
        self._ready = False
        self._t_ref = math.nan  # time of the reference's state [s]
        self._v0 = (0.0, 0.0)  # reference velocity at the window's start [m/s]
        self._st = np.zeros(BY + 1)  # the IMU side and the bias (:data:`T_IMU`...)
        self._open(math.nan)
        self._a = 0.0  # sum lambda (C^2 + S^2) [s^2]
        self._g = (0.0, 0.0)  # sum lambda M' d [m/s * s]

    @property
    def bias(self) -> tuple[float, float]:
        """The bias estimate (x forward, y left) [m/s^2]; (0, 0) before the first window."""
        return self._st.item(BX), self._st.item(BY)

    @property
    def state(self) -> np.ndarray:
        """The state array (:data:`T_IMU`...), for kernels that feed the IMU side."""
        return self._st

    def _open(self, t: float) -> None:
        st = self._st
        st[W0] = st[T_IMU] = t
        st[DVX] = st[DVY] = st[C] = st[S] = 0.0
        st[VALID] = 1.0

    def observe_imu(self, t: float, ax: float, ay: float, heading: float) -> None:
        """A raw IMU sample (x forward, y left) [m/s^2] at t [s] with the heading [rad, ENU]
        it is rotated by (NaN: unknown, the window is dropped)."""
        observe_imu(self._st, t, ax, ay, heading)

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
        _, w0, dvx, dvy, C, S, valid, _, _ = self._st.tolist()
        span = t - w0
        if span == span and span < self.min_window_s and valid:
            return  # keep collecting
        if span == span and valid and span <= self.max_window_s:
            dx = dvx - (v[0] - self._v0[0])
            dy = dvy - (v[1] - self._v0[1])
            lam = math.exp(-span / self.tau_s)
            self._a = lam * self._a + C * C + S * S
            gx, gy = self._g
            self._g = (lam * gx + C * dx + S * dy, lam * gy - S * dx + C * dy)
            if self._a > 0.0:
                self._st[BX], self._st[BY] = self._g[0] / self._a, self._g[1] / self._a
        self._open(t)
        self._v0 = v
