"""`bench train` ends with a short summary table (no raw JSON) and announces early stopping."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import pytest

pytest.importorskip("torch")

from typer.testing import CliRunner  # noqa: E402

import posbench.predictors.lstm.train as lstm_train  # noqa: E402
from posbench.cli.app import app  # noqa: E402

WIDTH = 100


def train_cli(out: Path, *args: str) -> str:
    r = CliRunner().invoke(
        app, ["train", "--synthetic", "2", "--out", str(out), *args], env={"COLUMNS": str(WIDTH)}
    )
    assert r.exit_code == 0, r.output
    return r.output


def test_train_ends_with_summary_table(tmp_path) -> None:
    out = train_cli(tmp_path, "--epochs", "2")
    js = json.loads((tmp_path / "model.json").read_text())
    lines = out.splitlines()
    assert "┏" in out and "…" not in out
    # every line fits but those that name a file (printed whole, to stay copyable: their
    # length is tmp_path's, longer under pytest-xdist)
    assert max(len(line) for line in lines if str(tmp_path) not in line) <= WIDTH
    assert not any(line.lstrip().startswith(("{", "}", '"')) for line in lines)  # no raw JSON
    assert '"mean_m"' not in out and "history" not in out
    assert f"model card: {tmp_path / 'model.json'}" in out
    assert f"model: {tmp_path / 'model.onnx'}" in out
    assert f"core weights: {tmp_path / 'model.core.npz'}" in out
    assert "2 of 2" in out and "early stop at" not in out
    rows = {line.split("│")[1].strip(): line for line in lines if line.startswith("│")}
    assert rows["early stopping"].split("│")[2].strip() == (
        f"no (patience {js['training']['early_stopping_patience']})"
    )
    assert rows["train"].split("│")[3].strip() == str(len(js["data"]["train_drives"]))
    assert str(js["data"]["val_windows"]) in rows["validation"]
    cells = [[c.strip() for c in line.split("│")[1:-1]] for line in lines if line.startswith("│")]
    for key, label in (
        ("lstm", "lstm (this model)"),
        ("cubic", "cubic extrapolation"),
        ("cv", "constant velocity"),
    ):
        e = js["validation"]["all"][key]
        assert [
            label,
            str(e["n"]),
            f"{e['mean_m']:.3f}",
            f"{e['p50_m']:.3f}",
            f"{e['p95_m']:.3f}",
        ] in cells


def test_early_stop_is_announced(tmp_path, monkeypatch) -> None:
    # lr 0: the weights never change, so the validation loss cannot improve after epoch 1
    monkeypatch.setattr(
        lstm_train,
        "run_training",
        functools.partial(lstm_train.run_training, patience=1, lr=0.0, timing_calls=50),
    )
    out = train_cli(tmp_path, "--epochs", "5")
    assert (
        "early stop at epoch 2: validation loss did not improve for 1 epoch (best epoch 1)" in out
    )
    js = json.loads((tmp_path / "model.json").read_text())
    assert js["training"]["epochs_run"] == 2 and js["training"]["best_epoch"] == 1
    assert "2 of 5" in out
    assert "after epoch 2 (patience 1)" in out
