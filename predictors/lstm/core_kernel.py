"""A small recurrent network as one compiled call (numba), and its numpy reference: the
*core* of the ``lstm``'s and the ``hybrid``'s models, all normalisation folded into its
weights.

The core: encoder ``Linear(n_in, H) -> LeakyReLU``, one LSTM layer of ``H`` over the 8 grid
samples (ONNX gate order i, o, f, c; zero initial state), decoder ``Linear(H + n_extra, H) ->
LeakyReLU -> Linear(H, n_out)`` on the last hidden state and ``n_extra`` further inputs (the
hybrid's prior; none for the lstm). Input ``z`` (8, n_in) float32 and ``extra``
(n_extra,) float32; output (n_out,). The ``lstm``'s core (n_in 7, n_out 2) is cut by
:mod:`posbench.predictors.lstm.core_graph` and run by :mod:`posbench.predictors.lstm.core_net`;
the hybrid's (n_in 6, n_extra 8, n_out 16) by :mod:`posbench.predictors.hybrid.core`.

For one window per call onnxruntime spends most of its ~20-60 us in per-node overhead
around ~0.1-0.3 M multiply-adds; :func:`core_forward` runs the same float32 arithmetic in
one call, with the gates' sigmoid and tanh as the rational approximation onnxruntime's MLAS
and Eigen use (|error| < 1e-6 on [-9, 9], saturated beyond), so its answers differ from
onnxruntime's by float32 rounding. :func:`core_forward_numpy` is the plain reference (exact
``tanh``, batched windows): it checks a core's weights against its full graph on load
without importing numba.

Weights travel as one flat float32 array (:func:`pack`) in the layout the kernel reads:
``enc_wT (n_in, H) | enc_b (H) | w_ihT (H, 4H) | w_hhT (H, 4H) | bias (4H) | dec0_wT
(H + n_extra, H) | dec0_b (H) | dec2_w (n_out, H) | dec2_b (n_out)``; transposed where the
kernel runs over outputs innermost (contiguous, vectorised).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posbench.predictors._kernels import fast_kernel
from posbench.scenarios.errors import DataError

#: the arrays of a core's weights file (``<stem>.core.npz``, besides ``slope``) and their
#: shapes (H hidden, E extra inputs, O outputs, I inputs)
WEIGHT_SHAPES = {
    "enc_w": ("H", "I"),
    "enc_b": ("H",),
    "lstm_w": (1, "4H", "H"),
    "lstm_r": (1, "4H", "H"),
    "lstm_b": (1, "8H"),
    "dec0_w": ("H", "H+E"),
    "dec0_b": ("H",),
    "dec2_w": ("O", "H"),
    "dec2_b": ("O",),
}


@dataclass(frozen=True)
class CoreDims:
    """A core's sizes: inputs per step, hidden units, extra decoder inputs, outputs."""

    n_in: int
    hidden: int
    n_extra: int
    n_out: int


def check_shapes(weights: Mapping[str, np.ndarray]) -> CoreDims:
    """The sizes of a core's weights; ValueError naming the first array that is missing
    or has another shape."""
    for name in ("enc_w", "dec0_w", "dec2_w"):
        if name not in weights or np.ndim(weights[name]) != 2:
            raise ValueError(f"no 2-D array {name}")
    hidden, n_in = (int(v) for v in np.shape(weights["enc_w"]))
    dims = CoreDims(
        n_in=n_in,
        hidden=hidden,
        n_extra=int(np.shape(weights["dec0_w"])[1]) - hidden,
        n_out=int(np.shape(weights["dec2_w"])[0]),
    )
    sizes = {
        "H": hidden,
        "4H": 4 * hidden,
        "8H": 8 * hidden,
        "I": n_in,
        "H+E": hidden + max(dims.n_extra, 0),
        "O": dims.n_out,
    }
    for name, shape in WEIGHT_SHAPES.items():
        want = tuple(sizes[d] if isinstance(d, str) else d for d in shape)
        got = np.shape(weights[name]) if name in weights else None
        if got != want:
            raise ValueError(f"array {name} has shape {got}, expected {want}")
    return dims


#: the packed weights start on this boundary [bytes], so that the kernel's vector loads of
#: a weight row never straddle a cache line: the lstm's core took 17 us aligned and 21-29 us
#: 16 or 48 bytes past a boundary (where numpy's allocation happened to put it), with the
#: same answers
ALIGN = 64


