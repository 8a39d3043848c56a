"""Export :class:`~posbench.predictors.hybrid.model.HybridNet` to ONNX, check it, write model.json.

The graph (torch's TorchScript exporter, ``dynamo=False``, opset 17, like
:mod:`posbench.predictors.lstm.export`; its dynamo exporter needs ``onnxscript``, not installed in
this project) takes two float32 inputs with a dynamic batch dimension ``batch``:
``features`` [batch, 8, 6] and ``prior`` [batch, 4, 2] [m], and answers ``correction``
[batch, 4, 4] (dx, dy [m, heading frame], log var along / across [log m^2] per horizon).
:func:`parity` compares onnxruntime with torch on random inputs; :func:`save_model`
refuses to write a model whose ONNX graph differs from torch by more than 1e-5.

``python -m predictors.hybrid.export OUT_DIR`` writes an *untrained* model (zero last
layer: correction 0, i.e. exactly the kf prior) with normalisation statistics from a few
synthetic drives and the kf's tuned parameters as its prior: the placeholder bundled
until a trained model replaces it. Imports torch: training only.
"""

from __future__ import annotations

import json
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort
import torch

from posbench.predictors.hybrid.core import fold, write_core
from posbench.predictors.hybrid.data import HybridWindows, hybrid_windows
from posbench.predictors.hybrid.model import HybridNet
from posbench.predictors.hybrid.model_info import (
    CONDITIONS,
    FORMAT,
    HORIZONS,
    INPUTS,
    N_H,
    OUTPUT,
)
from posbench.predictors.lstm.features import FEATURES, N_FEATURES
from posbench.predictors.lstm.resample import DT, MIN_SPAN_S, N_STEPS
from posbench.predictors.lstm.runtime import session_options

OPSET = 17
BATCH_DIM = "batch"
PARITY_TOL = 1e-5


def export_onnx(net: HybridNet, path: Path) -> None:
    """Write ``net`` (eval mode) as ONNX to ``path``: inputs ``features``, ``prior``, output
    ``correction``, dynamic batch (example batch 2, so the batch is not pinned)."""
    net = net.eval()
    example = (torch.zeros(2, N_STEPS, N_FEATURES), torch.zeros(2, N_H, 2))
    path.parent.mkdir(parents=True, exist_ok=True)
    with torch.no_grad(), warnings.catch_warnings():
        # the legacy exporter's deprecation and tracer notes; the batch-size note on LSTMs
        # does not apply (no h0/c0 inputs; parity is checked at batch 1 and 256)
        warnings.simplefilter("ignore")
        torch.onnx.export(
            net,
            example,
            str(path),
            dynamo=False,
            opset_version=OPSET,
            input_names=list(INPUTS),
            output_names=[OUTPUT],
            dynamic_axes={
                INPUTS[0]: {0: BATCH_DIM},
                INPUTS[1]: {0: BATCH_DIM},
                OUTPUT: {0: BATCH_DIM},
            },
        )


