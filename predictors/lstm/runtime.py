"""onnxruntime session wrapper for the predictors' hot path (no torch anywhere here).

One intra-op and one inter-op thread (no thread-pool wake-up tail), full graph
optimisation, a preallocated float32 input buffer for single windows.

Single windows cost ~20-30 us, most of it per-call overhead rather than arithmetic, so the
hot path takes two shortcuts, both checked to give the public API's outputs:

- ``batch_dim``: the graph's symbolic batch dimension pinned to 1 (onnxruntime then folds
  the LSTM's shape arithmetic: 14 nodes run instead of 18, ~3 us); :meth:`OnnxModel.run_batch`
  builds an unpinned session on first use;
- the feed is fixed (preallocated buffers, the inputs' names checked once), so
  :meth:`OnnxModel.run_buffer` calls the session's compiled ``run`` without the Python wrapper's
  per-call checks (~4 us under cache pressure); where onnxruntime's layout differs, or that call
  does not answer exactly as the public ``InferenceSession.run`` on a probe, the public one is used;
- where the output's shape is static, the buffers are bound once (IO binding: the inputs
  read in place, the output written into a preallocated array) and :meth:`run_buffer`
  calls the compiled ``run_with_iobinding`` (~3 us less: no feed dict, no output
  allocation); again only if it answers the probe exactly as the public ``run``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from posbench.scenarios.errors import DataError


def session_options() -> ort.SessionOptions:
    """1 intra-op / 1 inter-op thread, sequential execution, ORT_ENABLE_ALL."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 3
    return so


def _session(model: bytes, batch_dim: str | None = None) -> ort.InferenceSession:
    so = session_options()
    if batch_dim:
        so.add_free_dimension_override_by_name(batch_dim, 1)
    return ort.InferenceSession(model, sess_options=so, providers=["CPUExecutionProvider"])


