"""Training pipeline: ONNX parity torch vs onnxruntime, a tiny end-to-end retrain."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from posbench.predictors.lstm.export import export_best  # noqa: E402
from posbench.predictors.lstm.model import FuturePoint, LstmNet  # noqa: E402
from posbench.predictors.lstm.predictor import LstmPredictor  # noqa: E402
from posbench.predictors.lstm.runtime import OnnxModel  # noqa: E402
from posbench.predictors.lstm.train import run_training, sample_weights  # noqa: E402
from posbench.predictors.lstm.training_data import split_by_route  # noqa: E402
from posbench.scenarios.synthetic import generate_drive  # noqa: E402


def test_onnx_matches_torch(tmp_path) -> None:
    torch.manual_seed(0)
    net = LstmNet(hidden=32, lstm_layers=2).eval()
    net.set_stats(
        torch.tensor([0.1, 0.0, 0.2, -0.1, 0.0, 0.7]), torch.tensor([1.5, 0.3, 0.8, 0.9, 0.1, 0.46])
    )
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
    drives = [
        generate_drive(seed=100 + i, route=r, duration_s=40.0)
        for i, r in enumerate(("mixed", "turns", "straight"))
    ]
    calls = []
    info = run_training(
        [],
        tmp_path,
        epochs=2,
        seed=0,
        drives=drives,
        hidden=16,
        gps_seeds=1,
        timing_calls=20,
        command="test",
        progress=lambda *a: calls.append(a),
    )
    assert [c[0] for c in calls] == [1, 2] and all(math.isfinite(c[2]) for c in calls)
    js = json.loads((tmp_path / "model.json").read_text())
    assert js["command"] == "test" and js["frame"] == "heading"
    assert js["data"]["val_drives"] and js["validation"]["all"]["lstm"]["n"] > 0
    assert len(js["feature_mean"]) == 6 and info["training"]["epochs_run"] == 2
    card = (tmp_path / "MODEL_CARD.md").read_text()
    assert card.startswith("# Model card: `lstm`") and "never KITTI" in card
    assert f"{js['data']['train_windows']} windows" in card
    assert "`model.core.npz` beside the model" in card
    p = LstmPredictor(str(tmp_path / "model.onnx"))
    assert js["core"]["file"] == "model.core.npz" and p.core is not None  # the fused step's
    d = drives[0]
    for i in range(40):
        p.observe_gps(d.gps.t[i], d.gps.x[i], d.gps.y[i])
    assert p.steps > 0
    assert np.isfinite(p.position_at(d.gps.t[39] + 0.1)).all()


def test_speed_form_onnx_matches_torch_and_is_a_residual(tmp_path) -> None:
    """The speed-invariant form exports with the runtime's interface (raw features in, raw
    next-sample features out), matches torch in onnxruntime, and with a zero last layer
    predicts exactly the previous grid step (its skip)."""
    torch.manual_seed(1)
    net = LstmNet(hidden=16, form="speed").eval()
    net.set_stats(
        torch.tensor([1.0, 0.0, 0.2, -0.1, 0.0, 0.7]), torch.tensor([1.5, 0.3, 0.8, 0.9, 0.1, 0.46])
    )
    net.set_speed_stats(0.5, 0.8, torch.tensor([0.04, 0.03]))
    rng = np.random.default_rng(2)
    x = rng.normal(0, 1, (6, 8, 6)).astype(np.float32)
    x[:, :, 0] += 3.0  # ~15 m/s along the heading
    x[:, 0, :2] = 0.0
    export_best(net, tmp_path / "m.onnx", n_calls=20)
    with torch.no_grad():
        ref = FuturePoint(net)(torch.from_numpy(x)).numpy()
        full = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(OnnxModel(tmp_path / "m.onnx").run_batch(x), ref, atol=1e-5)
    np.testing.assert_allclose(full[:, -1], ref, atol=1e-5)
    with torch.no_grad():
        net.decoder[-1].weight.zero_()
        net.decoder[-1].bias.zero_()
        out = FuturePoint(net)(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(out[:, :2], x[:, -1, :2], atol=1e-6)


def test_speed_form_input_is_scale_free() -> None:
    """Scaling every displacement by k changes only the log-speed channel of the encoder input."""
    net = LstmNet(hidden=8, form="speed")
    x = torch.randn(3, 8, 6)
    x[:, 0, :2] = 0.0
    x2 = x.clone()
    x2[:, :, :2] *= 4.0
    a, b = net.encode_input(x), net.encode_input(x2)
    assert a.shape[-1] == 7
    # the 0.02 m standstill guard breaks exact invariance only slightly
    np.testing.assert_allclose(a[..., :2].numpy(), b[..., :2].numpy(), rtol=0.05, atol=0.02)
    np.testing.assert_allclose(a[..., 2:6].numpy(), b[..., 2:6].numpy())
    assert float((b[..., 6] - a[..., 6]).mean()) > 0


def test_mirroring_is_exact_left_right() -> None:
    """A mirrored drive's windows equal the original's with dy, ay, yaw negated, so mirroring
    windows in training is the same as training on mirrored drives."""
    from dataclasses import replace

    from posbench.predictors.lstm.train import mirror_signs
    from posbench.predictors.lstm.windows import drive_windows

    d = generate_drive(seed=5, route="turns", duration_s=60.0)
    g, imu, tr = d.gps, d.imu, d.truth
    m = replace(
        d,
        gps=replace(g, y=-g.y),
        imu=replace(imu, ay=-imu.ay, yaw=-imu.yaw, yaw_rate=-imu.yaw_rate),
        truth=replace(tr, y=-tr.y, yaw=-tr.yaw),
    )
    a, b = drive_windows(d), drive_windows(m)
    sign = np.array([1, -1, 1, -1, -1, 1.0])
    np.testing.assert_allclose(b.X, a.X * sign, atol=1e-6)
    np.testing.assert_allclose(b.Y, a.Y * sign, atol=1e-6)
    sg = mirror_signs(1000, torch.Generator().manual_seed(0), torch.zeros(1))
    flipped = (sg[:, 0, 1] < 0).float().mean()
    assert 0.4 < float(flipped) < 0.6 and torch.equal(sg[:, 0, 3], sg[:, 0, 1])
