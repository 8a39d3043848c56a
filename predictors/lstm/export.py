"""Export the trained network to ONNX and keep the faster of torch's two exporters.

- legacy TorchScript exporter (``dynamo=False``, opset 17): always available;
- dynamo exporter (``dynamo=True``): needs the ``onnxscript`` package; tried only if it
  is importable (it is not installed in this project's environment), example batch 2
  (a batch-1 example would pin the batch dimension).

Both export with a dynamic batch dimension, input ``features`` [batch, 8, 6] float32,
output ``future`` [batch, 6] (the last step: the sample 200 ms ahead, raw units).
Each candidate is timed in onnxruntime (1 intra-op thread, ORT_ENABLE_ALL, batch 1,
median of ``n_calls`` calls) and the fastest is kept. Imports torch: training only.
"""

from __future__ import annotations

import importlib.util
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from posbench.predictors.lstm.features import N_FEATURES
from posbench.predictors.lstm.model import FuturePoint, LstmNet
from posbench.predictors.lstm.resample import N_STEPS
from posbench.predictors.lstm.runtime import OnnxModel

INPUT_NAME = "features"
OUTPUT_NAME = "future"
OPSET = 17


def _export(module: torch.nn.Module, path: Path, dynamo: bool) -> None:
    example = torch.zeros(2, N_STEPS, N_FEATURES)
    if dynamo:
        batch = torch.export.Dim("batch", min=1, max=65536)
        torch.onnx.export(
            module,
            (example,),
            str(path),
            dynamo=True,
            input_names=[INPUT_NAME],
            output_names=[OUTPUT_NAME],
            dynamic_shapes={"x": {0: batch}},
        )
    else:
        torch.onnx.export(
            module,
            (example,),
            str(path),
            dynamo=False,
            opset_version=OPSET,
            input_names=[INPUT_NAME],
            output_names=[OUTPUT_NAME],
            dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}},
        )


def time_onnx(path: Path, n_calls: int = 2000, seed: int = 0) -> dict[str, float]:
    """Median / p10 / p90 single-window inference time [us] of an ONNX file in onnxruntime."""
    model = OnnxModel(path)
    x = np.random.default_rng(seed).standard_normal((N_STEPS, N_FEATURES)).astype(np.float32)
    for _ in range(50):
        model.run(x)
    ts = np.empty(n_calls)
    for i in range(n_calls):
        t0 = time.perf_counter()
        model.run(x)
        ts[i] = time.perf_counter() - t0
    return {
        "p50_us": float(np.median(ts) * 1e6),
        "p10_us": float(np.percentile(ts, 10) * 1e6),
        "p90_us": float(np.percentile(ts, 90) * 1e6),
    }


def export_best(net: LstmNet, out_path: Path, n_calls: int = 2000) -> dict:
    """Export ``net`` with each available exporter, time each, copy the fastest to ``out_path``.

    Returns a report: per exporter its timing or the reason it was skipped, and the choice.
    """
    head = FuturePoint(net).eval()
    report: dict = {
        "candidates": {},
        "onnxscript_installed": importlib.util.find_spec("onnxscript") is not None,
    }
    with tempfile.TemporaryDirectory() as tmp:
        best: tuple[float, Path, str] | None = None
        for name, dynamo in (("legacy_opset17", False), ("dynamo", True)):
            if dynamo and not report["onnxscript_installed"]:
                report["candidates"][name] = {"skipped": "onnxscript is not installed"}
                continue
            p = Path(tmp) / f"{name}.onnx"
            try:
                with torch.no_grad():
                    _export(head, p, dynamo)
            except Exception as exc:  # an exporter failing must not stop training
                report["candidates"][name] = {"failed": f"{type(exc).__name__}: {exc}"[:300]}
                continue
            timing = time_onnx(p, n_calls)
            report["candidates"][name] = timing
            if best is None or timing["p50_us"] < best[0]:
                best = (timing["p50_us"], p, name)
        if best is None:
            raise RuntimeError(f"ONNX export failed: {report['candidates']}")
        out_path.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(best[1], out_path)
        report["chosen"] = best[2]
    return report
