"""The hybrid's network as a compiled core: its ``model.onnx`` with every normalisation
folded into the weights, run in one call by
:func:`posbench.predictors.lstm.core_kernel.core_forward` instead of onnxruntime.

The full graph (:class:`posbench.predictors.hybrid.model.HybridNet`) standardises the
features, divides the prior by ``prior_std``, and turns the decoder's 16 outputs into
(dx, dy) x ``res_std`` [m] and log var + ``log_res_var`` per horizon. All of these are
affine, so they fold exactly (float32 rounding) into the encoder's first layer, the
decoder's prior columns and its last layer: the core takes the RAW features (8, 6) and the
RAW prior (4, 2) flattened to 8 [m], and answers the graph's RAW output (4, 4) flattened.

Export side (:func:`write_core`, needs the ``onnx`` package): ``<stem>.core.npz`` beside the
model and the ``model.json["core"]`` entry. Run time (:class:`HybridCore`): the weights are
checked against the full graph on load (:data:`CORE_TOL`); a core that does not reproduce
it is refused with a one-line :class:`~posbench.scenarios.errors.DataError`, and a model
without a core runs its full graph through onnxruntime (slower, the same answers).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from posbench.predictors.hybrid.model_info import N_H
from posbench.predictors.lstm import core_kernel
from posbench.predictors.lstm.features import N_FEATURES
from posbench.predictors.lstm.resample import N_STEPS
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.scenarios.errors import DataError

#: largest |difference| allowed between core and full graph on the check inputs, in the
#: output's units (corrections [m], log variances [log m^2]); float32 rounding is ~1e-6
CORE_TOL = 1e-4
#: inputs the check runs
CHECK_INPUTS = 32
#: the statistics and layers :func:`fold` reads by their torch names
_STATS = (
    "feature_mean",
    "feature_std",
    "prior_std",
    "res_std",
    "log_res_var",
    "encoder.0.bias",
    "decoder.0.weight",
    "decoder.0.bias",
    "decoder.2.weight",
    "decoder.2.bias",
)


def fold(init: dict[str, np.ndarray], enc_wt: np.ndarray, lstm: tuple, slope: float) -> dict:
    """The core's weights (float32) from the full graph's arrays: ``init`` by their torch
    names (feature_mean, feature_std, prior_std, res_std, log_res_var, encoder.0.bias,
    decoder.0/2.weight/bias), ``enc_wt`` the encoder's MatMul weight (6, H), ``lstm`` the
    LSTM node's (W, R, B)."""
    f64 = np.float64
    mean = np.asarray(init["feature_mean"], f64)
    std = np.asarray(init["feature_std"], f64)
    w = np.asarray(enc_wt, f64) / std[:, None]  # (6, H): z = (f - mean) / std folded in
    b = np.asarray(init["encoder.0.bias"], f64) - (mean / std) @ np.asarray(enc_wt, f64)
    w0 = np.asarray(init["decoder.0.weight"], f64).copy()  # (H, H + 8)
    hidden = w0.shape[0]
    w0[:, hidden:] /= np.asarray(init["prior_std"], f64).reshape(-1)
    w2 = np.asarray(init["decoder.2.weight"], f64).copy()  # (16, H): rows k * 4 + c
    b2 = np.asarray(init["decoder.2.bias"], f64).copy()
    res = np.asarray(init["res_std"], f64)
    logv = np.asarray(init["log_res_var"], f64)
    for k in range(N_H):
        for c in range(2):
            w2[4 * k + c] *= res[k, c]
            b2[4 * k + c] *= res[k, c]
            b2[4 * k + 2 + c] += logv[k, c]
    f32 = np.float32
    weights = {
        "enc_w": w.T.astype(f32),
        "enc_b": b.astype(f32),
        "lstm_w": np.asarray(lstm[0], f32),
        "lstm_r": np.asarray(lstm[1], f32),
        "lstm_b": np.asarray(lstm[2], f32),
        "dec0_w": w0.astype(f32),
        "dec0_b": np.asarray(init["decoder.0.bias"], f32),
        "dec2_w": w2.astype(f32),
        "dec2_b": b2.astype(f32),
        "slope": np.array(slope, f32),
    }
    core_kernel.check_shapes(weights)
    return weights


def write_core(onnx_path: Path, weights: dict | None = None) -> dict[str, Any]:
    """Write ``<stem>.core.npz`` beside a hybrid ``model.onnx``; returns the
    ``model.json["core"]`` entry. ``weights``: the core's weights where the caller has them
    (the export folds them from the torch net: an ONNX export may merge initializers of
    equal values, e.g. an untrained net's unit scales, under one name); else they are
    folded from the graph's named initializers (imports ``onnx``; ValueError where the
    graph is not a :class:`~posbench.predictors.hybrid.model.HybridNet` export of one
    encoder layer and one LSTM layer, or lacks a named statistic)."""
    onnx_path = Path(onnx_path)
    if weights is None:
        weights = _weights_from_graph(onnx_path)
    core_kernel.check_shapes(weights)
    out = onnx_path.with_name(onnx_path.stem + ".core.npz")
    np.savez(out, **weights)
    return {
        "file": out.name,
        "about": "the network's weights with its normalisation folded in, run in one "
        "compiled call (predictors.hybrid.core); checked against model.onnx on load",
    }