class OnnxModel:
    """An ONNX network with float32 inputs; ``run`` feeds one window, ``run_batch`` many
    (both for the first input alone: one-input graphs); ``run_buffer`` feeds every input
    from its preallocated buffer (:attr:`bufs`).

    Args:
        path: the .onnx file.
        output: the output to request (default: the first).
        fixed_batch: pad single windows to this batch if the graph's batch is fixed.
        batch_dim: the name of the graph's symbolic batch dimension, pinned to 1 in
            :attr:`session` (single windows; see the module doc). A name the graph does
            not have changes nothing.
    """

    def __init__(
        self,
        path: str | Path,
        output: str | None = None,
        fixed_batch: int | None = None,
        batch_dim: str | None = None,
    ) -> None:
        p = Path(path)
        if not p.is_file():
            raise DataError(p, "ONNX model file not found")
        self.source = p.read_bytes()  # kept so that a pickled copy rebuilds its session anywhere
        self.batch_dim = batch_dim
        self._batch_session: ort.InferenceSession | None = None
        try:
            self.session = _session(self.source, batch_dim)
        except Exception as exc:  # onnxruntime raises its own exception types
            raise DataError(
                p,
                f"not a loadable ONNX model ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0][:200]})",
            ) from None
        ins = self.session.get_inputs()
        inp = ins[0]
        self.input_name = inp.name
        self.input_shape = list(inp.shape)
        #: every input's name and shape, in the graph's order (the first is ``input_name``)
        self.input_names = [i.name for i in ins]
        self.input_shapes = [list(i.shape) for i in ins]
        outs = [o.name for o in self.session.get_outputs()]
        if output is not None and output not in outs:
            raise DataError(p, f"ONNX model has no output {output!r} (outputs: {outs})")
        self.output_name = output or outs[0]
        self._outs = [self.output_name]
        dims = [d if isinstance(d, int) else None for d in self.input_shape]
        b = dims[0] if fixed_batch is None else fixed_batch
        self.batch = b if isinstance(b, int) else 1
        self.buf = np.zeros(
            [self.batch] + [d if d is not None else 1 for d in dims[1:]], dtype=np.float32
        )
        #: one preallocated float32 buffer per input (``bufs[0]`` is :attr:`buf`): a graph
        #: with several inputs is fed all of them by :meth:`run_buffer`
        self.bufs = [self.buf] + [
            np.zeros(
                [self.batch] + [d if isinstance(d, int) else 1 for d in shape[1:]], dtype=np.float32
            )
            for shape in self.input_shapes[1:]
        ]
        self._feed = dict(zip(self.input_names, self.bufs, strict=True))
        #: the batch dimension was pinned to 1: many windows need another session
        self.pinned = bool(batch_dim) and self.input_shape[0] == 1
        self._bind_fast_run()

    def _agrees(self, candidate: Callable[[], np.ndarray]) -> bool:
        """``candidate()`` answers exactly as the public ``run`` (its first output, whole) on
        the probe inputs: every buffer zero, then two ramps; the buffers are zero again
        afterwards. Any exception counts as disagreeing."""
        public = self.session.run
        try:
            for ramp in (None, 7, 11):
                for b in self.bufs:
                    b[...] = 0.0 if ramp is None else np.arange(b.size).reshape(b.shape) % ramp - 3
                if not np.array_equal(candidate(), public(self._outs, self._feed)[0]):
                    return False
            return True
        except Exception:  # pragma: no cover - another onnxruntime layout or signature
            return False
        finally:
            for b in self.bufs:
                b[...] = 0.0

    def _bind_fast_run(self) -> None:
        """``self._run(outputs, feed)``: the session's compiled run where it answers the probe
        (:meth:`_agrees`) exactly as the public ``run``, else the public one; and
        ``self._run_bound`` (:meth:`_bound_run`)."""
        self._run = self.session.run
        self._run_bound: Callable[[], np.ndarray] | None = None
        inner = getattr(self.session, "_sess", None)
        if inner is None:  # pragma: no cover - another onnxruntime layout
            return
        if self._agrees(lambda: inner.run(self._outs, self._feed, None)[0]):

            def run(
                outputs: list[str], feed: dict, _inner: Callable[..., list] = inner.run
            ) -> list:
                return _inner(outputs, feed, None)

            self._run = run
        self._run_bound = self._bound_run(inner)

    def _bound_run(self, inner: Any) -> Callable[[], np.ndarray] | None:
        """A call that runs the session on the bound buffers and returns the first row of
        a preallocated output (overwritten by the next call); None where the output shape
        is not static, binding is not available, or the probe answers differ."""
        meta = next(o for o in self.session.get_outputs() if o.name == self.output_name)
        shape = meta.shape
        if meta.type != "tensor(float)" or not all(isinstance(d, int) for d in shape):
            return None
        out = np.zeros(shape, dtype=np.float32)
        try:
            io = self.session.io_binding()
            for name, b in zip(self.input_names, self.bufs, strict=True):
                io.bind_cpu_input(name, b)
            io.bind_output(self.output_name, "cpu", 0, np.float32, list(shape), out.ctypes.data)
            run_io = inner.run_with_iobinding
        except Exception:  # pragma: no cover - another onnxruntime layout
            return None

        def run(
            _run: Callable[[Any, None], object] = run_io,
            _io: Any = io._iobinding,
            _out: np.ndarray = out,
        ) -> np.ndarray:
            _run(_io, None)
            return _out[0]

        def whole() -> np.ndarray:
            run()
            return out

        if not self._agrees(whole):
            return None
        self._binding = (io, out)  # keeps the binding and its output alive
        return run

    def __getstate__(self) -> dict:
        """Everything but the onnxruntime sessions (not picklable): they are rebuilt from the
        model bytes on unpickling, so predictors can cross process boundaries."""
        return {
            k: v
            for k, v in self.__dict__.items()
            if k not in ("session", "_batch_session", "_feed", "_run", "_run_bound", "_binding")
        }

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.session = _session(self.source, self.batch_dim)
        self._batch_session = None
        if "bufs" not in state:  # pickled before models with several inputs were fed
            self.input_names, self.bufs = [self.input_name], [self.buf]
        self._feed = dict(zip(self.input_names, self.bufs, strict=True))
        self._bind_fast_run()

    def _batch(self) -> ort.InferenceSession:
        """A session for many windows: :attr:`session`, or an unpinned one (built once) if
        the batch dimension was pinned to 1."""
        if not self.pinned:
            return self.session
        if self._batch_session is None:
            self._batch_session = _session(self.source)
        return self._batch_session

    def run(self, x: np.ndarray) -> np.ndarray:
        """One window (the input shape without the batch) -> its output row."""
        self.buf[0] = x
        return self._run(self._outs, self._feed)[0][0]

    def run_buffer(self) -> np.ndarray:
        """The network on :attr:`buf` as it stands (the caller wrote its window into
        ``buf[0]``, float32; a graph with several inputs: each into ``bufs[k][0]``): the
        first output row, without copying the input. The row may be a view of a
        preallocated output that the next call overwrites: use it before the next call."""
        if self._run_bound is not None:
            return self._run_bound()
        return self._run(self._outs, self._feed)[0][0]

    def run_batch(self, X: np.ndarray) -> np.ndarray:
        """Many windows (B, ...) -> outputs (B, ...), in chunks of a fixed batch if needed."""
        X = np.ascontiguousarray(X, dtype=np.float32)
        if self.pinned or (self.batch == 1 and not isinstance(self.input_shape[0], int)):
            return self._batch().run(self._outs, {self.input_name: X})[0]
        outs = []
        for i in range(0, X.shape[0], self.batch):
            chunk = X[i : i + self.batch]
            buf = np.zeros_like(self.buf)
            buf[: chunk.shape[0]] = chunk
            outs.append(self.session.run(self._outs, {self.input_name: buf})[0][: chunk.shape[0]])
        return np.concatenate(outs) if outs else np.zeros((0,))