def random_inputs(net: HybridNet, n: int = 256, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Random raw inputs around the net's statistics: features ~ N(mean, std), prior ~
    N(0, (3 prior_std)^2); float32 (n, 8, 6) and (n, 4, 2)."""
    rng = np.random.default_rng(seed)
    mean = net.feature_mean.numpy()
    std = net.feature_std.numpy()
    f = mean + std * rng.standard_normal((n, N_STEPS, N_FEATURES))
    p = 3.0 * net.prior_std.numpy() * rng.standard_normal((n, N_H, 2))
    return f.astype(np.float32), p.astype(np.float32)


def parity(net: HybridNet, path: Path, n: int = 256, seed: int = 0) -> float:
    """Largest |onnxruntime - torch| over ``n`` random input pairs (raw output units)."""
    f, p = random_inputs(net, n, seed)
    sess = ort.InferenceSession(
        str(path), sess_options=session_options(), providers=["CPUExecutionProvider"]
    )
    got = sess.run([OUTPUT], {INPUTS[0]: f, INPUTS[1]: p})[0]
    with torch.no_grad():
        want = net.eval()(torch.from_numpy(f), torch.from_numpy(p)).numpy()
    return float(np.max(np.abs(got.astype(np.float64) - want)))


def fit_stats(hw: HybridWindows) -> dict[str, np.ndarray]:
    """Normalisation statistics of training rows: feature mean / std (6,) over all steps,
    prior RMS (4, 2) and target (residual) RMS (4, 2) [m], floored at 1e-3."""
    X = hw.X.reshape(-1, N_FEATURES)
    floor = 1e-3
    return {
        "feature_mean": X.mean(axis=0),
        "feature_std": np.maximum(X.std(axis=0), floor),
        "prior_std": np.maximum(np.sqrt((hw.prior**2).mean(axis=0)), floor),
        "res_std": np.maximum(np.sqrt((hw.target**2).mean(axis=0)), floor),
    }


def architecture(net: HybridNet) -> dict[str, Any]:
    """The network's shape, for model.json."""
    hidden = net.lstm.hidden_size
    return {
        "encoder": f"{len(net.encoder) // 2} x (Linear -> LeakyReLU(0.1)), width {hidden}",
        "lstm": {"hidden": hidden, "layers": net.lstm.num_layers},
        "decoder": f"Linear({hidden}+{2 * N_H},{hidden}) -> LeakyReLU(0.1) -> "
        f"Linear({hidden},{4 * N_H})",
        "parameters": int(sum(p.numel() for p in net.parameters())),
    }


def model_info(net: HybridNet, prior_params: dict[str, dict], **extra: Any) -> dict[str, Any]:
    """model.json's content (format ``posbench-hybrid``) for ``net`` with the kf prior's
    parameters per GPS condition; ``extra`` keys (data, training, command, ...) are added."""
    info: dict[str, Any] = {
        "format": FORMAT,
        "version": 1,
        "frame": "heading",
        "features": list(FEATURES),
        "n_steps": N_STEPS,
        "dt_s": DT,
        "min_span_s": MIN_SPAN_S,
        "horizons_s": list(HORIZONS),
        "inputs": list(INPUTS),
        "output": OUTPUT,
        "input_shapes": {
            INPUTS[0]: [BATCH_DIM, N_STEPS, N_FEATURES],
            INPUTS[1]: [BATCH_DIM, N_H, 2],
        },
        "output_shape": [BATCH_DIM, N_H, 4],
        "output_units": "per horizon: dx, dy [m, heading frame] added to the kf's answer; "
        "log var along, across the heading [log m^2]",
        "normalisation": "in-graph (raw inputs in, raw correction out)",
        "feature_mean": net.feature_mean.tolist(),
        "feature_std": net.feature_std.tolist(),
        "prior_std": net.prior_std.tolist(),
        "res_std": net.res_std.tolist(),
        "prior": {"predictor": "kf", "params": {c: dict(p) for c, p in prior_params.items()}},
        "architecture": architecture(net),
    }
    info.update(extra)
    return info


def save_model(
    net: HybridNet, out_dir: Path, prior_params: dict[str, dict], **extra: Any
) -> dict[str, Any]:
    """Write ``out_dir/model.onnx``, its compiled core's weights (``model.core.npz``,
    :func:`posbench.predictors.hybrid.core.write_core`) and ``model.json``; raises
    RuntimeError if the ONNX graph differs from torch by more than :data:`PARITY_TOL`.
    Returns model.json's content."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp_onnx = Path(tmp) / "model.onnx"
        export_onnx(net, tmp_onnx)
        err = parity(net, tmp_onnx)
        if not err <= PARITY_TOL:
            raise RuntimeError(f"ONNX export differs from torch by {err:.3g} > {PARITY_TOL}")
        (out_dir / "model.onnx").write_bytes(tmp_onnx.read_bytes())
    core = write_core(out_dir / "model.onnx", core_weights(net))
    info = model_info(net, prior_params, parity_max_abs=err, **extra, core=core)
    (out_dir / "model.json").write_text(json.dumps(info, indent=1) + "\n")
    return info


def core_weights(net: HybridNet) -> dict[str, np.ndarray]:
    """The compiled core's weights (:func:`posbench.predictors.hybrid.core.fold`) from the
    torch net: its LSTM's gates reordered from torch's (i, f, g, o) to ONNX's (i, o, f, c)
    and its two biases side by side, as the ONNX LSTM node holds them."""
    if len(net.encoder) != 2 or net.lstm.num_layers != 1:
        raise ValueError("the compiled core takes one encoder layer and one LSTM layer")
    sd = {k: v.detach().cpu().numpy().astype(np.float64) for k, v in net.state_dict().items()}
    h = net.lstm.hidden_size
    order = np.concatenate([np.arange(k * h, (k + 1) * h) for k in (0, 3, 1, 2)])
    lstm = (
        sd["lstm.weight_ih_l0"][order][None],
        sd["lstm.weight_hh_l0"][order][None],
        np.concatenate([sd["lstm.bias_ih_l0"][order], sd["lstm.bias_hh_l0"][order]])[None],
    )
    act = net.encoder[1]
    if not isinstance(act, torch.nn.LeakyReLU):
        raise ValueError(f"the encoder's activation is {type(act).__name__}, not LeakyReLU")
    slope = float(act.negative_slope)
    return fold(sd, sd["encoder.0.weight"].T, lstm, slope)


def prior_kf_params() -> dict[str, dict]:
    """The prior's parameters per GPS condition: the ``kf``'s package tuning for each
    (``predictors/tuned.json``, through :func:`posbench.predictors.registry.tuned_params`;
    {} where it has none). The prior is the ``kf`` itself
    (:class:`~posbench.predictors.kalman.kf.KalmanBank`) as ``bench run -p kf`` builds it,
    so that the hybrid is held against the filter under it."""
    from posbench.predictors.registry import tuned_params

    return {c: tuned_params("kf", c) for c in CONDITIONS}


def write_untrained(
    out_dir: Path,
    seeds: tuple[int, ...] = (0, 1, 2, 3),
    stats_condition: str = "rtk",
    hidden: int = 48,
) -> dict[str, Any]:
    """An untrained (zero last layer) model: statistics from synthetic drives ``seeds`` (their
    fixes degraded by the ``stats_condition`` profile, the kf prior with that condition's
    tuned parameters), the tuned kf parameters of every condition as prior."""
    from posbench.scenarios.degrade import degrade_gps
    from posbench.scenarios.synthetic import generate_drive

    prior = prior_kf_params()
    rows = []
    names = []
    for s in seeds:
        d = generate_drive(seed=s)
        assert d.truth is not None  # a synthetic drive always has its truth
        gps = degrade_gps(d.truth, stats_condition, seed=s)
        rows.append(hybrid_windows(d, gps, prior[stats_condition]))
        names.append(d.name)
    hw = HybridWindows.concat(rows)
    torch.manual_seed(0)
    net = HybridNet(hidden=hidden)
    st = fit_stats(hw)
    net.set_stats(st["feature_mean"], st["feature_std"], st["prior_std"], st["res_std"])
    cmd = f"python -m predictors.hybrid.export {out_dir}"
    return save_model(
        net,
        out_dir,
        prior,
        command=cmd,
        trained=False,
        note="UNTRAINED placeholder: the last layer is zero, so the correction "
        "is 0 and the hybrid answers exactly as its kf prior; the variance "
        "added is res_std^2",
        data={
            "stats_drives": names,
            "stats_gps_profile": stats_condition,
            "stats_windows": len(hw),
            "train_drives": [],
        },
    )


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print(
            "usage: python -m predictors.hybrid.export OUT_DIR  (writes an untrained model)",
            file=sys.stderr,
        )
        return 2
    info = write_untrained(Path(args[0]))
    print(
        f"wrote {args[0]}/model.onnx, model.json ({info['data']['stats_windows']} windows "
        f"for the statistics; parity {info['parity_max_abs']:.2g})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
