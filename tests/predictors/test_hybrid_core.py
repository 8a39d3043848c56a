"""The hybrid's compiled core (predictors.hybrid.core): the bundled model runs it, with the
full graph's answers; a model copied without it runs the full graph; a core that does not
reproduce its model is refused in one line; the export writes the committed weights."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import copy_model

from posbench.predictors.hybrid.core import CORE_TOL, check_inputs
from posbench.predictors.hybrid.model_info import bundled_model
from posbench.predictors.hybrid.predictor import HybridPredictor
from posbench.scenarios.errors import DataError
from posbench.scenarios.synthetic import generate_drive


def _copy_bundled(dst: Path, with_core: bool = True) -> Path:
    return copy_model(bundled_model().parent, dst, with_core)


def test_bundled_hybrid_runs_its_core_and_it_reproduces_the_graph() -> None:
    p = HybridPredictor()
    assert p.core is not None and p.config()["core"] is True
    assert p.core.difference(p.info, p.net) <= CORE_TOL / 10
    f, pr = check_inputs(p.info, 8, seed=9)
    net = p.net
    for fi, pi in zip(f, pr, strict=True):
        want = net.session.run(
            [net.output_name], {net.input_names[0]: fi[None], net.input_names[1]: pi[None]}
        )[0][0]
        got = p.core.run(np.ascontiguousarray(fi), np.ascontiguousarray(pi.reshape(-1)))
        np.testing.assert_allclose(got, want, atol=CORE_TOL / 10, rtol=0)


def test_model_copied_without_its_core_gives_the_same_answers(tmp_path: Path) -> None:
    bare = HybridPredictor(str(_copy_bundled(tmp_path / "bare", with_core=False)))
    cored = HybridPredictor()
    assert bare.core is None and bare.config()["core"] is False
    d = generate_drive(seed=4, route="mixed", duration_s=60.0)
    imu = d.imu
    assert imu is not None
    j = 0
    diffs = []
    for i in range(len(d.gps)):
        t = d.gps.t[i]
        while j < len(imu.t) and imu.t[j] <= t:
            for p in (bare, cored):
                p.observe_imu(imu.t[j], imu.ax[j], imu.ay[j], imu.yaw[j], imu.yaw_rate[j])
            j += 1
        for p in (bare, cored):
            p.observe_gps(t, d.gps.x[i], d.gps.y[i])
        for dt in (0.1, 0.4, 0.9):
            a, b = bare.position_at(t + dt), cored.position_at(t + dt)
            diffs.append(max(abs(a[0] - b[0]), abs(a[1] - b[1])))
    assert cored.last_step() is not None
    assert max(diffs) <= 1e-5


def test_a_core_that_does_not_reproduce_its_model_is_refused(tmp_path: Path) -> None:
    d = _copy_bundled(tmp_path / "m")
    with np.load(d / "model.core.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["dec2_b"] = arrays["dec2_b"] + np.float32(0.01)
    np.savez(d / "model.core.npz", **arrays)
    with pytest.raises(DataError, match="model.core.npz.*does not reproduce model.onnx") as e:
        HybridPredictor(str(d))
    assert "\n" not in str(e.value)
    (d / "model.core.npz").write_text("not weights")
    with pytest.raises(DataError, match="not a core weights file"):
        HybridPredictor(str(d))


def test_write_core_folds_the_bundled_graph_into_the_committed_weights(tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    from posbench.predictors.hybrid.core import write_core

    d = _copy_bundled(tmp_path / "m", with_core=False)
    entry = write_core(d / "model.onnx")
    assert entry["file"] == "model.core.npz"
    with (
        np.load(d / "model.core.npz") as new,
        np.load(bundled_model().parent / entry["file"]) as ref,
    ):
        assert sorted(new.files) == sorted(ref.files)
        for k in ref.files:
            np.testing.assert_array_equal(new[k], ref[k], err_msg=k)


def test_the_cores_weights_are_aligned_also_in_a_pickled_copy() -> None:
    """The lstm's and the hybrid's packed weights start on an ALIGN-byte boundary (their
    kernel's speed depends on it), in a new predictor and in a pickled copy (a worker's,
    whose arrays land wherever the allocator puts them), with the same values; the copied
    hybrid's step kernel reads its own core's weights."""
    import pickle

    from posbench.predictors.lstm.core_kernel import ALIGN
    from posbench.predictors.lstm.predictor import LstmPredictor

    for p in (HybridPredictor(), LstmPredictor()):
        assert p.core is not None
        q = pickle.loads(pickle.dumps(p))
        for core in (p.core.core, q.core.core):
            assert core.packed.ctypes.data % ALIGN == 0
        np.testing.assert_array_equal(q.core.core.packed, p.core.core.packed)
        if isinstance(q, HybridPredictor):
            assert any(a is q.core.core.packed for a in q._args)
