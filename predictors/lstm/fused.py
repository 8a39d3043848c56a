"""The fused ``lstm`` fix step: the same maths as the staged step, in four compiled calls.

The staged step (:meth:`posbench.predictors.lstm.predictor.LstmPredictor._step_on_fixes` with
``step="staged"``) stays the readable reference; this module computes the same answer
(to float rounding; a test holds them within 1e-6 m on every shared drive) with the
per-call overhead taken out (:mod:`posbench.predictors.lstm.fused_kernels`):

- both cubic regressions (the fixes' x, y and the IMU's ax, ay, yaw) are 4 x 4
  normal-equation systems from power sums of s = t - t_fix [s] (no scaling: the windows
  span ~2 s, so the normal equations stay well conditioned), solved and evaluated on the 8
  grid times (and +0.2 s) in one call;
- the features are written straight into the float32 input buffer in one call; a
  ``"speed"``-form model with a core (:mod:`posbench.predictors.lstm.core_net`) is fed its
  normalised input instead and runs in one compiled call
  (:mod:`posbench.predictors.lstm.core_kernel`), without onnxruntime;
- the current-position cubic (8 grid points + the prediction) is one call with the
  precomputed pseudo-inverse.

Frames: positions [m] in the drive's local ENU frame; IMU acceleration [m/s^2] in the
vehicle frame (x forward, y left); yaw [rad] unwrapped ENU; times [s].

Only fix steps with a window of >= 4 fixes are fused (strictly increasing times, so the
normal equations are regular); the caller runs the staged step for anything else (fewer
fixes: a lower-degree fit; a non-finite result; the L-BFGS fit; bridging steps inside
``position_at``), so rare paths keep the reference's behaviour exactly.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors.lstm import fused_kernels
from posbench.predictors.lstm.core_net import CoreNet
from posbench.predictors.lstm.features import gps_substitute_imu, time_feature
from posbench.predictors.lstm.resample import DT, GRID_OFFSETS, N_STEPS, powers
from posbench.predictors.lstm.runtime import OnnxModel

#: the rows of a block's coefficients: s^2, s^3, 1, s
_C2, _C3, _C0, _C1 = 0, 1, 2, 3
#: no IMU samples in the window
_NO_IMU = np.empty((0, 4))
#: the 8 grid times and the prediction's time, relative to the fix [s]
_TIMES9 = np.append(GRID_OFFSETS, DT)


def _eval_rows() -> np.ndarray:
    """(24, 4) rows that one product with the coefficients turns into: [0:9] the values at
    the 9 times, [9:16] the differences between neighbouring grid values, [16:24] the grid
    values minus the value at the fix (the constant term drops out exactly)."""
    p = powers(_TIMES9)[:, [2, 3, 0, 1]]
    rel = p[:8].copy()
    rel[:, _C0] = 0.0
    return np.concatenate([p, p[1:8] - p[:7], rel])


_REL = slice(16, 24)


class FusedStep:
    """Preallocated buffers and the arithmetic of one fused step (see the module doc).

    Args:
        net: the predictor's ONNX model; features are written into ``net.buf[0]`` (8, 6).
        frame: ``"heading"`` or ``"world"`` (:mod:`posbench.predictors.lstm.features`).
        final_pinv: (4, 9) pseudo-inverse of the current-position cubic through the 8 grid
            points and the prediction (times ``_TIMES9``).
        fix_offset: row 0 of the window holds the newest fix minus the newest grid point.
        core: the model's core graph (:class:`~posbench.predictors.lstm.core_net.CoreNet`), run
            instead of ``net`` where given.

    After a successful :meth:`finish`, :attr:`pts` (9, 2) holds the grid [m] and the
    prediction (row 8), :attr:`coef` the current-position cubic as 8 floats
    ``(x0..x3, y0..y3)`` in s = t - t_fix [s]; :attr:`psi` [rad] and :attr:`speed` [m/s]
    are the heading and speed of the fixes' cubic at the fix (after :meth:`fit`).
    ``pts`` is overwritten by the next step: copy what must be kept.
    """

    def __init__(
        self,
        net: OnnxModel,
        frame: str,
        final_pinv: np.ndarray,
        fix_offset: bool = False,
        core: CoreNet | None = None,
    ) -> None:
        self.net = net
        self.frame = frame
        self.final_pinv = np.ascontiguousarray(final_pinv)
        self.fix_offset = fix_offset
        self.core = core
        self._alloc()

    # scratch buffers are rebuilt, not pickled (a pickled view would lose its base)
    def __getstate__(self) -> dict:
        return {
            "net": self.net,
            "frame": self.frame,
            "final_pinv": self.final_pinv,
            "fix_offset": self.fix_offset,
            "core": self.core,
        }

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._alloc()

    def _alloc(self) -> None:
        self._x = np.empty((2, 4, 3))  # coefficients of the fixes' [0] and IMU's [1] cubics
        self._rows_eval = _eval_rows()
        # [0]: x, y (+ an unused 0), [1]: ax, ay, yaw; rows as in _eval_rows; row 8 of
        # [0] becomes the prediction
        self._e = np.empty((2, 24, 3))
        self.pts = self._e[0, :9, :2]
        self._x64 = np.zeros((8, 6))  # features in float64, cast once into the input
        self._x64[:, 5] = time_feature()
        self._cf = np.empty((2, 4))
        self._pinv_t = np.ascontiguousarray(self.final_pinv.T)  # (9, 4)
        self.coef: tuple[float, ...] = (0.0,) * 8
        self._fix_xy = (0.0, 0.0)  # the newest fix [m] (fix_offset models)
        # the core's input scales (speed_eps_m, res_std x, y), empty for a full graph
        core = self.core
        self._scales = np.array([core.eps, *core.res_std]) if core is not None else np.empty(0)
        self._s = 1.0  # the window's speed scale [m] (cores)
        self.psi = 0.0
        self.speed = math.nan

    def warm_up(self) -> None:
        """Run the compiled calls once on a made-up window (a straight line at 10 m/s, with
        IMU samples), so that no timed step pays their loading; every buffer they write
        is scratch, overwritten by the next step."""
        t = np.linspace(-2.0, 0.0, 11)
        ti = np.linspace(-2.0, 0.0, 101)
        self.fit(
            np.column_stack([t, 10.0 * t, 0.0 * t]),
            np.column_stack([ti, 0 * ti, 0 * ti, 0 * ti]),
            0.0,
        )
        self.features()
        if self.core is not None:
            self.core.run()
        self.finish(0.0, 0.0)

    def fit(
        self, fix: np.ndarray, imu: np.ndarray | None, t_end: float, yaw_ok: bool = True
    ) -> None:
        """Both cubics and their values on the grid (and 0.2 s past the fix).

        Args:
            fix: (n >= 4, 3) rows t [s], x, y [m] of the window of fixes, the last at t_end.
            imu: (m >= 4, 4) rows t [s], ax, ay [m/s^2, vehicle frame], yaw [rad] of the IMU
                samples in the window, or None: the GPS curve's stand-ins for all three.
            t_end: the newest fix's time [s] (the origin of s).
            yaw_ok: False if a yaw in ``imu`` is unknown: ax, ay are fitted, the yaw is the
                GPS curve's heading.
        """
        nf = fix.shape[0]
        self._fix_xy = (float(fix[nf - 1, 1]), float(fix[nf - 1, 2]))
        samples = imu if imu is not None and imu.shape[0] > 0 else _NO_IMU
        has_imu = samples is not _NO_IMU
        x = self._x
        e = self._e
        fused_kernels.fit_cubics(fix, samples, t_end, yaw_ok, self._rows_eval, x, e)
        if not (has_imu and yaw_ok):
            coef = x[0, [_C0, _C1, _C2, _C3], :2]
            ax, ay, yaw = gps_substitute_imu(coef, 1.0, GRID_OFFSETS)
            if not has_imu:
                e[1, :8, 0] = ax
                e[1, :8, 1] = ay
            e[1, :8, 2] = yaw
            e[1, _REL, 2] = yaw - yaw[7]
        c1x, c1y = float(x[0, _C1, 0]), float(x[0, _C1, 1])
        self.speed = math.hypot(c1x, c1y)
        self.psi = math.atan2(c1y, c1x)

    def features(self) -> None:
        """The network input (8, 6) from the grid values, written into the input buffer
        (the core's, or ``net.buf[0]``) in one compiled call
        (:func:`~posbench.predictors.lstm.fused_kernels.window_features`).

        Rotations: (dx + i dy) e^(-i psi) and (ax + i ay) e^(i rel) (the same products and
        sums as :func:`posbench.predictors.lstm.features.features_one`). A core takes the
        displacements divided by the window's speed scale s [m] (rotation-invariant: from
        the grid differences before any rotation), row 0 by res_std, and log s as a 7th
        column (:meth:`~posbench.predictors.lstm.core_net.CoreNet.load` is the reference)."""
        core = self.core
        fx, fy = self._fix_xy
        self._s = fused_kernels.window_features(
            self._e,
            self.psi,
            fx,
            fy,
            self.frame == "heading",
            self.fix_offset,
            self._scales,
            self._x64,
            core.buf if core is not None else self.net.buf[0],
        )

    def infer(self) -> tuple[float, float]:
        """The network on the window :meth:`features` wrote: its displacement output [m] in
        the model's frame (through the core where the model has one: the last grid step,
        unscaled, plus the residual x res_std)."""
        core = self.core
        if core is not None:
            o0, o1 = core.run()
            s = self._s
            x7 = self._x64[N_STEPS - 1]
            return float(x7[0]) * s + o0 * core.res_std[0], float(x7[1]) * s + o1 * core.res_std[1]
        out = self.net.run_buffer()
        return float(out[0]), float(out[1])

    def finish(self, d0: float, d1: float) -> bool:
        """The prediction from the network's displacement (d0, d1) [m, model frame] and the
        current-position cubic; False if the prediction is not finite (the caller then
        runs the staged step)."""
        cf = self._cf
        if not fused_kernels.finish_step(
            self._e, d0, d1, self.psi, self.frame == "heading", self._pinv_t, cf
        ):
            return False
        self.coef = tuple(cf.ravel().tolist())
        return True
