"""``lstm-authors``: the paper authors' published ONNX network in the same streaming pipeline.

The files (``../shared/models/authors/*.onnx``, MIT, never bundled) take ``[batch, 6, 8]``:
features x 8 samples 200 ms apart, oldest first, in the authors' layout

- x, y [m]: the resampled fixes in the route frame (see ``origin``);
- ax, ay [m/s^2]: IMU acceleration in the vehicle frame, *not* rotated;
- theta [rad]: heading of the fitted GPS curve (atan2 of its derivative), wrapped;
- t [s]: 0, 0.2, ..., 1.4;

and return ``output`` ``[batch, 6, 1]``: the same features 200 ms after the last sample,
x, y in the input's frame. The network normalises each window internally.

Everything else (cubic resampling, dropout feedback loop, standstill hold, start-up
line, final cubic for the current position) is
:class:`~posbench.predictors.lstm.predictor.LstmPredictor`'s.

``origin``: ``"window"`` (default) subtracts the window's first grid sample from x, y
and adds it back to the output (the paper: "each training sequence commences at the
coordinate origin"); ``"absolute"`` feeds the drive's local coordinates as they are.
Measured on the aslan routes (see the report / tests): both give the same predictions to
about a millimetre, since the graph normalises per window; ``"window"`` is kept as it
does not depend on where the drive's origin lies.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from posbench.predictors.lstm.predictor import Fit, LstmPredictor
from posbench.predictors.lstm.resample import GRID_OFFSETS, N_STEPS, deriv_poly
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.scenarios.errors import DataError

OUTPUT = "output"
FIXED_BATCH = 1024
Origin = Literal["window", "absolute"]
ORIGINS: tuple[str, ...] = get_args(Origin)
_T = np.arange(N_STEPS) * 0.2


class AuthorsLstmPredictor(LstmPredictor):
    """The authors' ONNX network (``--model PATH`` to one of their .onnx files).

    Args:
        model: path of ``gps_interpolation_model2.onnx`` / ``..._model3.onnx``.
        fit: ``"closed"`` or ``"lbfgs"`` (as :class:`LstmPredictor`).
        origin: ``"window"`` or ``"absolute"`` (see the module doc).

    :meth:`model_description` names the .onnx file (never bundled); :meth:`training_drives`
    is (): the authors' files come without a model description and their ONNX metadata
    records no training data.
    """

    name = "lstm-authors"

    def __init__(
        self, model: str | None = None, fit: Fit = "closed", origin: Origin = "window"
    ) -> None:
        if model is None:
            raise DataError(
                None,
                "lstm-authors needs the authors' ONNX file: pass --model PATH "
                "(e.g. ../shared/models/authors/gps_interpolation_model3.onnx); "
                "it is not bundled",
            )
        if fit not in ("closed", "lbfgs"):
            raise ValueError(f"fit must be 'closed' or 'lbfgs', not {fit!r}")
        if origin not in ORIGINS:
            raise ValueError(f"origin must be one of {ORIGINS}, not {origin!r}")
        self.model_path = Path(model)
        self.fit = fit
        self.step = "staged"  # the authors' feature layout runs through the staged step
        self.origin = origin
        self.frame = "authors"
        self.info = {}
        self.bundled = False  # the authors' files are never bundled
        self.net = OnnxModel(self.model_path, output=OUTPUT)
        try:
            self.net.run(np.zeros((6, N_STEPS), dtype=np.float32))
        except Exception:  # onnxruntime rejects batch 1: feed fixed batches, padded
            self.net = OnnxModel(self.model_path, output=OUTPUT, fixed_batch=FIXED_BATCH)
        self._xa = np.empty((6, N_STEPS))
        self._off = np.zeros(2)  # x, y offset [m] of the newest network input
        self._init_buffers()

    def config(self) -> dict:
        return {
            "model": str(self.model_path),
            "fit": self.fit,
            "origin": self.origin,
            "batch": self.net.batch,
        }

    def features(
        self, grid: np.ndarray, ax: np.ndarray, ay: np.ndarray, coef: np.ndarray, scale: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The authors' input (6, 8) and the x, y offset subtracted from positions."""
        d = deriv_poly(coef, GRID_OFFSETS / scale)
        off = grid[0].copy() if self.origin == "window" else np.zeros(2)
        x = self._xa
        x[0] = grid[:, 0] - off[0]
        x[1] = grid[:, 1] - off[1]
        x[2] = ax
        x[3] = ay
        x[4] = np.arctan2(d[:, 1], d[:, 0])
        x[5] = _T
        return x, off

    def _net_input(
        self,
        grid: np.ndarray,
        ax: np.ndarray,
        ay: np.ndarray,
        yaw: np.ndarray,
        psi: float,
        coef: np.ndarray,
        scale: float,
    ) -> np.ndarray:
        x, self._off = self.features(grid, ax, ay, coef, scale)
        return x

    def _net_output(self, out: np.ndarray, grid: np.ndarray, psi: float) -> tuple[float, float]:
        out = np.asarray(out).reshape(-1)
        off = self._off
        px, py = float(out[0]) + off[0], float(out[1]) + off[1]
        if not (math.isfinite(px) and math.isfinite(py)):
            return 0.0, 0.0
        return px - grid[-1, 0], py - grid[-1, 1]
