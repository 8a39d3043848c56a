"""The ``hybrid`` predictor (the kf bank as prior + a gated learned residual): its fallback
to the prior, the correction it adds, its gate, ONNX parity with torch, its training data,
pickling, the GPS-condition seam of the registry and one-line errors for a bad model."""

from __future__ import annotations

import json
import math
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import ROOT

torch = pytest.importorskip("torch")

from posbench.config import RunConfig  # noqa: E402
from posbench.predictor_tools.contract.inputs import HORIZON_S  # noqa: E402
from posbench.predictors.hybrid.data import hybrid_windows  # noqa: E402
from posbench.predictors.hybrid.export import (  # noqa: E402
    export_onnx,
    model_info,
    parity,
    prior_kf_params,
    save_model,
    write_untrained,
)
from posbench.predictors.hybrid.model import HybridNet  # noqa: E402
from posbench.predictors.hybrid.predictor import HORIZONS, HybridPredictor  # noqa: E402
from posbench.predictors.lstm.windows import drive_windows  # noqa: E402
from posbench.predictors.registry import create  # noqa: E402
from posbench.replay.loop import GPS, events, feed, replay  # noqa: E402
from posbench.replay.prepare import prepare_drive  # noqa: E402
from posbench.scenarios.errors import DataError  # noqa: E402
from posbench.scenarios.synthetic import generate_drive  # noqa: E402

#: a hand-set correction per horizon: dx, dy [m, heading frame], log var along, across
CORR = (
    np.array(
        [
            [0.05, -0.02, -4.0, -5.0],
            [0.11, 0.03, -3.0, -4.5],
            [0.20, 0.07, -2.5, -4.0],
            [0.31, -0.10, -2.0, -3.0],
        ]
    )
    .astype(np.float32)
    .astype(np.float64)
)


@pytest.fixture(scope="module")
def untrained(tmp_path_factory) -> Path:
    """An untrained model (zero last layer), statistics from one synthetic drive."""
    d = tmp_path_factory.mktemp("untrained")
    write_untrained(d, seeds=(0,))
    return d


def _constant_net() -> HybridNet:
    """A net whose output is CORR whatever its input (last layer: weight 0, bias CORR)."""
    torch.manual_seed(1)
    net = HybridNet(hidden=16)
    net.set_stats(np.zeros(6), np.ones(6), 1.0, 1.0)
    with torch.no_grad():
        net.decoder[-1].bias.copy_(torch.as_tensor(CORR.ravel(), dtype=torch.float32))
    return net


