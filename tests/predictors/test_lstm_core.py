"""The core graph of speed-form lstm models (predictors.lstm.core_graph / core_net): the same
answers as the full graph, used by the fused step, refused when it does not reproduce its
model, optional when a model was copied without it."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import copy_model

torch = pytest.importorskip("torch")

from posbench.predictors.lstm.core_graph import NoCoreGraph, write_core  # noqa: E402
from posbench.predictors.lstm.core_net import CORE_TOL_M, CoreNet, check_windows  # noqa: E402
from posbench.predictors.lstm.export import export_best  # noqa: E402
from posbench.predictors.lstm.model import FuturePoint, LstmNet  # noqa: E402
from posbench.predictors.lstm.predictor import LstmPredictor, bundled_model  # noqa: E402
from posbench.predictors.lstm.runtime import OnnxModel  # noqa: E402
from posbench.scenarios.errors import DataError  # noqa: E402
from posbench.scenarios.synthetic import generate_drive  # noqa: E402


def _speed_net(seed: int, hidden: int = 16) -> LstmNet:
    torch.manual_seed(seed)
    net = LstmNet(hidden=hidden, form="speed", fix_offset=True).eval()
    net.set_stats(
        torch.tensor([2.0, 0.0, 0.1, -0.1, 0.0, 0.7]), torch.tensor([1.5, 0.3, 0.8, 0.9, 0.1, 0.46])
    )
    net.set_speed_stats(0.7, 0.9, torch.tensor([0.035, 0.024]))
    return net


def test_core_reproduces_torch_and_the_full_graph(tmp_path: Path) -> None:
    """Core (with the numpy scaling) = full ONNX graph = torch's FuturePoint, to float32
    rounding, on windows from standstill to 40 m/s."""
    net = _speed_net(3)
    export_best(net, tmp_path / "model.onnx", n_calls=10)
    entry = write_core(tmp_path / "model.onnx")
    assert (tmp_path / "model.core.npz").is_file() and entry["file"] == "model.core.npz"
    full = OnnxModel(tmp_path / "model.onnx")
    core = CoreNet(tmp_path / "model.onnx", entry, full)
    assert core.difference(full) <= 1e-6
    x = check_windows(16, seed=5)
    with torch.no_grad():
        ref = FuturePoint(net)(torch.from_numpy(x.astype(np.float32))).numpy()[:, :2]
    got = []
    for w in x:
        core.load(w)
        got.append(core.displacement(w))
    np.testing.assert_allclose(np.array(got), ref, atol=2e-6)


def test_paper_form_has_no_core(tmp_path: Path) -> None:
    torch.manual_seed(0)
    export_best(LstmNet(hidden=8, form="paper").eval(), tmp_path / "m.onnx", n_calls=10)
    with pytest.raises(NoCoreGraph, match="speed-form"):
        write_core(tmp_path / "m.onnx")


def test_bundled_model_runs_its_core_and_config_says_so() -> None:
    p = LstmPredictor()
    assert p.core is not None and p.config()["core_graph"] is True
    assert p.core.difference(p.net) <= CORE_TOL_M / 10
    assert LstmPredictor(step="staged").core is None


def _copy_bundled(dst: Path, with_core: bool = True) -> Path:
    return copy_model(bundled_model().parent, dst, with_core)


def test_model_copied_without_its_core_runs_the_full_graph_with_the_same_answers(
    tmp_path: Path,
) -> None:
    bare = LstmPredictor(str(_copy_bundled(tmp_path / "bare", with_core=False)))
    assert bare.core is None and bare.config()["core_graph"] is False
    cored = LstmPredictor()
    d = generate_drive(seed=4, route="mixed", duration_s=60.0)
    diffs = []
    for i in range(len(d.gps)):
        t, x, y = d.gps.t[i], d.gps.x[i], d.gps.y[i]
        for p in (bare, cored):
            p.observe_gps(t, x, y)
        a, b = bare.position_at(t + 0.2), cored.position_at(t + 0.2)
        diffs.append(max(abs(a[0] - b[0]), abs(a[1] - b[1])))
    assert cored.fused_steps > 100 and bare.fused_steps == cored.fused_steps
    assert max(diffs) <= 5e-6


def test_a_core_that_does_not_reproduce_its_model_is_refused(tmp_path: Path) -> None:
    """Another model's core beside the bundled one: one error line naming the core file,
    also through the CLI (exit 2, no traceback)."""
    d = _copy_bundled(tmp_path / "m")
    other = tmp_path / "other"
    other.mkdir()
    export_best(_speed_net(7, hidden=64), other / "model.onnx", n_calls=10)
    write_core(other / "model.onnx")
    shutil.copy(other / "model.core.npz", d / "model.core.npz")
    with pytest.raises(DataError, match="does not reproduce model.onnx"):
        LstmPredictor(str(d))
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "posbench",
            "run",
            "-p",
            "lstm",
            "--model",
            f"lstm={d}",
            "--synthetic-duration",
            "30",
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "model.core.npz" in lines[0]


def test_core_entry_in_model_json_names_its_scales() -> None:
    info = json.loads(bundled_model().with_suffix(".json").read_text())
    entry = info["core"]
    assert entry["file"] == "model.core.npz"
    np.testing.assert_allclose(entry["res_std_m"], info["speed_stats"]["res_std_m"], rtol=1e-6)