def _weights_from_graph(onnx_path: Path) -> dict:
    """The core's weights folded from a hybrid ``model.onnx``'s initializers."""
    import onnx
    from onnx import helper, numpy_helper

    g = onnx.load(str(onnx_path)).graph
    init = {i.name: numpy_helper.to_array(i) for i in g.initializer}
    missing = [k for k in _STATS if k not in init]
    if missing:
        raise ValueError(f"no initializer {', '.join(missing)} in {onnx_path.name}")
    matmuls = [n for n in g.node if n.op_type == "MatMul" and n.input[1] in init]
    lstms = [n for n in g.node if n.op_type == "LSTM"]
    if len(matmuls) != 1 or len(lstms) != 1 or any("encoder.2" in k for k in init):
        raise ValueError("not a hybrid network of one encoder layer and one LSTM layer")
    slopes = {
        round(float(helper.get_attribute_value(a)), 7)
        for n in g.node
        if n.op_type == "LeakyRelu"
        for a in n.attribute
        if a.name == "alpha"
    }
    if len(slopes) != 1:
        raise ValueError(f"LeakyReLU slopes {sorted(slopes)}")
    lstm = tuple(init[k] for k in lstms[0].input[1:4])
    return fold(init, init[matmuls[0].input[1]], lstm, next(iter(slopes)))


def check_inputs(info: dict, n: int = CHECK_INPUTS, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Deterministic raw inputs around the model's statistics (float32): features (n, 8, 6)
    ~ N(mean, std), priors (n, 4, 2) ~ N(0, (3 prior_std)^2)."""
    rng = np.random.default_rng(seed)
    mean = np.asarray(info.get("feature_mean", np.zeros(N_FEATURES)), float)
    std = np.asarray(info.get("feature_std", np.ones(N_FEATURES)), float)
    ps = np.asarray(info.get("prior_std", 1.0), float)
    ps = np.broadcast_to(ps[:, None] if ps.shape == (N_H,) else ps, (N_H, 2))
    f = mean + std * rng.standard_normal((n, N_STEPS, N_FEATURES))
    p = 3.0 * ps * rng.standard_normal((n, N_H, 2))
    return f.astype(np.float32), p.astype(np.float32)


class HybridCore:
    """A hybrid model's core (``model.json["core"]``), checked against its full graph.

    Args:
        onnx_path: the full ``model.onnx``; the core's file name in ``entry`` is relative to it.
        entry: ``model.json["core"]``.
        info: model.json (its statistics shape the check inputs).
        full: the full graph's session.
    Raises:
        DataError: the core file is missing or unreadable, has other sizes, or does not
            reproduce the full graph.
    """

    def __init__(self, onnx_path: Path, entry: dict, info: dict, full: OnnxModel) -> None:
        self.path = Path(onnx_path).with_name(str(entry.get("file", "")))
        weights, slope = core_kernel.load_weights(self.path)
        self.core = core_kernel.CompiledCore(weights, slope)
        d = self.core.dims
        if (d.n_in, d.n_extra, d.n_out) != (N_FEATURES, 2 * N_H, 4 * N_H):
            raise DataError(
                self.path,
                f"core of {d.n_in} inputs, {d.n_extra} extra and {d.n_out} outputs, "
                f"expected {N_FEATURES}, {2 * N_H} and {4 * N_H}",
            )
        worst = self.difference(info, full)
        if not worst <= CORE_TOL:
            raise DataError(
                self.path,
                f"does not reproduce {Path(onnx_path).name}: outputs differ by up to "
                f"{worst:.3g} (allowed {CORE_TOL:g}); export the model again",
            )

    def run(self, features: np.ndarray, prior: np.ndarray) -> np.ndarray:
        """The core on raw ``features`` (8, 6) float32 and ``prior`` (8,) float32 [m]: the
        graph's output (4, 4) (a view overwritten by the next call)."""
        return self.core.run(features, prior).reshape(N_H, 4)

    def difference(self, info: dict, full: OnnxModel) -> float:
        """Largest |output difference| between the core's weights (numpy reference) and
        ``full`` on :func:`check_inputs`; NaN if either answers NaN."""
        f, p = check_inputs(info)
        got = self.core.reference(f, p.reshape(len(p), -1)).astype(np.float64)
        names, out = full.input_names, [full.output_name]
        want = np.stack(
            [
                full.session.run(out, {names[0]: fi[None], names[1]: pi[None]})[0][0]
                for fi, pi in zip(f, p, strict=True)
            ]
        )
        return float(np.max(np.abs(got - want.reshape(len(f), -1))))