@pytest.fixture(scope="module")
def constant(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("constant")
    save_model(_constant_net(), d, prior_kf_params())
    return d


@pytest.fixture(scope="module")
def prep():
    return prepare_drive(generate_drive(seed=5, route="mixed"), RunConfig(gps_profile="rtk"))


def _rot(psi: float, v: np.ndarray) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _corr_at(h: float) -> np.ndarray:
    """CORR's (dx, dy) interpolated as the hybrid does (0 at h = 0, held beyond 0.8 s)."""
    knots = np.concatenate([[0.0], HORIZONS])
    return np.array([np.interp(h, knots, np.concatenate([[0.0], CORR[:, j]])) for j in (0, 1)])


# --------------------------------------------------------------- the prior, exactly
@pytest.mark.parametrize("profile", ["rtk", "consumer", "none"])
def test_untrained_hybrid_answers_exactly_as_kf_in_the_runner(untrained, profile):
    """Zero correction: every future and now answer of the hybrid is the kf's (same tuned
    parameters: the model records them per condition), bit for bit, though the network ran;
    with the gate off too (no shrinkage, no evidence)."""
    prep = prepare_drive(generate_drive(seed=2, route="mixed"), RunConfig(gps_profile=profile))
    kf = create("kf", profile)
    hy = create("hybrid", profile, model=str(untrained), gate=False)
    assert hy.prior_condition == profile and hy.kf.config() == kf.config()
    a, b = replay(kf, prep, 0.2), replay(hy, prep, 0.2)
    assert hy.steps > 100  # the network did run on most fixes
    np.testing.assert_array_equal(b.future_xy, a.future_xy)
    np.testing.assert_array_equal(b.now_xy, a.now_xy)
    assert np.isfinite(b.future_xy[5:]).all()


@pytest.mark.slow
def test_untrained_hybrid_equals_kf_through_the_runner_command(untrained, tmp_path):
    """The real runner (`bench run`, one worker): same figures for the hybrid and its prior,
    the ``kf`` as the run builds it (its tuning for the run's GPS condition)."""
    out = tmp_path / "out"
    cls = "kf"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "posbench",
            "run",
            "-p",
            f"{cls},hybrid",
            "--model",
            f"hybrid={untrained}",
            "--out",
            str(out),
            "--workers",
            "1",
            "--plot-format",
            "none",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    res = json.loads((out / "results.json").read_text())["predictors"]
    for kind in ("future", "now"):
        a, b = res[cls][kind], res["hybrid"][kind]
        assert a["count"] > 100
        for key in ("count", "missing", "mean_m", "median_m", "rmse_m", "p95_m", "max_m"):
            assert a[key] == b[key], (kind, key)


# --------------------------------------------------------------- the correction
def test_a_hand_set_correction_shifts_answers_by_exactly_R_psi_corr(constant, prep):
    hy = HybridPredictor(str(constant), "rtk", gate=False)
    evs = events(prep)
    checked = 0
    for i, (k, t, _) in enumerate(evs):
        feed(hy, evs, HORIZON_S, i, i + 1)
        if k != GPS or hy.last_step() is None or hy._stationary():
            continue
        t_fix, psi = hy.last_step()
        assert t_fix == t
        for h in (0.0, 0.1, 0.2, 0.35, 0.6, 0.8, 1.5):
            want = np.asarray(hy.kf.position_at(t + h)) + _rot(psi, _corr_at(h))
            np.testing.assert_allclose(hy.position_at(t + h), want, rtol=0, atol=1e-9)
        # covariance: the kf's + R diag(exp(logvar)) R^T at a knot (0.4 s) and beyond (2 s)
        for h, j in ((0.4, 1), (2.0, 3)):
            c, s = math.cos(psi), math.sin(psi)
            r = np.array([[c, -s], [s, c]])
            extra = r @ np.diag(np.exp(CORR[j, 2:])) @ r.T
            np.testing.assert_allclose(
                hy.covariance_at(t + h), hy.kf.covariance_at(t + h) + extra, rtol=1e-9, atol=1e-12
            )
        checked += 1
    assert checked > 100


def test_start_up_and_standstill_fall_back_to_the_prior(constant):
    hy = HybridPredictor(str(constant), "rtk", gate=False)
    # start-up: fixes 0.2 s apart along a line; no window until they span 2 s
    for i in range(11):
        t = 0.2 * i
        hy.observe_gps(t, 10.0 * t, 0.0, sigma=0.02)
        if i < 10:
            assert hy.last_step() is None
            assert hy.position_at(t + 0.5) == hy.kf.position_at(t + 0.5)
    assert hy.last_step() is not None
    t = 2.0
    moved = np.subtract(hy.position_at(t + 0.5), hy.kf.position_at(t + 0.5))
    np.testing.assert_allclose(moved, _rot(0.0, _corr_at(0.5)), atol=1e-6)  # heading ~0
    # standstill by wheel speed: the prior alone, answers and covariance
    hy.observe_speed(t + 0.01, 0.0)
    assert hy.position_at(t + 0.5) == hy.kf.position_at(t + 0.5)
    np.testing.assert_array_equal(hy.covariance_at(t + 0.5), hy.kf.covariance_at(t + 0.5))
    hy.observe_speed(t + 0.02, 10.0)
    assert hy.position_at(t + 0.5) != hy.kf.position_at(t + 0.5)
    # standstill by the window cubic's speed (no wheel speed): fixes that do not move
    hy2 = HybridPredictor(str(constant), "rtk", gate=False)
    for i in range(15):
        hy2.observe_gps(0.2 * i, 5.0, 7.0, sigma=0.02)
    assert hy2.last_step() is not None
    assert hy2.position_at(3.0) == hy2.kf.position_at(3.0)
    # a fix after a long outage restarts: no window, no stale correction
    hy.observe_gps(20.0, 200.0, 0.0, sigma=0.02)
    assert hy.last_step() is None
    assert hy.position_at(20.3) == hy.kf.position_at(20.3)


def test_a_non_finite_network_output_falls_back_to_the_prior(tmp_path):
    net = _constant_net()
    with torch.no_grad():
        net.decoder[-1].bias[0] = float("nan")
    export_onnx(net, tmp_path / "model.onnx")
    (tmp_path / "model.json").write_text(json.dumps(model_info(net, prior_kf_params())))
    hy = HybridPredictor(str(tmp_path))
    for i in range(15):
        hy.observe_gps(0.2 * i, 10.0 * 0.2 * i, 0.0)
    assert hy.steps == 0 and hy.last_step() is None
    assert hy.position_at(3.0) == hy.kf.position_at(3.0)
    assert math.isfinite(hy.position_at(3.0)[0])


# --------------------------------------------------------------- ONNX
def test_onnx_matches_torch_on_random_inputs(tmp_path):
    torch.manual_seed(3)
    net = HybridNet()
    with torch.no_grad():  # a non-zero last layer: the parity must mean something
        torch.nn.init.normal_(net.decoder[-1].weight, std=0.3)
        torch.nn.init.normal_(net.decoder[-1].bias, std=0.3)
    net.set_stats(np.linspace(-1, 1, 6), np.linspace(0.5, 2, 6), [0.5, 1, 1.5, 2], 0.05)
    info = save_model(net, tmp_path, prior_kf_params())
    assert info["parity_max_abs"] <= 1e-5
    assert parity(net, tmp_path / "model.onnx", n=64, seed=9) <= 1e-5
    # the runtime's preallocated two-input feed gives torch's answer too
    hy = HybridPredictor(str(tmp_path))
    rng = np.random.default_rng(4)
    f = rng.standard_normal((8, 6)).astype(np.float32)
    p = rng.standard_normal((4, 2)).astype(np.float32)
    hy.net.bufs[0][0] = f
    hy.net.bufs[1][0] = p
    got = hy.net.run_buffer()
    with torch.no_grad():
        want = net(torch.from_numpy(f[None]), torch.from_numpy(p[None])).numpy()[0]
    np.testing.assert_allclose(got, want, atol=1e-5)
    assert got.shape == (4, 4)
    # and the compiled core the export folded from the torch net (gates reordered)
    assert hy.core is not None and (tmp_path / "model.core.npz").is_file()
    np.testing.assert_allclose(hy.core.run(f, p.reshape(-1)), want, atol=1e-5)


def test_untrained_net_outputs_zero_correction():
    net = HybridNet()
    net.set_stats(np.zeros(6), np.ones(6), 1.0, [0.1, 0.2, 0.3, 0.4])
    with torch.no_grad():
        out = net(torch.randn(5, 8, 6), torch.randn(5, 4, 2)).numpy()
    assert np.all(out[..., :2] == 0.0)
    want = np.broadcast_to(2 * np.log([0.1, 0.2, 0.3, 0.4]), (5, 4))
    np.testing.assert_allclose(out[..., 2], want, rtol=1e-6)
    np.testing.assert_allclose(out[..., 3], want, rtol=1e-6)


# --------------------------------------------------------------- training data
def test_hybrid_windows_prior_is_what_kf_answers_in_a_real_replay(prep):
    params = prior_kf_params()["rtk"]
    kf = create("kf", "rtk")
    assert kf.config() == create("kf", None, **params).config()
    future = replay(kf, prep, 0.2).future_xy
    hw = hybrid_windows(prep.drive, prep.gps, params)
    ws = drive_windows(prep.drive, prep.gps)
    assert len(hw) > 100 and len(hw) <= len(ws)
    idx = np.searchsorted(prep.gps.t, hw.t_end)
    np.testing.assert_array_equal(prep.gps.t[idx], hw.t_end)
    np.testing.assert_allclose(hw.kf_future, future[idx], rtol=0, atol=1e-9)
    # the prior input is that answer minus the newest grid point, in the heading frame
    c, s = np.cos(hw.psi), np.sin(hw.psi)
    d = hw.kf_future - hw.p_last
    np.testing.assert_allclose(hw.prior[:, 0, 0], c * d[:, 0] + s * d[:, 1], atol=1e-9)
    np.testing.assert_allclose(hw.prior[:, 0, 1], c * d[:, 1] - s * d[:, 0], atol=1e-9)
    # the target: truth minus the kf, heading frame; X: the lstm's windows
    e = hw.truth_future - hw.kf_future
    np.testing.assert_allclose(hw.target[:, 0, 0], c * e[:, 0] + s * e[:, 1], atol=1e-9)
    keep = np.isin(ws.t_end, hw.t_end)
    np.testing.assert_array_equal(hw.X, ws.X[keep])
    assert hw.target.shape == (len(hw), 4, 2) and np.isfinite(hw.target).all()
    # residuals of a tuned kf with RTK fixes are centimetres at 0.2 s, larger at 0.8 s
    rms = np.sqrt((hw.target**2).sum(-1).mean(0))
    assert rms[0] < 0.2 and rms[3] > rms[0]


def test_hybrid_windows_drop_rows_the_reference_does_not_cover(prep):
    d = prep.drive
    hw = hybrid_windows(d, prep.gps, {})
    assert (hw.t_end + 0.8 <= d.truth.t[-1]).all()
    assert hw.t_end.max() > d.truth.t[-1] - 1.5


# --------------------------------------------------------------- pickling
def test_pickle_round_trip_mid_drive(constant, prep):
    """A fresh instance and one in the middle of a drive survive pickle (the ONNX session
    and the two-input feed are rebuilt) and then answer as the original."""
    evs = events(prep)
    ref = HybridPredictor(str(constant), "rtk")
    full = feed(ref, evs, HORIZON_S)
    a = HybridPredictor(str(constant), "rtk")
    half = len(evs) // 2
    first = feed(a, evs, HORIZON_S, 0, half)
    b = pickle.loads(pickle.dumps(a))
    ra, rb = feed(a, evs, HORIZON_S, half), feed(b, evs, HORIZON_S, half)
    assert rb == ra == full[len(first) :]
    assert b.steps == a.steps > 100 and b.last_step() == a.last_step()
    fresh = pickle.loads(pickle.dumps(HybridPredictor(str(constant), "rtk")))
    assert feed(fresh, evs, HORIZON_S) == full


# --------------------------------------------------------------- condition seam
def test_gps_condition_picks_the_prior_params(untrained, tmp_path):
    tuned = prior_kf_params()
    for cond in ("none", "rtk", "consumer", "native"):
        hy = create("hybrid", cond, model=str(untrained))
        assert hy.prior_condition == cond
        assert hy.config()["prior"]["condition"] == cond
        kf_config = hy.kf.config()  # flat names (the kf's inputs hold most of them)
        for k, v in tuned[cond].items():
            assert kf_config[k] == v
    assert create("hybrid", None, model=str(untrained)).prior_condition == "native"
    assert (
        create("hybrid", "rtk", model=str(untrained), gps_condition="consumer").prior_condition
        == "consumer"
    )  # explicit wins
    # a model without "native" and an unknown condition: the kf's defaults
    shutil.copy(untrained / "model.onnx", tmp_path / "model.onnx")
    info = json.loads((untrained / "model.json").read_text())
    info["prior"]["params"] = {"rtk": {"jerk_psd": 7.0}}
    (tmp_path / "model.json").write_text(json.dumps(info))
    hy = create("hybrid", "consumer", model=str(tmp_path))
    assert hy.prior_condition == "defaults" and hy.kf.config() == create("kf", None).config()
    assert create("hybrid", "rtk", model=str(tmp_path)).kf.config()["jerk_psds"] == [7.0]
    # predictors without the parameter never receive it
    assert "gps_condition" not in create("kf", "rtk").config()


def test_the_bundled_model_loads_and_records_itself():
    hy = create("hybrid", "rtk")
    assert hy.model_description() == {
        "model": "bundled (predictors/hybrid/bundled/model.onnx)",
        "bundled": True,
    }
    assert isinstance(hy.training_drives(), tuple)
    json.dumps(hy.config())


# --------------------------------------------------------------- bad models
def _bad_models(untrained: Path, root: Path) -> dict[str, tuple[Path, str]]:
    info = json.loads((untrained / "model.json").read_text())
    cases = {
        "not-json": ("{ nope", "not valid JSON"),
        "format": (json.dumps({**info, "format": "posbench-lstm"}), "posbench-hybrid"),
        "horizons": (json.dumps({**info, "horizons_s": [0.2, 0.4]}), "horizons_s"),
        "prior": (json.dumps({**info, "prior": {"predictor": "ekf"}}), "'prior'"),
        "kf-param": (
            json.dumps({**info, "prior": {"predictor": "kf", "params": {"native": {"warp": 1.0}}}}),
            "not a kf configuration",
        ),
        "kf-range": (
            json.dumps(
                {**info, "prior": {"predictor": "kf", "params": {"native": {"jerk_psd": -1.0}}}}
            ),
            "jerk_psd",
        ),
    }
    out = {}
    for name, (text, needle) in cases.items():
        d = root / name
        d.mkdir()
        shutil.copy(untrained / "model.onnx", d / "model.onnx")
        (d / "model.json").write_text(text)
        out[name] = (d, needle)
    d = root / "lstm-net"
    d.mkdir()
    from posbench.predictors.lstm.predictor import bundled_model

    shutil.copy(bundled_model(), d / "model.onnx")
    shutil.copy(untrained / "model.json", d / "model.json")
    out["lstm-net"] = (d, "no output 'correction'")
    return out


def test_a_bad_model_is_a_one_line_data_error(untrained, tmp_path):
    for name, (d, needle) in _bad_models(untrained, tmp_path).items():
        with pytest.raises(DataError) as ei:
            HybridPredictor(str(d))
        msg = str(ei.value)
        assert needle in msg and "\n" not in msg, (name, msg)
        pickle.loads(pickle.dumps(ei.value))


def test_a_bad_model_on_the_command_line_is_one_error_line(untrained, tmp_path):
    d, needle = _bad_models(untrained, tmp_path)["kf-param"]
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "posbench",
            "run",
            "-p",
            "hybrid",
            "--model",
            f"hybrid={d}",
            "--out",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], r.stderr
    assert "Traceback" not in r.stderr
