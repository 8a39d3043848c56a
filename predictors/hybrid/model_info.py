"""The ``hybrid``'s model files: ``model.onnx`` and the ``model.json`` beside it, loaded and
checked (format, frame, horizons, prior, gate, the network's inputs and output), and the
constants of its interface. One-line :class:`DataError` naming the file for a bad model.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from posbench.predictors.lstm.features import N_FEATURES
from posbench.predictors.lstm.resample import N_STEPS
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.scenarios.errors import DataError

FORMAT = "posbench-hybrid"
#: horizons [s] of the prior input and the correction output, after the fix
HORIZONS = (0.2, 0.4, 0.6, 0.8)
N_H = len(HORIZONS)
INPUTS = ("features", "prior")
OUTPUT = "correction"
#: GPS conditions model.json records prior parameters for; a condition it lacks falls
#: back to ``native``, then to the kf's defaults
CONDITIONS = ("none", "rtk", "consumer", "native")
FALLBACK_CONDITION = "native"
#: text recorded in results for the bundled model
BUNDLED_TEXT = "bundled (predictors/hybrid/bundled/model.onnx)"


def bundled_model() -> Path:
    """Path of the bundled ``model.onnx`` (package data of predictors.hybrid)."""
    return Path(str(resources.files("posbench.predictors.hybrid") / "bundled" / "model.onnx"))


def load_model_info(onnx_path: Path) -> dict:
    """The ``model.json`` next to ``model.onnx``, checked: format, frame, horizons, prior.
    Raises a one-line :class:`DataError` naming the file."""
    js = onnx_path.with_suffix(".json")
    if not js.is_file():
        raise DataError(js, "model description not found (expected next to the .onnx file)")
    try:
        info = json.loads(js.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(js, f"not valid JSON (line {exc.lineno}): {exc.msg}") from None
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise DataError(js, f"not a {FORMAT} model description (key 'format')")
    if info.get("frame", "heading") != "heading":
        raise DataError(
            js,
            f"frame {info.get('frame')!r} is not supported (key 'frame'; "
            "the hybrid works in the heading frame)",
        )
    hz = info.get("horizons_s", list(HORIZONS))
    if not (
        isinstance(hz, list)
        and len(hz) == N_H
        and all(
            isinstance(h, int | float) and abs(h - w) < 1e-9
            for h, w in zip(hz, HORIZONS, strict=True)
        )
    ):
        raise DataError(js, f"horizons_s {hz!r} must be {list(HORIZONS)}")
    prior = info.get("prior")
    if not (
        isinstance(prior, dict)
        and prior.get("predictor") == "kf"
        and isinstance(prior.get("params", {}), dict)
        and all(isinstance(v, dict) for v in prior.get("params", {}).values())
    ):
        raise DataError(
            js,
            'key \'prior\' must be {"predictor": "kf", "params": {CONDITION: {kf option: value}}}',
        )
    check_gate(js, info.get("gate"))
    return info


def check_gate(js: Path, gate: Any) -> None:
    """model.json's optional ``gate``: ``shrink`` (4 factors in [0, 1]) and the envelope
    (``feature_min``/``feature_max`` of 6, ``prior_min``/``prior_max`` of 4 x 2), each
    optional. Raises a one-line :class:`DataError` naming the key."""
    if gate is None:
        return
    if not isinstance(gate, dict):
        raise DataError(js, "key 'gate' must be an object")
    shapes = {
        "shrink": (N_H,),
        "feature_min": (N_FEATURES,),
        "feature_max": (N_FEATURES,),
        "prior_min": (N_H, 2),
        "prior_max": (N_H, 2),
    }
    for key, shape in shapes.items():
        if key not in gate:
            continue
        try:
            a = np.asarray(gate[key], dtype=float)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != shape or (key == "shrink" and not ((a >= 0) & (a <= 1)).all()):
            extra = ", each in [0, 1]" if key == "shrink" else ""
            raise DataError(js, f"gate.{key} must be numbers of shape {list(shape)}{extra}")
    if ("feature_min" in gate) != ("prior_max" in gate) or any(
        (k in gate) != ("feature_min" in gate) for k in ("feature_max", "prior_min")
    ):
        raise DataError(
            js, "gate: give all of feature_min, feature_max, prior_min, prior_max or none"
        )


def prior_params(info: dict, condition: str | None) -> tuple[str, dict[str, Any]]:
    """(condition used, kf parameters) for a GPS ``condition``: model.json's params for it,
    else for ``native``, else the kf's defaults (condition ``"defaults"``)."""
    params = info["prior"].get("params", {})
    for c in (condition, FALLBACK_CONDITION):
        if c is not None and c in params:
            return c, dict(params[c])
    return "defaults", {}


def check_net(onnx_path: Path, net: OnnxModel) -> None:
    """The graph must take ``features`` [b, 8, 6] and ``prior`` [b, 4, 2] (in that order)
    and answer ``correction`` [b, 4, 4]."""
    if net.input_names != list(INPUTS):
        raise DataError(onnx_path, f"network inputs {net.input_names} are not {list(INPUTS)}")
    want = ([N_STEPS, N_FEATURES], [N_H, 2])
    for name, shape, w in zip(INPUTS, net.input_shapes, want, strict=True):
        got = shape[1:]
        if len(got) != 2 or any(isinstance(g, int) and g != x for g, x in zip(got, w, strict=True)):
            raise DataError(
                onnx_path,
                f"network input {name} has shape {shape}, expected [batch, {w[0]}, {w[1]}]",
            )
    out = next(o for o in net.session.get_outputs() if o.name == net.output_name)
    got = list(out.shape)[1:]
    if len(got) != 2 or any(
        isinstance(g, int) and g != x for g, x in zip(got, (N_H, 4), strict=True)
    ):
        raise DataError(
            onnx_path,
            f"network output {OUTPUT} has shape {list(out.shape)}, expected [batch, {N_H}, 4]",
        )
