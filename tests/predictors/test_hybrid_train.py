"""The hybrid's training loop end to end (tiny), and `bench train --network hybrid`."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from typer.testing import CliRunner  # noqa: E402

from posbench.cli.app import app  # noqa: E402
from posbench.predictors.hybrid.data import hybrid_windows  # noqa: E402
from posbench.predictors.hybrid.predictor import HybridPredictor  # noqa: E402
from posbench.predictors.hybrid.train import future_answers, run_training  # noqa: E402
from posbench.scenarios.synthetic import generate_drive  # noqa: E402


@pytest.mark.slow
def test_tiny_hybrid_training_end_to_end(tmp_path) -> None:
    drives = [
        generate_drive(seed=200 + i, route=r, duration_s=60.0)
        for i, r in enumerate(("mixed", "turns", "roundabout"))
    ]
    calls = []
    info = run_training(
        [],
        tmp_path,
        epochs=2,
        drives=drives,
        hidden=16,
        command="test",
        profiles=("rtk",),
        progress=lambda *a: calls.append(a),
        held_out=lambda d, tr, va, prof: {"seen": [str(d), len(tr), len(va), list(prof)]},
    )
    assert [c[0] for c in calls] == [1, 2] and all(np.isfinite(c[4]) for c in calls)
    js = json.loads((tmp_path / "model.json").read_text())
    assert js["format"] == "posbench-hybrid" and js["trained"] is True
    assert js["command"] == "test" and js["data"]["val_drives"]
    assert js["training"]["history"][0]["epoch"] == 0  # the kf alone, the selection's baseline
    val = js["validation"]["all"]
    assert val["hybrid"]["n"] == val["kf"]["n"] > 0
    # selection keeps the best epoch by validation error, epoch 0 (= the kf) included
    best = min(h["val_future_mean_m"] for h in js["training"]["history"])
    assert val["hybrid"]["mean_m"] == pytest.approx(best, rel=1e-4)
    # the gate: shrinkage per horizon in [0, 1] from the validation rows, the training box
    gate = js["gate"]
    assert len(gate["shrink"]) == 4 and all(0 <= a <= 1 for a in gate["shrink"])
    assert len(gate["feature_min"]) == 6 and np.shape(gate["prior_max"]) == (4, 2)
    assert js["held_out"]["seen"] == [str(tmp_path), 2, 1, ["rtk"]]
    card = (tmp_path / "MODEL_CARD.md").read_text()
    assert card.startswith("# Model card: `hybrid`") and "| all | hybrid |" in card
    p = HybridPredictor(str(tmp_path), gps_condition="rtk")
    p.reset()
    assert p.config()["gps_condition"] == "rtk"
    assert info["prior"]["params"]["rtk"] == js["prior"]["params"]["rtk"]


def test_future_answers_rotate_the_correction() -> None:
    d = generate_drive(seed=3, route="turns", duration_s=40.0)
    hw = hybrid_windows(d, d.gps, {})
    corr = np.zeros((len(hw), 2))
    corr[:, 0] = 1.0  # 1 m along the heading
    got = future_answers(hw, corr) - hw.kf_future
    np.testing.assert_allclose(got, np.stack([np.cos(hw.psi), np.sin(hw.psi)], 1), atol=1e-12)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--network", "gru"], "--network 'gru': choose one of lstm, hybrid"),
        (["--profiles", "rtk,gnss"], "--profiles 'rtk,gnss': choose from none, rtk, consumer"),
        (["--corpus-hours", "-1"], "--corpus-hours must be >= 0"),
        (["--max-minutes", "0"], "--max-minutes must be > 0"),
    ],
)
def test_train_option_errors_are_one_line(tmp_path, args, message) -> None:
    r = CliRunner().invoke(app, ["train", "--synthetic", "1", "--out", str(tmp_path / "o"), *args])
    assert r.exit_code == 2
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]


def test_training_refuses_kitti(kitti_dir) -> None:
    """KITTI is evaluation only: `bench train --data <kitti>` is one error line, exit 2."""
    drive = next(p for p in sorted(kitti_dir.rglob("*_sync")) if p.is_dir())
    r = CliRunner().invoke(app, ["train", "--data", str(drive), "--out", "/tmp/never-written"])
    assert r.exit_code == 2 and "Traceback" not in r.output
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "evaluation-only" in lines[0]


def test_held_out_comparison_of_an_untrained_model_is_exactly_zero(tmp_path) -> None:
    """The untrained model answers as its prior: every held-out difference is 0, CI too;
    a drive without truth is compared once, on its own fixes."""
    from posbench.predictor_tools.held_out import compare_on_held_out
    from posbench.predictors.hybrid.export import write_untrained

    write_untrained(tmp_path, seeds=(0,), hidden=8)
    drives = [generate_drive(seed=300 + i, duration_s=60.0) for i in range(3)]
    res = compare_on_held_out(tmp_path, drives, ("rtk", "none"), workers=1)
    assert set(res["conditions"]) == {"rtk", "none"} and len(res["drives"]) == 3
    for c in res["conditions"].values():
        assert c["drives"] == 3
        for kind in ("future", "now"):
            r = c[kind]
            assert r["kf_mean_m"] == r["hybrid_mean_m"] > 0
            assert r["hybrid_minus_kf"] == {"diff": 0.0, "lo": 0.0, "hi": 0.0}


def test_bench_train_hybrid_prints_and_records_the_held_out_table(tmp_path, monkeypatch) -> None:
    """The held-out table in the terminal, model.json and the card, beside the kf tuned by
    gradient on the training drives (its fit is tested in test_kf_gradient.py; here a
    stand-in that records what it was given)."""
    import posbench.predictors.kalman.tuning.gradient as kg

    fitted = []

    def fake_tune(drives, cond, seed=0):
        fitted.append((cond, len(drives)))
        return {
            "params": {"jerk_psd": 3.0},
            "Q_c": [[3.0, 0.0], [0.0, 3.0]],
            "R": [[1e-4, 0.0], [0.0, 1e-4]],
            "sigma_a": 0.3,
            "loss": {},
            "best_iteration": 0,
        }

    monkeypatch.setattr(kg, "gradient_tune", fake_tune)
    out = tmp_path / "m"
    r = CliRunner().invoke(
        app,
        [
            "train",
            "--network",
            "hybrid",
            "--synthetic",
            "6",
            "--epochs",
            "1",
            "--hidden",
            "8",
            "--profiles",
            "rtk",
            "--out",
            str(out),
            "--workers",
            "1",
        ],
    )
    assert r.exit_code == 0, r.output
    js = json.loads((out / "model.json").read_text())
    rtk = js["held_out"]["conditions"]["rtk"]
    assert rtk["drives"] >= 1 and set(rtk["future"]["hybrid_minus_kf"]) == {"diff", "lo", "hi"}
    assert "held out, as run" in r.output
    assert fitted == [("rtk", 5)]  # the 5 synthetic training drives, under the profile
    grad = rtk["future"]["hybrid_minus_kf@gradient"]
    assert set(grad) == {"diff", "lo", "hi"}
    assert js["held_out"]["gradient_prior"]["rtk"]["params"] == {"jerk_psd": 3.0}
    card = (out / "MODEL_CARD.md").read_text()
    assert "Gain over its prior" in card and "hybrid - kf@gradient" in card
