"""The core network of a ``"speed"``-form model at run time: the fused step's inference
without the ~30 normalisation nodes of the full graph and without onnxruntime (see
:mod:`posbench.predictors.lstm.core_graph`, which folds its weights, and
:mod:`posbench.predictors.lstm.core_kernel`, which runs them in one compiled call).

The fused step writes its (8, 6) float64 window once; :meth:`CoreNet.load` applies the
model's input scaling in three numpy calls (the displacements divided by the window's speed
scale, row 0's fix offset by ``res_std``, ``log s`` as column 7; the standardisation of the
other columns lives in the core's weights) and :meth:`CoreNet.displacement` turns the core's
standardised residual into the displacement 200 ms ahead [m, the model's frame]:
``d_7 + o * res_std``, as :class:`posbench.predictors.lstm.model.FuturePoint` does in-graph.

A core is used only if it reproduces its full graph: on load, its weights (through the numpy
reference :func:`~posbench.predictors.lstm.core_kernel.core_forward_numpy`, so that building
a predictor does not import numba) and the full graph answer the same deterministic windows
(0-40 m/s, turning, braking) and must agree to :data:`CORE_TOL_M`; a core that does not, or a
weights file that cannot be read, is refused with a one-line
:class:`~posbench.scenarios.errors.DataError`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from posbench.predictors.lstm import core_kernel
from posbench.predictors.lstm.features import N_FEATURES
from posbench.predictors.lstm.resample import DT, N_STEPS
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.scenarios.errors import DataError

#: largest displacement difference [m] allowed between core and full graph on the check
#: windows (float32 rounding of the folded weights is ~1e-7 m)
CORE_TOL_M = 1e-5
#: check windows on load
CHECK_WINDOWS = 24


def check_windows(n: int = CHECK_WINDOWS, seed: int = 0) -> np.ndarray:
    """(n, 8, 6) deterministic raw windows (heading frame): 0-8 m per 0.2 s step (0-40 m/s),
    turning and braking, IMU and yaw of matching size, a fix offset of a few cm in row 0;
    float32-representable, so both graphs see the same numbers."""
    rng = np.random.default_rng(seed)
    x = np.zeros((n, N_STEPS, N_FEATURES))
    step = rng.uniform(0.0, 8.0, n)[:, None] * (
        1 + rng.uniform(-0.2, 0.2, n)[:, None] * np.linspace(-1, 1, N_STEPS)
    )
    turn = rng.normal(0.0, 0.1, n)[:, None] * np.arange(N_STEPS)
    x[:, :, 0] = step * np.cos(turn)
    x[:, :, 1] = step * np.sin(turn)
    x[:, 0, :2] = rng.normal(0.0, 0.03, (n, 2))
    x[:, :, 2:4] = rng.normal(0.0, 1.0, (n, N_STEPS, 2))
    x[:, :, 4] = turn - turn[:, -1:]
    x[:, :, 5] = np.arange(N_STEPS) * DT
    return x.astype(np.float32).astype(np.float64)


def has_core(onnx_path: Path, info: dict) -> bool:
    """``model.json`` names a core graph and its file is beside the model (a model copied
    without it runs its full graph: slower, same answers)."""
    entry = info.get("core")
    return (
        isinstance(entry, dict)
        and bool(entry.get("file"))
        and Path(onnx_path).with_name(str(entry["file"])).is_file()
    )


class CoreNet:
    """The core beside a full model (its folded weights, ``<stem>.core.npz``), with the
    scaling the fused step applies.

    Args:
        onnx_path: the full ``model.onnx`` (the core's file name in ``entry`` is relative
            to it).
        entry: ``model.json["core"]`` (:func:`posbench.predictors.lstm.core_graph.write_core`).
        full: the full model's session, to check the core against.
    Raises:
        DataError: the core file is missing or unreadable, its arrays have other shapes, or
            it does not reproduce the full graph.
    """

    def __init__(self, onnx_path: Path, entry: dict, full: OnnxModel) -> None:
        path = Path(onnx_path).with_name(str(entry.get("file", "")))
        self.path = path
        weights, slope = core_kernel.load_weights(path)
        self.core = core_kernel.CompiledCore(weights, slope)
        d = self.core.dims
        if (d.n_in, d.n_extra, d.n_out) != (N_FEATURES + 1, 0, 2):
            raise DataError(
                path,
                f"core of {d.n_in} inputs, {d.n_extra} extra and {d.n_out} outputs, "
                f"expected {N_FEATURES + 1}, 0 and 2",
            )
        #: the core's input (8, 7) float32: :meth:`load` or the fused step writes it
        self.buf = np.zeros((N_STEPS, N_FEATURES + 1), np.float32)
        self.res_std = (float(entry["res_std_m"][0]), float(entry["res_std_m"][1]))
        self.eps = float(entry["speed_eps_m"])
        #: per-element input scale: rows 1-7 of the displacement columns are set to 1/s per
        #: window; row 0 (fix offset) 1/res_std; the raw columns 1
        self._scale = np.ones((N_STEPS, N_FEATURES))
        self._scale[0, :2] = (1.0 / self.res_std[0], 1.0 / self.res_std[1])
        worst = self.difference(full)
        if not worst <= CORE_TOL_M:
            raise DataError(
                path,
                f"does not reproduce {Path(onnx_path).name}: displacements "
                f"differ by up to {worst:.3g} m (allowed {CORE_TOL_M:g}); "
                "export the model again with `bench train`",
            )

    def _scaled(self, x: np.ndarray) -> tuple[np.ndarray, float]:
        """The core's input for the raw window ``x`` (8, 6) float64 and its speed scale s
        [m] = mean length of the grid displacements of rows 1-7 + ``speed_eps_m``."""
        s = float(np.hypot(x[1:, 0], x[1:, 1]).sum()) / (N_STEPS - 1) + self.eps
        sc = self._scale
        sc[1:, :2] = 1.0 / s
        z = np.empty((N_STEPS, N_FEATURES + 1), np.float32)
        np.multiply(x, sc, out=z[:, :N_FEATURES], casting="same_kind")
        z[:, N_FEATURES] = math.log(s)
        return z, s

    def load(self, x: np.ndarray) -> None:
        """Write the raw window ``x`` (8, 6) float64 (row 0: the fix offset) into
        :attr:`buf`, scaled as the full graph's ``encode_input``."""
        self.buf[...] = self._scaled(x)[0]

    def run(self) -> tuple[float, float]:
        """The core on :attr:`buf` (compiled): its standardised residual."""
        o = self.core.run(self.buf)
        return float(o[0]), float(o[1])

    def displacement(self, x: np.ndarray) -> tuple[float, float]:
        """The core on the loaded window: the displacement 200 ms ahead [m, the model's
        frame] = the last grid displacement of ``x`` + the residual x ``res_std``."""
        o0, o1 = self.run()
        return (
            float(x[N_STEPS - 1, 0]) + o0 * self.res_std[0],
            float(x[N_STEPS - 1, 1]) + o1 * self.res_std[1],
        )

    def difference(self, full: OnnxModel) -> float:
        """Largest |displacement| difference [m] between this core's weights (numpy
        reference, exact sigmoid and tanh) and ``full`` on :func:`check_windows`."""
        windows = check_windows()
        z = np.stack([self._scaled(x)[0] for x in windows])
        o = self.core.reference(z).astype(np.float64)
        got = windows[:, N_STEPS - 1, :2] + o * np.asarray(self.res_std)
        want = np.stack([full.run(x)[:2] for x in windows]).astype(np.float64)
        return float(np.max(np.abs(got - want)))  # NaN if either answered NaN