def aligned(a: np.ndarray) -> np.ndarray:
    """A copy of 1-D ``a`` that starts on an :data:`ALIGN`-byte boundary."""
    buf = np.empty(a.size + ALIGN // a.itemsize, a.dtype)
    start = (-buf.ctypes.data % ALIGN) // a.itemsize
    out = buf[start : start + a.size]
    out[:] = a
    return out


def pack(weights: Mapping[str, np.ndarray]) -> np.ndarray:
    """The flat float32 array :func:`core_forward` reads (module doc) from the arrays of a
    core's weights file, :func:`aligned`."""
    h = check_shapes(weights).hidden
    b = np.asarray(weights["lstm_b"], np.float64)[0]
    parts = [
        np.asarray(weights["enc_w"]).T,
        weights["enc_b"],
        np.asarray(weights["lstm_w"])[0].T,
        np.asarray(weights["lstm_r"])[0].T,
        b[: 4 * h] + b[4 * h :],
        np.asarray(weights["dec0_w"]).T,
        weights["dec0_b"],
        weights["dec2_w"],
        weights["dec2_b"],
    ]
    return aligned(np.concatenate([np.asarray(p, np.float32).ravel() for p in parts]))


def output_buffer(dims: CoreDims) -> np.ndarray:
    """The buffer :func:`core_forward` writes its output to: (n_out,) float32."""
    return np.zeros(dims.n_out, np.float32)


def core_forward_numpy(
    z: np.ndarray,
    weights: Mapping[str, np.ndarray],
    slope: float,
    extra: np.ndarray | None = None,
) -> np.ndarray:
    """Reference forward pass: ``z`` (B, 8, n_in) and ``extra`` (B, n_extra) -> (B, n_out),
    float32 arithmetic with exact sigmoid and tanh (ONNX LSTM semantics)."""
    f32 = np.float32
    h_n = int(np.shape(weights["enc_w"])[0])
    z = np.asarray(z, f32)
    e = z @ np.asarray(weights["enc_w"], f32).T + np.asarray(weights["enc_b"], f32)
    e = np.where(e > 0, e, f32(slope) * e)
    w = np.asarray(weights["lstm_w"], f32)[0]
    r = np.asarray(weights["lstm_r"], f32)[0]
    b = np.asarray(weights["lstm_b"], f32)[0]
    gx = e @ w.T + (b[: 4 * h_n] + b[4 * h_n :])
    h = np.zeros((z.shape[0], h_n), f32)
    c = np.zeros_like(h)
    for t in range(z.shape[1]):
        g = gx[:, t] + h @ r.T
        i, o, f = (0.5 + 0.5 * np.tanh(0.5 * g[:, k * h_n : (k + 1) * h_n]) for k in range(3))
        c = f * c + i * np.tanh(g[:, 3 * h_n :])
        h = o * np.tanh(c)
    if extra is not None:
        h = np.concatenate([h, np.asarray(extra, f32).reshape(len(h), -1)], axis=1)
    d = h @ np.asarray(weights["dec0_w"], f32).T + np.asarray(weights["dec0_b"], f32)
    d = np.where(d > 0, d, f32(slope) * d)
    return d @ np.asarray(weights["dec2_w"], f32).T + np.asarray(weights["dec2_b"], f32)


@fast_kernel
def _tanh(x: np.float32) -> np.float32:
    """tanh of a float32 as a rational function in float32 (Eigen's and MLAS's): |error|
    < 1e-6, the argument clamped to [-9, 9] (where tanh is 1 to float32 precision)."""
    f = np.float32
    x = min(max(x, f(-9.0)), f(9.0))
    x2 = x * x
    p = x2 * f(-2.76076847742355e-16) + f(2.00018790482477e-13)
    p = x2 * p + f(-8.60467152213735e-11)
    p = x2 * p + f(5.12229709037114e-08)
    p = x2 * p + f(1.48572235717979e-05)
    p = x2 * p + f(6.37261928875436e-04)
    p = x2 * p + f(4.89352455891786e-03)
    q = x2 * f(1.19825839466702e-06) + f(1.18534705686654e-04)
    q = x2 * q + f(2.26843463243900e-03)
    q = x2 * q + f(4.89352518554385e-03)
    return x * p / q


@fast_kernel
def core_forward(
    z: np.ndarray,
    extra: np.ndarray,
    w: np.ndarray,
    hidden: int,
    n_out: int,
    slope: float,
    out: np.ndarray,
) -> None:
    """The core on one window ``z`` (8, n_in) float32 and its ``extra`` decoder inputs
    (n_extra,) float32 with packed weights ``w`` (:func:`pack`), in float32; the output
    (n_out,) is written to ``out`` (:func:`output_buffer`).

    Its working arrays are allocated per call (~0.1 us each): arrays the compiler sees
    allocated here alias nothing, so its loops over the gates are vectorised without
    run-time overlap checks (the lstm's core ran ~1.3x slower on slices of one buffer)."""
    f = np.float32
    slope32 = f(slope)
    half = f(0.5)
    n_t, n_in = z.shape
    n_x = extra.shape[0]
    hh = hidden
    g4 = 4 * hh
    # views into the flat weights (layout: module doc)
    o = 0
    enc_wt = w[o : o + n_in * hh].reshape(n_in, hh)
    o += n_in * hh
    enc_b = w[o : o + hh]
    o += hh
    w_iht = w[o : o + hh * g4].reshape(hh, g4)
    o += hh * g4
    w_hht = w[o : o + hh * g4].reshape(hh, g4)
    o += hh * g4
    bias = w[o : o + g4]
    o += g4
    d0_wt = w[o : o + (hh + n_x) * hh].reshape(hh + n_x, hh)
    o += (hh + n_x) * hh
    d0_b = w[o : o + hh]
    o += hh
    d2_w = w[o : o + n_out * hh].reshape(n_out, hh)
    o += n_out * hh
    d2_b = w[o : o + n_out]
    # working arrays of this call: fresh, so the compiler knows they alias nothing
    gates = np.empty((n_t, g4), np.float32)
    enc = np.empty((n_t, hh), np.float32)
    h = np.empty(hh, np.float32)
    c = np.empty(hh, np.float32)
    d = np.empty(hh, np.float32)
    # the encoder on every step, then the input part of every step's gates in one sweep
    # over the input weights (each row read once, from L1, for all steps)
    for t in range(n_t):
        e = enc[t]
        for j in range(hh):
            e[j] = enc_b[j]
        for k in range(n_in):
            zk = z[t, k]
            for j in range(hh):
                e[j] += enc_wt[k, j] * zk
        for j in range(hh):
            if e[j] < 0.0:
                e[j] *= slope32
        g = gates[t]
        for r in range(g4):
            g[r] = bias[r]
    for k in range(hh):
        wk = w_iht[k]
        for t in range(n_t):
            ek = enc[t, k]
            g = gates[t]
            for r in range(g4):
                g[r] += wk[r] * ek
    for j in range(hh):
        h[j] = 0.0
        c[j] = 0.0
    for t in range(n_t):
        g = gates[t]
        if t > 0:
            for k in range(hh):
                hk = h[k]
                for r in range(g4):
                    g[r] += w_hht[k, r] * hk
        for r in range(3 * hh):  # sigmoid(x) = (1 + tanh(x / 2)) / 2
            g[r] = half + half * _tanh(half * g[r])
        for r in range(3 * hh, g4):
            g[r] = _tanh(g[r])
        for j in range(hh):
            c[j] = g[2 * hh + j] * c[j] + g[j] * g[3 * hh + j]
        for j in range(hh):
            h[j] = g[hh + j] * _tanh(c[j])
    for j in range(hh):
        d[j] = d0_b[j]
    for k in range(hh):
        hk = h[k]
        for j in range(hh):
            d[j] += d0_wt[k, j] * hk
    for k in range(n_x):
        xk = extra[k]
        for j in range(hh):
            d[j] += d0_wt[hh + k, j] * xk
    for j in range(hh):
        if d[j] < 0.0:
            d[j] *= slope32
    for i in range(n_out):
        acc = d2_b[i]
        for k in range(hh):
            acc += d2_w[i, k] * d[k]
        out[i] = acc


def load_weights(path: Path) -> tuple[dict[str, np.ndarray], float]:
    """A core's weights file (``<stem>.core.npz``): its arrays and LeakyReLU slope.

    Raises:
        DataError: the file is missing or unreadable, an array is missing or has another
            shape, or the slope is not in [0, 1).
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            weights = {k: z[k] for k in z.files}
        check_shapes(weights)
        slope = float(weights.pop("slope")) if "slope" in weights else math.nan
    except (OSError, ValueError, KeyError) as e:
        raise DataError(path, f"not a core weights file: {e}") from None
    if not 0.0 <= slope < 1.0:
        raise DataError(path, f"LeakyReLU slope {slope} is not in [0, 1)")
    return weights, slope


class CompiledCore:
    """A core's weights, packed, with the kernel's output buffer: :meth:`run` is one
    compiled call (numba is imported at the first), :meth:`reference` the numpy pass."""

    def __init__(self, weights: Mapping[str, np.ndarray], slope: float) -> None:
        self.weights = dict(weights)
        self.slope = float(slope)
        self.dims = check_shapes(weights)
        self.packed = pack(weights)
        #: the buffer :meth:`run` writes (n_out,) float32
        self.output = output_buffer(self.dims)
        self._no_extra = np.zeros(0, np.float32)

    def __getstate__(self) -> dict:
        """Without the packed weights: a copy packs them again, :func:`aligned` (an
        unpickled array lands wherever the allocator puts it)."""
        return {k: v for k, v in self.__dict__.items() if k != "packed"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.packed = pack(self.weights)

    def run(self, z: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """The core on one window ``z`` (8, n_in) float32 (C-contiguous) and ``extra``
        (n_extra,) float32: its output (n_out,), overwritten by the next call."""
        d = self.dims
        core_forward(
            z,
            self._no_extra if extra is None else extra,
            self.packed,
            d.hidden,
            d.n_out,
            self.slope,
            self.output,
        )
        return self.output

    def reference(self, z: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """:func:`core_forward_numpy` on windows ``z`` (B, 8, n_in), ``extra`` (B, n_extra)."""
        return core_forward_numpy(z, self.weights, self.slope, extra)
