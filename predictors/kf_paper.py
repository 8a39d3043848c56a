"""The paper's Kalman baseline, as its authors published it (GitHub
PetarSt98/LSTM-Kalman-GPS-predictor, ``kalman.py``), made causal.

What their code does, and what this class keeps (K) or changes (C):

- (K) State ``[x, y, vx, vy]``, ``F = [[1,0,dt,0],[0,1,0,dt],[0,0,1,0],[0,0,0,1]]``,
  control ``u = (ax, ay)`` with ``B = [[dt^2,0],[0,dt^2],[dt,0],[0,dt]]`` (no 1/2),
  ``Q = 0.05 I4``, ``R = 0.05 I2``, ``P0 = I4``, ``dt = 0.05`` s fixed.
- (K) The acceleration is the IMU's *vehicle-frame* (ax, ay) used as if it were ENU
  (no rotation).
- (K) A new filter per window of 8 points 200 ms apart, ending at the newest fix:
  initial position = first point, initial velocity = (p1 - p0) / dt, then for points
  1..7 one ``predict(accel_i)`` and one ``correct(p_i)``; finally one more ``predict`` is
  the future point. That single step is "200 ms ahead": a fixed number of steps (one)
  regardless of the real time.
- (K) The 8 points are the paper's resampling: a least-squares cubic
  (:func:`posbench.predictors._cubic_xy.fit_cubic_xy`, the normal equations of ``fit_cubic``)
  through the recent fixes, evaluated on a 200 ms grid ending at the newest fix
  (``resample=True``). Their code fitted the window's 8 raw fixes (~1.4 s); the paper's
  text says the fit covers at least 2 s: ``fit_span_s`` (default 2.0) follows the text.
  ``resample=False`` feeds the newest raw fixes as if they were 200 ms apart.
- (C) Acceleration at each point: the latest IMU sample at or before its time (theirs:
  a cubic through the window's IMU samples, evaluated at the grid times).
- (C) Future information removed: their final ``predict`` used ``accel_gt``, the IMU
  acceleration at the *target* time (from a fit through past and future IMU samples).
  Here the final step uses the latest IMU sample at or before the newest fix. (Their
  evaluation reference is also a cubic through past and future fixes; that is an
  evaluation matter, not the filter's input.)
- (C) Streaming: the window is rebuilt on every fix; before 8 grid points of history
  exist, the available raw fixes (>= 2) are used; with one fix it is held.
- (C) ``position_at(t)``: their method yields only the future point; for any t the
  estimate is the straight line through the newest fix (t_fix) and the predicted point
  (t_fix + ``horizon_steps * step_s``), interpolated between them and extrapolated past
  the future point (GNSS dropout).

Physics of its error: ``dt = 0.05`` while the points are 0.2 s apart, but the initial
velocity is divided by the same ``dt``, so the velocity state is "displacement per
sample / 0.05" and one step advances exactly one sample: constant velocity is
predicted exactly (error 0 for noiseless fixes on a line). In those units P0 = I and
Q = 0.05 I make the velocity nearly frozen at its initial value, the window's *first*
difference (gain ~0.05 per step, ~2 mm of displacement per step per metre of residual),
while the position gain is ~0.95: the prediction is about "newest point + (p1 - p0)".
Hence under acceleration a the miss is ~ (W - 1) a T^2 (0.56 m at 2 m/s^2), on a turn
the predicted step points along the heading of 1.4 s earlier, and fix noise enters
through a two-point difference. The IMU term barely helps: position gets ``0.0025 a``
instead of ``a T^2/2 = 0.02 a`` and the velocity state ``0.05 a`` instead of
``a T^2 / dt = 0.8 a``, and the IMU is not rotated, so on a turn its lateral
acceleration pushes in a wrong world direction. With ``resample=False`` and fixes T
seconds apart the single step lands at t_fix + T while it is reported at t_fix + 0.2:
an extra error of ~ v |0.2 - T|.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._cubic_xy import fit_cubic_xy
from posbench.predictors._geometry import FixBuffer, check_config
from posbench.predictors.base import Predictor
from posbench.predictors.cubic import fit_cubic

NAN2 = (math.nan, math.nan)


def paper_window_predict(
    points: np.ndarray | list[list[float]],
    accel: np.ndarray,
    accel_next: np.ndarray,
    dt: float = 0.05,
    q: float = 0.05,
    r: float = 0.05,
    steps: int = 1,
) -> tuple[float, float]:
    """The authors' per-window filter: points (n, 2) [m] (an array or a list of pairs),
    accel (n, 2) [m/s^2] (accel[i]
    drives the step into point i; accel[0] unused), accel_next (2,) for the future
    steps. Returns the predicted (x, y) after ``steps`` further predict steps.

    Their F, B, Q = q I, R = r I, P0 = I and H are block-diagonal per axis, so the 4-state
    filter is two identical 2-state (position, velocity) filters sharing one covariance
    [[pa, pb], [pb, pc]]: computed here in plain floats, equal to their matrix code
    (checked in the tests against a transcription of it).
    """
    pts = points.tolist() if isinstance(points, np.ndarray) else points
    acc = accel.tolist()
    d2 = dt * dt
    x, y = pts[0]
    vx = (pts[1][0] - x) / dt
    vy = (pts[1][1] - y) / dt
    pa, pb, pc = 1.0, 0.0, 1.0
    for i in range(1, len(pts)):
        ax, ay = acc[i]
        x += dt * vx + d2 * ax
        y += dt * vy + d2 * ay
        vx += dt * ax
        vy += dt * ay
        pa, pb, pc = pa + 2.0 * dt * pb + d2 * pc + q, pb + dt * pc, pc + q
        s = pa + r
        kp, kv = pa / s, pb / s
        zx, zy = pts[i]
        ix, iy = zx - x, zy - y
        x += kp * ix
        y += kp * iy
        vx += kv * ix
        vy += kv * iy
        pa, pb, pc = pa * (1.0 - kp), pb * (1.0 - kp), pc - kv * pb
    ax, ay = float(accel_next[0]), float(accel_next[1])
    for _ in range(steps):
        x += dt * vx + d2 * ax
        y += dt * vy + d2 * ay
        vx += dt * ax
        vy += dt * ay
    return x, y


class PaperKalman(Predictor):
    """The paper authors' Kalman baseline (see the module docstring for every choice).

    Args:
        dt: the filter's step [s] (paper: 0.05, although the points are 0.2 s apart).
        q, r: process / measurement noise (times identity), paper: 0.05 each.
        window: number of points per window (paper: 8).
        step_s: spacing [s] of the resampled grid and the horizon of one step (0.2).
        horizon_steps: predict steps to the future point (paper: 1).
        resample: cubic-resample the fixes onto the grid (paper) or use raw fixes.
        fit_span_s: the resampling cubic uses the newest fixes covering this span [s].
    """

    name = "kf-paper"

    def __init__(
        self,
        dt: float = 0.05,
        q: float = 0.05,
        r: float = 0.05,
        window: int = 8,
        step_s: float = 0.2,
        horizon_steps: int = 1,
        resample: bool = True,
        fit_span_s: float = 2.0,
    ) -> None:
        check_config(
            "kf-paper",
            dt=(dt, 1e-6, 10.0),
            q=(q, 0.0, 1e6),
            r=(r, 1e-9, 1e6),
            window=(window, 2, 1000),
            step_s=(step_s, 1e-3, 10.0),
            horizon_steps=(horizon_steps, 1, 1000),
            fit_span_s=(fit_span_s, 0.0, 60.0),
        )
        self.dt = float(dt)
        self.q = float(q)
        self.r = float(r)
        self.window = int(window)
        self.step_s = float(step_s)
        self.horizon_steps = int(horizon_steps)
        self.resample = bool(resample)
        self.fit_span_s = float(fit_span_s)
        self._fixes = FixBuffer(256)
        self._imu = FixBuffer(1024)  # t, ax, ay (valid samples only)
        self._offsets = -self.step_s * np.arange(self.window - 1, -1, -1, dtype=float)
        self.reset()

    def config(self) -> dict:
        return {
            "dt": self.dt,
            "q": self.q,
            "r": self.r,
            "window": self.window,
            "step_s": self.step_s,
            "horizon_steps": self.horizon_steps,
            "resample": self.resample,
            "fit_span_s": self.fit_span_s,
        }

    def reset(self) -> None:
        self._fixes.clear()
        self._imu.clear()
        self._t = self._x = self._y = math.nan
        self._vx = self._vy = 0.0  # slope of the line fix -> predicted point [m/s]

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        if math.isfinite(ax) and math.isfinite(ay):
            self._imu.append(t, ax, ay)

    def _accel_at(self, times: np.ndarray) -> np.ndarray:
        """Latest IMU (ax, ay) at or before each time; zeros before the first sample."""
        out = np.zeros((times.size, 2))
        imu = self._imu
        if imu.n == 0:
            return out
        idx = np.searchsorted(imu.t, times, side="right") - 1
        ok = idx >= 0
        out[ok, 0] = imu.x[idx[ok]]
        out[ok, 1] = imu.y[idx[ok]]
        return out

    def observe_gps(self, t: float, x: float, y: float) -> None:  # type: ignore[override]  # three-argument form on purpose: no sigma passed (accepts_sigma)
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        buf = self._fixes
        buf.append(t, x, y)
        self._t, self._x, self._y = t, x, y
        self._vx = self._vy = 0.0
        if buf.n < 2:
            return
        grid_span = self.step_s * (self.window - 1)
        if self.resample and buf.n >= 4 and t - buf.t[0] >= grid_span - 1e-9:
            i = buf.window_start(max(self.fit_span_s, grid_span), 4)
            times = t + self._offsets
            points = self._resample(buf.t[i:], buf.xy_rows_from(i), times)
        else:
            i = max(0, buf.n - self.window)
            times = buf.t[i:]
            points = buf.xy_from(i)
        accel = self._accel_at(times)
        px, py = paper_window_predict(
            points, accel, accel[-1], self.dt, self.q, self.r, self.horizon_steps
        )
        h = self.horizon_steps * self.step_s
        self._vx = (px - x) / h
        self._vy = (py - y) / h

    def _resample(
        self, t: np.ndarray, xy: np.ndarray, times: np.ndarray
    ) -> np.ndarray | list[list[float]]:
        """The least-squares cubics through the fixes (times t [s], positions xy [m] as rows
        (2, n)) at ``times`` [s]: :func:`posbench.predictors._cubic_xy.fit_cubic_xy` evaluated in
        plain floats, or ``fit_cubic`` (lstsq) for a window with fewer than four distinct
        times. Pairs [x, y] [m], one per time."""
        fit = fit_cubic_xy(t, xy)
        if fit is None:
            return fit_cubic(t, xy.T)(times)
        (a0, a1, a2, a3), (b0, b1, b2, b3), t_ref, inv = fit
        out = []
        for tq in times.tolist():
            u = (tq - t_ref) * inv
            out.append([((a3 * u + a2) * u + a1) * u + a0, ((b3 * u + b2) * u + b1) * u + b0])
        return out

    def position_at(self, t: float) -> tuple[float, float]:
        if self._t != self._t:
            return NAN2
        dt = t - self._t
        return self._x + self._vx * dt, self._y + self._vy * dt
