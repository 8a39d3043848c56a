"""Cut the *core* network out of a ``"speed"``-form model: its layers without the in-graph
normalisation, as folded weights for the fused step (export side: needs the ``onnx``
package).

The exported ``model.onnx`` keeps the public interface (raw features ``[B, 8, 6]`` in, raw
next-sample features ``[B, 6]`` out, :mod:`posbench.predictors.lstm.model`). Its normalisation
(speed scale, log, divisions, residual) is ~30 small onnxruntime nodes around a network of 6,
and for one window per call onnxruntime's per-node overhead is most of the inference time.
The core is the same weights with the input affine parts folded in:

- input ``z`` ``[8, 7]`` float32: columns 0-1 the displacements already scaled by the fused
  step (rows 1-7 divided by the window's speed scale s, row 0 by ``res_std``: what
  :meth:`LstmNet.encode_input` does), columns 2-5 the RAW ax, ay, yaw, t, column 6 the RAW
  ``log s``: their standardisation ``(v - mean) / std`` is folded into the encoder's weights
  and bias (exact algebra, float32 rounding);
- Linear -> LeakyReLU -> LSTM (last hidden state) -> Linear -> LeakyReLU -> Linear with the
  decoder's last layer cut to its 2 displacement rows;
- output: the standardised residual (2,); the caller adds ``d_7 + o * res_std`` (the last
  grid step plus the residual, [m], the model's frame).

:func:`write_core` writes ``<stem>.core.npz`` (the arrays of
:data:`~posbench.predictors.lstm.core_kernel.WEIGHT_SHAPES` and ``slope``) beside the model and
returns the ``model.json["core"]`` entry; the runtime (:mod:`posbench.predictors.lstm.core_net`,
:mod:`posbench.predictors.lstm.core_kernel`) checks on load that core and full graph agree (to
1e-5 m) and refuses a core that does not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import helper, numpy_helper

from posbench.predictors.lstm.core_kernel import check_shapes
from posbench.predictors.lstm.features import N_FEATURES, SPEED_EPS_M


class NoCoreGraph(ValueError):
    """The model is not one whose core this module can cut out (another form or layout)."""


def _node_with_input(graph: onnx.GraphProto, op: str, name: str) -> onnx.NodeProto:
    hits = [n for n in graph.node if n.op_type == op and name in n.input]
    if len(hits) != 1:
        raise NoCoreGraph(f"expected one {op} node reading {name!r}, found {len(hits)}")
    return hits[0]


def _attrs(node: onnx.NodeProto) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def core_weights(full: onnx.ModelProto) -> dict[str, np.ndarray]:
    """The core's weights (float32; ``slope`` the LeakyReLU slope) of a ``"speed"``-form
    model exported by :mod:`posbench.predictors.lstm.export`
    (one encoder layer, one LSTM layer; initializer names as torch exports them).

    Raises:
        NoCoreGraph: the model has another form or layout (its fused step then runs the
            full graph).
    """
    g = full.graph
    init = {i.name: numpy_helper.to_array(i).astype(np.float64) for i in g.initializer}
    need = (
        "net.mean",
        "net.std",
        "net.log_s_mean",
        "net.log_s_std",
        "net.res_std",
        "net.encoder.0.bias",
        "net.decoder.0.weight",
        "net.decoder.0.bias",
        "net.decoder.2.weight",
        "net.decoder.2.bias",
    )
    missing = [k for k in need if k not in init]
    if missing:
        raise NoCoreGraph(f"not a speed-form posbench model (no {', '.join(missing)})")
    if any("encoder.2" in k for k in init):
        raise NoCoreGraph("more than one encoder layer")
    # encoder: MatMul(z, W[7, H]) + bias
    add = _node_with_input(g, "Add", "net.encoder.0.bias")
    mm = [n for n in g.node if n.op_type == "MatMul" and set(n.output) & set(add.input)]
    if len(mm) != 1 or mm[0].input[1] not in init:
        raise NoCoreGraph("encoder is not one MatMul + Add")
    w_enc = init[mm[0].input[1]]  # (7, H)
    lstms = [n for n in g.node if n.op_type == "LSTM"]
    if len(lstms) != 1:
        raise NoCoreGraph(f"expected one LSTM node, found {len(lstms)}")
    lstm = lstms[0]
    la = _attrs(lstm)
    if set(la) - {"hidden_size"} or any(k not in init for k in lstm.input[1:4]):
        raise NoCoreGraph(f"LSTM node with attributes {sorted(la)} or computed weights")
    hidden = int(la["hidden_size"])
    if w_enc.shape != (N_FEATURES + 1, hidden):
        raise NoCoreGraph(f"encoder weight {w_enc.shape}, expected {(N_FEATURES + 1, hidden)}")
    slopes = {round(_attrs(n).get("alpha", 0.01), 7) for n in g.node if n.op_type == "LeakyRelu"}
    if len(slopes) != 1:
        raise NoCoreGraph(f"LeakyReLU slopes {sorted(slopes)}")
    slope = float(next(iter(slopes)))
    for k in ("net.decoder.0.weight", "net.decoder.2.weight"):
        gemm = _node_with_input(g, "Gemm", k)
        if _attrs(gemm) != {"alpha": 1.0, "beta": 1.0, "transB": 1}:
            raise NoCoreGraph(f"decoder Gemm {k} with attributes {_attrs(gemm)}")

    # fold (v - mean) / std of the raw columns 2-5 and (log s - m) / sd of column 6
    mean, std = init["net.mean"], init["net.std"]
    w = w_enc.copy()
    b = init["net.encoder.0.bias"].copy()
    for j in range(2, N_FEATURES):
        b -= w_enc[j] * (mean[j] / std[j])
        w[j] = w_enc[j] / std[j]
    ls_m, ls_s = float(init["net.log_s_mean"]), float(init["net.log_s_std"])
    b -= w_enc[N_FEATURES] * (ls_m / ls_s)
    w[N_FEATURES] = w_enc[N_FEATURES] / ls_s

    f32 = np.float32
    weights: dict[str, np.ndarray] = {
        "enc_w": w.T.astype(f32),
        "enc_b": b.astype(f32),
        "lstm_w": init[lstm.input[1]].astype(f32),
        "lstm_r": init[lstm.input[2]].astype(f32),
        "lstm_b": init[lstm.input[3]].astype(f32),
        "dec0_w": init["net.decoder.0.weight"].astype(f32),
        "dec0_b": init["net.decoder.0.bias"].astype(f32),
        "dec2_w": init["net.decoder.2.weight"][:2].astype(f32),
        "dec2_b": init["net.decoder.2.bias"][:2].astype(f32),
        "slope": np.array(slope, f32),
    }
    check_shapes(weights)
    return weights


def write_core(onnx_path: Path) -> dict:
    """Write ``<stem>.core.npz`` beside ``onnx_path`` (a speed-form model); returns the
    ``model.json["core"]`` entry (file name relative to the model, input/output names,
    ``res_std_m`` [m] and ``speed_eps_m`` [m] the runtime needs).

    Raises:
        NoCoreGraph: see :func:`core_model`.
    """
    onnx_path = Path(onnx_path)
    full = onnx.load(str(onnx_path))
    out = onnx_path.with_name(onnx_path.stem + ".core.npz")
    np.savez(out, **core_weights(full))  # type: ignore[arg-type]  # stub: allow_pickle
    res_std = next(
        numpy_helper.to_array(i) for i in full.graph.initializer if i.name == "net.res_std"
    )
    return {
        "file": out.name,
        "res_std_m": [float(v) for v in res_std],
        "speed_eps_m": SPEED_EPS_M,
        "about": "the network's weights without its in-graph normalisation, for the fused "
        "step (predictors.lstm.core_graph, core_kernel); checked against model.onnx on load",
    }
