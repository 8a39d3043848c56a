"""The ``hybrid``'s gate (predictors/hybrid/gate.py): the shrinkage fit, the input envelope
(a drive unlike the training data gets the prior's answers, exactly) and the drive's own
evidence (a correction that does not help is not applied)."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from posbench.config import RunConfig  # noqa: E402
from posbench.predictors.hybrid.data import hybrid_windows  # noqa: E402
from posbench.predictors.hybrid.export import prior_kf_params, save_model  # noqa: E402
from posbench.predictors.hybrid.gate import (  # noqa: E402
    MIN_FIXES,
    EvidenceGate,
    fit_shrink,
    input_envelope,
)
from posbench.predictors.hybrid.model import HybridNet  # noqa: E402
from posbench.predictors.hybrid.predictor import HybridPredictor  # noqa: E402
from posbench.predictors.registry import create  # noqa: E402
from posbench.replay.loop import replay  # noqa: E402
from posbench.replay.prepare import prepare_drive  # noqa: E402
from posbench.scenarios.errors import DataError  # noqa: E402
from posbench.scenarios.synthetic import generate_drive  # noqa: E402

#: a correction the network answers whatever its input [m, heading frame], log variances
WRONG = np.array(
    [
        [0.10, 0.06, -4.0, -5.0],
        [0.20, 0.12, -3.0, -4.5],
        [0.30, 0.18, -2.5, -4.0],
        [0.40, 0.24, -2.0, -3.0],
    ],
    dtype=np.float32,
)


def _constant_net() -> HybridNet:
    torch.manual_seed(1)
    net = HybridNet(hidden=16)
    net.set_stats(np.zeros(6), np.ones(6), 1.0, 1.0)
    with torch.no_grad():
        net.decoder[-1].bias.copy_(torch.as_tensor(WRONG.ravel()))
    return net


@pytest.fixture(scope="module")
def prep():
    return prepare_drive(generate_drive(seed=5, route="mixed"), RunConfig(gps_profile="rtk"))


@pytest.fixture(scope="module")
def boxed(tmp_path_factory, prep):
    """The constant net with the envelope of one synthetic rtk drive's windows."""
    hw = hybrid_windows(prep.drive, prep.gps, prior_kf_params()["rtk"])
    d = tmp_path_factory.mktemp("boxed")
    save_model(_constant_net(), d, prior_kf_params(), gate=input_envelope(hw.X, hw.prior))
    return d


def _fast_line(hy: HybridPredictor) -> list[tuple[float, float]]:
    """Fixes along a line at 150 m/s (no car drove so in training), 0.2 s apart; the
    answers 0.2 s after each fix and the prior's."""
    pairs = []
    for i in range(40):
        t = 0.2 * i
        hy.observe_gps(t, 150.0 * t, 0.3 * t * t, sigma=0.02)
        pairs.append((hy.position_at(t + 0.2), hy.kf.position_at(t + 0.2)))
    return pairs


def test_a_drive_unlike_the_training_data_gets_the_priors_answers(boxed):
    hy = HybridPredictor(str(boxed), "rtk")
    for got, prior in _fast_line(hy):
        assert got == prior  # to the bit
    assert hy.outside > 20 and hy.steps == 0
    # not vacuous: the same fixes without the gate are corrected
    raw = HybridPredictor(str(boxed), "rtk", gate=False)
    assert any(g != p for g, p in _fast_line(raw))


def test_a_training_like_drive_lies_inside_its_own_box(boxed, prep):
    hy = HybridPredictor(str(boxed), "rtk", gate=False)
    hy_box = HybridPredictor(str(boxed), "rtk")
    replay(hy, prep, 0.2)
    replay(hy_box, prep, 0.2)
    assert hy_box.steps == hy.steps > 100 and hy_box.outside == 0


def test_a_correction_that_does_not_help_is_not_applied(tmp_path, prep):
    """A constant correction unrelated to the motion (10-40 cm off): without the gate it
    costs accuracy; with it the hybrid stays within 2 % of its prior (rtk fixes)."""
    save_model(_constant_net(), tmp_path, prior_kf_params())
    kf = replay(create("kf", "rtk"), prep, 0.2)
    raw = replay(HybridPredictor(str(tmp_path), "rtk", gate=False), prep, 0.2)
    gated_hy = HybridPredictor(str(tmp_path), "rtk")
    gated = replay(gated_hy, prep, 0.2)
    truth = prep.drive.truth

    def mean_err(xy: np.ndarray, t: np.ndarray) -> float:
        ok = np.isfinite(xy).all(axis=1) & (t <= truth.t[-1])
        ref = np.stack([np.interp(t, truth.t, truth.x), np.interp(t, truth.t, truth.y)], 1)
        return float(np.linalg.norm(xy[ok] - ref[ok], axis=1).mean())

    tq = prep.gps.t + 0.2
    e_kf, e_raw, e_gated = (mean_err(r.future_xy, tq) for r in (kf, raw, gated))
    assert e_raw > 1.5 * e_kf  # the correction hurts
    assert e_gated <= 1.02 * e_kf, (e_kf, e_raw, e_gated)
    assert gated_hy.steps > 100


def test_evidence_earns_and_loses_the_correction():
    rng = np.random.default_rng(0)
    c = np.array([0.05, 0.02])
    g = EvidenceGate()
    assert g.weight == 0.0
    for i in range(40):  # fixes where the prior is off by the correction (+2 cm noise)
        e = c + rng.normal(0, 0.02, 2)
        g.observe(*e, *c)
        if i + 1 < MIN_FIXES:
            assert g.weight == 0.0
    assert g.weight == 1.0
    for _ in range(40):  # the prior is right now: the correction costs
        e = rng.normal(0, 0.02, 2)
        g.observe(*e, *c)
    assert g.weight == 0.0
    # metre-level fixes and a useless correction: applied rarely and never in full for long
    g.reset()
    ws = []
    for _ in range(2000):
        g.observe(*rng.normal(0, 2.0, 2), *c)
        ws.append(g.weight)
    assert np.mean(ws) < 0.25
    g.observe(0.0, 0.0, 0.0, 0.0)  # a zero correction is no evidence
    assert g.weight == ws[-1]


def test_fit_shrink_is_the_clipped_least_squares_factor():
    rng = np.random.default_rng(1)
    corr = rng.normal(0, 0.1, (500, 4, 2))
    target = corr * np.array([1.0, 0.5, 0.0, 2.0])[None, :, None]
    a = fit_shrink(corr, target)
    np.testing.assert_allclose(a, [1.0, 0.5, 0.0, 1.0], atol=1e-12)
    assert fit_shrink(np.zeros((3, 4, 2)), target[:3]).tolist() == [0.0] * 4
    assert fit_shrink(corr, -corr).tolist() == [0.0] * 4


def test_a_bad_gate_is_a_one_line_error(boxed, tmp_path):
    info = json.loads((boxed / "model.json").read_text())
    (tmp_path / "model.onnx").write_bytes((boxed / "model.onnx").read_bytes())
    for gate, needle in (
        ({**info["gate"], "shrink": [1.0, 2.0, 0.5, 0.5]}, "gate.shrink"),
        ({"feature_min": [0.0] * 6}, "give all of"),
        ({**info["gate"], "prior_max": [1.0]}, "gate.prior_max"),
        ([1, 2], "'gate'"),
    ):
        (tmp_path / "model.json").write_text(json.dumps({**info, "gate": gate}))
        with pytest.raises(DataError) as ei:
            HybridPredictor(str(tmp_path))
        assert needle in str(ei.value) and "\n" not in str(ei.value)
