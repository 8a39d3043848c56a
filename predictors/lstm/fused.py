"""The fused ``lstm`` fix step: the same maths as the staged step, in few numpy calls.

The staged step (:meth:`posbench.predictors.lstm.predictor.LstmPredictor._step_on_fixes` with
``step="staged"``) stays the readable reference; this module computes the same answer
(to float rounding; a test holds them within 1e-6 m on every shared drive) with the
per-call overhead taken out:

- both cubic regressions (the fixes' x, y and the IMU's ax, ay, yaw) are one batched
  solve of two 4 x 4 normal-equation systems. Each system comes from ONE matrix product
  ``V.T @ [V | Y]`` over a preallocated block ``[1, s, s^2, s^3, y...]`` (s = t - t_fix
  [s], no scaling: the windows span ~2 s, so the normal equations stay well conditioned);
- both cubics are evaluated on the 8 grid times (and +0.2 s) by one product with a
  precomputed Vandermonde matrix;
- the features are written straight into the float32 input buffer of the ONNX session
  (rotations as complex products); a ``"speed"``-form model with a core graph
  (:mod:`posbench.predictors.lstm.core_net`) is fed its normalised input instead and runs without
  the ~30 normalisation nodes of the full graph;
- the current-position cubic (8 grid points + the prediction) is one product with the
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

from posbench.predictors.lstm.core_net import CoreNet
from posbench.predictors.lstm.features import N_FEATURES, gps_substitute_imu, time_feature
from posbench.predictors.lstm.resample import DT, GRID_OFFSETS, N_STEPS, powers
from posbench.predictors.lstm.runtime import OnnxModel

try:  # the gufunc behind np.linalg.solve, without its Python-side checks (~3 us)
    from numpy.linalg import _umath_linalg

    def _solve(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        return _umath_linalg.solve(a, b, signature="dd->d", out=out)
except (ImportError, AttributeError):  # pragma: no cover - other NumPy layouts

    def _solve(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        out[...] = np.linalg.solve(a, b)
        return out


#: columns of a fit block: s^2, s^3, 1, s, then 3 value channels (x, y, 0 for the fixes;
#: ax, ay, yaw for the IMU). With this order one subtraction of (t_end, 0, ...) from the
#: buffer's rows (t, values...) writes s and the values at once, and the basis columns
#: (s^2, s^3, 1, s) are adjacent: coefficients come out in that order (``_C0``.. below)
_COLS = 7
_C2, _C3, _C0, _C1 = 0, 1, 2, 3
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


_VAL, _DIFF, _REL = slice(0, 9), slice(9, 16), slice(16, 24)


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

    def _alloc(self, rows: int = 256) -> None:
        # the two fit blocks, fixes [0] and IMU [1], stored by column (each column's
        # samples contiguous) and padded with all-zero samples (which add nothing to the
        # normal equations) so that one product serves both
        self._w = np.zeros((2, _COLS, rows))
        self._live = [0, 0]  # samples of each block with the 1 set; all-zero beyond
        self._t3 = np.zeros((3, 1))  # (t_end, 0, 0): subtracted from fix rows (t, x, y)
        self._t4 = np.zeros((4, 1))  # (t_end, 0, 0, 0): from IMU rows (t, ax, ay, yaw)
        self._m = np.empty((2, 4, _COLS))
        self._x = np.empty((2, 4, 3))
        self._rows_eval = _eval_rows()
        # [0]: x, y (+ an unused 0), [1]: ax, ay, yaw; rows as in _eval_rows; row 8 of
        # [0] becomes the prediction
        self._e = np.empty((2, 24, 3))
        self.pts = self._e[0, :9, :2]
        self._ec = self._e[:, :, :2].view(np.complex128)[..., 0]  # x + iy, ax + i ay
        self._x64 = np.zeros((8, 6))  # features in float64, cast once into net.buf
        self._x64[:, 5] = time_feature()
        self._xc = self._x64[:, :4].view(np.complex128)  # (8, 2): dx + i dy, ax + i ay
        self._cs = np.empty((8, 2))
        self._csc = self._cs.view(np.complex128)[:, 0]  # cos + i sin of the relative yaw
        self._cf = np.empty((2, 4))
        self._pinv_t = np.ascontiguousarray(self.final_pinv.T)  # (9, 4)
        self.coef: tuple[float, ...] = (0.0,) * 8
        self._fix_c = 0j  # the newest fix as x + iy (fix_offset models)
        self._s = 1.0  # the window's speed scale [m] (core graphs)
        self.psi = 0.0
        self.speed = math.nan

    def _rows(self, k: int, n: int) -> np.ndarray:
        """Block k (columns x samples) with exactly n live samples (grown when too small)."""
        w = self._w
        if n > w.shape[2]:
            g = np.zeros((2, _COLS, max(n, 2 * w.shape[2])))
            g[:, :, : w.shape[2]] = w
            self._w = w = g
        live = self._live[k]
        if n > live:
            w[k, _C0, live:n] = 1.0
        elif n < live:
            w[k, :, n:live] = 0.0
        self._live[k] = n
        return w[k]

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
        ni = 0 if imu is None else imu.shape[0]
        self._fix_c = complex(fix[nf - 1, 1], fix[nf - 1, 2])
        t3 = self._t3
        t3[0, 0] = t_end
        np.subtract(fix.T, t3, out=self._rows(0, nf)[3:6, :nf])
        b = self._rows(1, ni)
        if imu is not None and ni:
            t4 = self._t4
            t4[0, 0] = t_end
            np.subtract(imu.T, t4, out=b[3:7, :ni])
            if not yaw_ok:
                b[6, :ni] = 0.0
        w = self._w[:, :, : max(nf, ni)]
        s = w[:, _C1]
        np.multiply(s, s, out=w[:, _C2])
        np.multiply(w[:, _C2], s, out=w[:, _C3])
        m = np.matmul(w[:, :4], w.transpose(0, 2, 1), out=self._m)
        x = self._x
        e = self._e
        if ni:
            _solve(m[:, :, :4], m[:, :, 4:], x)
            np.matmul(self._rows_eval, x, out=e)
        else:
            _solve(m[0, :, :4], m[0, :, 4:], x[0])
            np.matmul(self._rows_eval, x[0], out=e[0])
        if not (ni and yaw_ok):
            coef = x[0, [_C0, _C1, _C2, _C3], :2]
            ax, ay, yaw = gps_substitute_imu(coef, 1.0, GRID_OFFSETS)
            if not ni:
                e[1, :8, 0] = ax
                e[1, :8, 1] = ay
            e[1, :8, 2] = yaw
            e[1, _REL, 2] = yaw - yaw[7]
        c1x, c1y = x[0, _C1, :2].tolist()
        self.speed = math.hypot(c1x, c1y)
        self.psi = math.atan2(c1y, c1x)

    def features(self) -> None:
        """The network input (8, 6) from the grid values, cast once into ``net.buf[0]``.

        Rotations are complex products: (dx + i dy) e^(-i psi) and (ax + i ay) e^(i rel)
        (the same products and sums as :func:`posbench.predictors.lstm.features.features_one`)."""
        x64 = self._x64
        xc = self._xc
        ec = self._ec
        imu = self._e[1]
        core = self.core
        # a core graph takes the displacements divided by the window's speed scale s [m]
        # (rotation-invariant: from the grid differences before any rotation) and row 0 by
        # res_std, and log s as a 7th column (core_net.CoreNet.load is the reference)
        if core is not None:
            s = sum(map(abs, ec[0, _DIFF].tolist())) / (N_STEPS - 1) + core.eps
            self._s = s
            k = 1.0 / s
        else:
            k = 1.0
        if self.frame == "heading":
            rot = complex(math.cos(self.psi), -math.sin(self.psi))
            np.multiply(ec[0, _DIFF], rot * k, out=xc[1:, 0])
            if self.fix_offset:  # row 0: the newest fix minus the newest grid point
                off = (self._fix_c - ec[0, 7]) * rot
            rel = imu[_REL, 2]  # yaw relative to the newest sample
            x64[:, 4] = rel
        else:
            np.multiply(ec[0, _DIFF], k, out=xc[1:, 0])
            if self.fix_offset:
                off = self._fix_c - ec[0, 7]
            rel = imu[:8, 2]
            x64[:, 4] = np.pi - np.mod(np.pi - rel, 2 * np.pi)
        if self.fix_offset:
            xc[0, 0] = (
                off
                if core is None
                else complex(off.real / core.res_std[0], off.imag / core.res_std[1])
            )
        cs = self._cs
        np.cos(rel, out=cs[:, 0])
        np.sin(rel, out=cs[:, 1])
        np.multiply(ec[1, :8], self._csc, out=xc[:, 1])
        if core is not None:
            z = core.net.buf
            z[:, :N_FEATURES] = x64
            z[:, N_FEATURES] = math.log(s)
        else:
            self.net.buf[0] = x64

    def infer(self) -> tuple[float, float]:
        """The network on the window :meth:`features` wrote: its displacement output [m] in
        the model's frame (through the core graph where the model has one: the last grid
        step, unscaled, plus the residual x res_std)."""
        core = self.core
        if core is not None:
            o0, o1 = core.net.run_buffer().tolist()
            d7 = complex(self._xc[N_STEPS - 1, 0]) * self._s
            return d7.real + o0 * core.res_std[0], d7.imag + o1 * core.res_std[1]
        out = self.net.run_buffer()
        return float(out[0]), float(out[1])

    def finish(self, d0: float, d1: float) -> bool:
        """The prediction from the network's displacement (d0, d1) [m, model frame] and the
        current-position cubic; False if the prediction is not finite (the caller then
        runs the staged step)."""
        if self.frame == "heading":
            c, s = math.cos(self.psi), math.sin(self.psi)
            d0, d1 = c * d0 - s * d1, s * d0 + c * d1
        pts = self.pts
        px = float(pts[7, 0]) + d0
        py = float(pts[7, 1]) + d1
        if not (math.isfinite(px) and math.isfinite(py)):
            return False
        pts[8, 0] = px
        pts[8, 1] = py
        cf = np.matmul(pts.T, self._pinv_t, out=self._cf)  # (2, 4): x0..x3, y0..y3
        self.coef = tuple(cf.ravel().tolist())
        return True
