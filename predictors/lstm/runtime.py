"""onnxruntime session wrapper for the predictors' hot path (no torch anywhere here).

One intra-op and one inter-op thread (no thread-pool wake-up tail), full graph
optimisation, a preallocated float32 input buffer for single windows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort

from scenarios.errors import DataError


def session_options() -> ort.SessionOptions:
    """1 intra-op / 1 inter-op thread, sequential execution, ORT_ENABLE_ALL."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 3
    return so


def _session(model: bytes) -> ort.InferenceSession:
    return ort.InferenceSession(model, sess_options=session_options(),
                                providers=["CPUExecutionProvider"])


class OnnxModel:
    """An ONNX network with one float32 input; ``run`` feeds one window, ``run_batch`` many.

    Args:
        path: the .onnx file.
        output: the output to request (default: the first).
        fixed_batch: pad single windows to this batch if the graph's batch is fixed.
    """

    def __init__(self, path: str | Path, output: str | None = None,
                 fixed_batch: int | None = None) -> None:
        p = Path(path)
        if not p.is_file():
            raise DataError(p, "ONNX model file not found")
        self.source = p.read_bytes()  # kept so that a pickled copy rebuilds its session anywhere
        try:
            self.session = _session(self.source)
        except Exception as exc:  # onnxruntime raises its own exception types
            raise DataError(p, f"not a loadable ONNX model ({type(exc).__name__}: "
                               f"{str(exc).splitlines()[0][:200]})") from None
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        self.input_shape = list(inp.shape)
        outs = [o.name for o in self.session.get_outputs()]
        if output is not None and output not in outs:
            raise DataError(p, f"ONNX model has no output {output!r} (outputs: {outs})")
        self.output_name = output or outs[0]
        self._outs = [self.output_name]
        dims = [d if isinstance(d, int) else None for d in self.input_shape]
        b = dims[0] if fixed_batch is None else fixed_batch
        self.batch = b if isinstance(b, int) else 1
        self.buf = np.zeros([self.batch] + [d if d is not None else 1 for d in dims[1:]],
                            dtype=np.float32)
        self._feed = {self.input_name: self.buf}

    def __getstate__(self) -> dict:
        """Everything but the onnxruntime session (not picklable): it is rebuilt from the
        model bytes on unpickling, so predictors can cross process boundaries."""
        return {k: v for k, v in self.__dict__.items() if k not in ("session", "_feed")}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.session = _session(self.source)
        self._feed = {self.input_name: self.buf}

    def run(self, x: np.ndarray) -> np.ndarray:
        """One window (the input shape without the batch) -> its output row."""
        self.buf[0] = x
        return self.session.run(self._outs, self._feed)[0][0]

    def run_batch(self, X: np.ndarray) -> np.ndarray:
        """Many windows (B, ...) -> outputs (B, ...), in chunks of a fixed batch if needed."""
        X = np.ascontiguousarray(X, dtype=np.float32)
        if self.batch == 1 and not isinstance(self.input_shape[0], int):
            return self.session.run(self._outs, {self.input_name: X})[0]
        outs = []
        for i in range(0, X.shape[0], self.batch):
            chunk = X[i:i + self.batch]
            buf = np.zeros_like(self.buf)
            buf[:chunk.shape[0]] = chunk
            outs.append(self.session.run(self._outs, {self.input_name: buf})[0][:chunk.shape[0]])
        return np.concatenate(outs) if outs else np.zeros((0,))
