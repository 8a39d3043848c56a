"""The compiled pieces of the fused lstm step (predictors.lstm.core_kernel, fused_kernels)
against plain numpy references; a core weights file that cannot be read is one error line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from posbench.predictors.lstm import core_kernel, fused_kernels
from posbench.predictors.lstm.core_net import check_windows
from posbench.predictors.lstm.fused import _eval_rows
from posbench.predictors.lstm.predictor import LstmPredictor, bundled_model
from posbench.scenarios.errors import DataError


def test_rational_tanh_is_within_1e6_of_tanh_and_saturates() -> None:
    x = np.concatenate([np.linspace(-30, 30, 20001), [0.0, 1e-8, -1e-8]]).astype(np.float32)
    got = np.array([core_kernel._tanh(np.float32(v)) for v in x])
    assert np.max(np.abs(got - np.tanh(x.astype(np.float64)))) < 1e-6
    assert got[0] == -got[-4] and abs(got[-4]) <= 1.0


@pytest.fixture(scope="module")
def bundled_core():
    return LstmPredictor().core


def test_core_kernel_matches_the_numpy_reference(bundled_core) -> None:
    """Check windows and random ones (large inputs drive the gates into saturation)."""
    core = bundled_core
    rng = np.random.default_rng(2)
    z = np.concatenate(
        [
            np.stack([core._scaled(x)[0] for x in check_windows(48, seed=3)]),
            rng.normal(0.0, 4.0, (48, 8, 7)).astype(np.float32),
        ]
    )
    want = core.core.reference(z)
    got = np.stack([core.core.run(np.ascontiguousarray(w)).copy() for w in z])
    # residuals are standardised (x res_std ~0.03 m): 1e-4 here is ~3e-6 m
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)
    assert np.isfinite(got).all()


def test_fit_cubics_is_least_squares(bundled_core) -> None:
    rng = np.random.default_rng(0)
    rows_eval = _eval_rows()
    for n_fix, n_imu, yaw_ok in ((4, 0, True), (11, 200, True), (7, 30, False)):
        t = np.sort(rng.uniform(0, 2.2, n_fix))
        t[-1] = 2.2
        fix = np.column_stack([t + 100.0, 3e3 + 10 * t + rng.normal(0, 0.1, n_fix), -50 + t**2])
        ti = np.sort(rng.uniform(0.1, 2.2, n_imu)) + 100.0
        imu = np.column_stack([ti, rng.normal(size=(n_imu, 3))]) if n_imu else np.empty((0, 4))
        x = np.zeros((2, 4, 3))
        e = np.zeros((2, 24, 3))
        fused_kernels.fit_cubics(fix, imu, 102.2, yaw_ok, rows_eval, x, e)
        for k, rows in enumerate((fix, imu)):
            if not len(rows):
                continue
            s = rows[:, 0] - 102.2
            v = np.vander(s, 4, increasing=True)[:, [2, 3, 0, 1]]
            n_vals = 2 if k == 0 or not yaw_ok else 3
            ref = np.zeros((4, 3))
            ref[:, :n_vals] = np.linalg.lstsq(v, rows[:, 1 : 1 + n_vals], rcond=None)[0]
            np.testing.assert_allclose(x[k], ref, atol=1e-7, rtol=1e-9)
            np.testing.assert_allclose(e[k], rows_eval @ ref, atol=1e-7, rtol=1e-9)


def test_an_unreadable_core_weights_file_is_one_error_naming_it(tmp_path: Path) -> None:
    src = bundled_model().parent
    for name in ("model.onnx", "model.json"):
        shutil.copy(src / name, tmp_path / name)
    (tmp_path / "model.core.npz").write_bytes(b"not a zip archive")
    with pytest.raises(DataError, match="model.core.npz") as e:
        LstmPredictor(str(tmp_path))
    assert "\n" not in str(e.value)
    with np.load(src / "model.core.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["lstm_r"] = arrays["lstm_r"][:, :, :-1]
    np.savez(tmp_path / "model.core.npz", **arrays)
    with pytest.raises(DataError, match="lstm_r has shape"):
        LstmPredictor(str(tmp_path))
    info = json.loads((src / "model.json").read_text())
    assert info["core"]["file"] == "model.core.npz"
