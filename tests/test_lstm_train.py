"""Training pipeline: ONNX parity torch vs onnxruntime, a tiny end-to-end retrain."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from predictors.lstm.export import export_best  # noqa: E402
from predictors.lstm.model import FuturePoint, LstmNet  # noqa: E402
from predictors.lstm.predictor import LstmPredictor  # noqa: E402
from predictors.lstm.runtime import OnnxModel  # noqa: E402
from predictors.lstm.train import run_training, sample_weights, split_by_route  # noqa: E402
from scenarios.synthetic import generate_drive  # noqa: E402


def test_onnx_matches_torch(tmp_path) -> None:
    torch.manual_seed(0)
    net = LstmNet(hidden=32, lstm_layers=2).eval()
    net.set_stats(torch.tensor([0.1, 0.0, 0.2, -0.1, 0.0, 0.7]),
                  torch.tensor([1.5, 0.3, 0.8, 0.9, 0.1, 0.46]))
    report = export_best(net, tmp_path / "m.onnx", n_calls=20)
    assert report["chosen"] == "legacy_opset17"
    x = np.random.default_rng(0).normal(0, 1, (5, 8, 6)).astype(np.float32)
    with torch.no_grad():
        ref = FuturePoint(net)(torch.from_numpy(x)).numpy()
        full = net(torch.from_numpy(x)).numpy()
    m = OnnxModel(tmp_path / "m.onnx")
    np.testing.assert_allclose(m.run_batch(x), ref, atol=1e-5)  # dynamic batch 5
    np.testing.assert_allclose(m.run(x[3]), ref[3], atol=1e-5)  # batch 1
    np.testing.assert_allclose(full[:, -1], ref, atol=1e-6)  # head == last many-to-many step


def test_split_is_by_route_and_weights_favour_turns() -> None:
    drives = [generate_drive(seed=i, route="straight", duration_s=5.0) for i in range(6)]
    train, val = split_by_route(drives)
    assert {d.name for d in train}.isdisjoint({d.name for d in val})
    assert len(val) == 1 and len(train) == 5
    w = sample_weights(np.array(["straight"] * 8 + ["turn"] * 2))
    assert w[-1] == pytest.approx(4.0) and w[0] == 1.0


@pytest.mark.slow
def test_tiny_retrain_end_to_end(tmp_path) -> None:
    drives = [generate_drive(seed=100 + i, route=r, duration_s=40.0)
              for i, r in enumerate(("mixed", "turns", "straight"))]
    calls = []
    info = run_training([], tmp_path, epochs=2, seed=0, drives=drives, hidden=16,
                        gps_seeds=1, timing_calls=20, command="test",
                        progress=lambda *a: calls.append(a))
    assert [c[0] for c in calls] == [1, 2] and all(math.isfinite(c[2]) for c in calls)
    js = json.loads((tmp_path / "model.json").read_text())
    assert js["command"] == "test" and js["frame"] == "heading"
    assert js["data"]["val_drives"] and js["validation"]["all"]["lstm"]["n"] > 0
    assert len(js["feature_mean"]) == 6 and info["training"]["epochs_run"] == 2
    p = LstmPredictor(str(tmp_path / "model.onnx"))
    d = drives[0]
    for i in range(40):
        p.observe_gps(d.gps.t[i], d.gps.x[i], d.gps.y[i])
    assert p.steps > 0
    assert np.isfinite(p.position_at(d.gps.t[39] + 0.1)).all()
