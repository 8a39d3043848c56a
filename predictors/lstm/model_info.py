"""The lstm's model files: where the bundled model is, its ``model.json`` read and checked
against the features the predictor builds (one :class:`DataError` line naming the file)."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from posbench.predictors.lstm.features import FRAMES
from posbench.predictors.lstm.resample import N_STEPS
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.scenarios.errors import DataError

N_FEATURES = 6
#: text recorded in results for the bundled model
#: (:meth:`~posbench.predictors.base.ModelFileSeams.model_description`)
BUNDLED_TEXT = "bundled (predictors/lstm/bundled/model.onnx)"


def bundled_model() -> Path:
    """Path of the bundled ``model.onnx`` (package data of predictors.lstm)."""
    return Path(str(resources.files("posbench.predictors.lstm") / "bundled" / "model.onnx"))


def load_model_info(onnx_path: Path) -> dict:
    """The ``model.json`` next to an ``model.onnx`` (same stem)."""
    js = onnx_path.with_suffix(".json")
    if not js.is_file():
        raise DataError(js, "model description not found (expected next to the .onnx file)")
    try:
        info = json.loads(js.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(js, f"not valid JSON (line {exc.lineno}): {exc.msg}") from None
    if info.get("format") != "posbench-lstm":
        raise DataError(js, "not a posbench-lstm model description (key 'format')")
    return info


def check_model(onnx_path: Path, info: dict, net: OnnxModel) -> None:
    """model.json and the network must both match the features this predictor builds
    (frame, window of N_STEPS x 6): a one-line :class:`DataError` naming the file if not."""
    js = onnx_path.with_suffix(".json")
    if info.get("frame", "heading") not in FRAMES:
        raise DataError(
            js, f"unknown frame {info.get('frame')!r} (key 'frame'; known: {', '.join(FRAMES)})"
        )
    want = [N_STEPS, N_FEATURES]
    declared = info.get("input_shape")
    if declared is not None and list(declared)[1:] != want:
        raise DataError(
            js,
            f"input_shape {declared} does not match the features [batch, {N_STEPS}, {N_FEATURES}]",
        )
    got = list(net.input_shape)[1:]
    if len(got) != 2 or any(isinstance(g, int) and g != w for g, w in zip(got, want, strict=True)):
        raise DataError(
            onnx_path,
            f"network input shape {net.input_shape} does not match the "
            f"features [batch, {N_STEPS}, {N_FEATURES}]",
        )
