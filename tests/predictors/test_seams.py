"""Public seams instead of reach-ins: the lstm's stage-timer hook and last step, the
predictors' model description / training drives, and the gate forwarding them."""

from __future__ import annotations

import copy
import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from posbench.config import RunConfig
from posbench.predictors.base import Predictor
from posbench.predictors.lstm.predictor import (
    BUNDLED_TEXT,
    FUSED_STAGES,
    STAGES,
    LstmPredictor,
    LstmStep,
    StageRecorder,
    bundled_model,
)
from posbench.predictors.lstm.resample import DT, GRID_OFFSETS, MIN_SPAN_S, FixedGridFit
from posbench.predictors.registry import create
from posbench.replay.gps_outliers import GatedPredictor
from posbench.replay.loop import replay
from posbench.replay.predictor_setup import learned_models
from posbench.replay.prepare import prepare_drive
from posbench.scenarios.synthetic import generate_drive


@pytest.fixture(scope="module")
def prepared():
    # synthetic fixes with dropouts: the "now" queries run bridging steps in position_at
    return prepare_drive(generate_drive(seed=7, route="mixed", duration_s=40.0), RunConfig())


class _CallLog:
    """A stage hook that logs (stage, duration [ns], the predictor's step count then)."""

    def __init__(self, p: LstmPredictor) -> None:
        self.p = p
        self.calls: list[tuple[str, int, int]] = []

    def __call__(self, stage: str, ns: int) -> None:
        self.calls.append((stage, ns, self.p.steps))


@pytest.mark.parametrize("step", ["fused", "staged"])
def test_stage_timer_reports_each_stage_once_per_fix_step(prepared, step) -> None:
    p = LstmPredictor(step=step)
    assert p.stages == (FUSED_STAGES if step == "fused" else STAGES)
    log = _CallLog(p)
    p.stage_timer = log
    g = prepared.gps
    per_fix = []
    bridged = 0
    for i in range(len(g)):
        n0, s0 = len(log.calls), p.steps
        p.observe_gps(float(g.t[i]), float(g.x[i]), float(g.y[i]))
        per_fix.append((log.calls[n0:], p.steps - s0))
        # a query well past the prediction bridges: those steps report no stages
        n1, b0 = len(log.calls), p.bridge_steps
        p.position_at(float(g.t[i]) + 0.7)
        bridged += p.bridge_steps - b0
        assert len(log.calls) == n1
        p.observe_gps(float(g.t[i]), float(g.x[i]), float(g.y[i]))  # a real fix again
    stepped = [calls for calls, n in per_fix if n == 1]
    assert bridged > 0 and len(stepped) > 100
    for calls, n in per_fix:
        if n == 0:  # start-up line fit: no network step, nothing reported
            assert calls == []
    for calls in stepped:
        assert [c[0] for c in calls] == list(p.stages)
        assert all(isinstance(ns, int) and ns > 0 for _, ns, _ in calls)
        # current_position_fit is reported once the step has completed
        assert calls[-1][2] == calls[0][2] + 1


@pytest.mark.parametrize("step", ["fused", "staged"])
def test_stage_timer_is_none_by_default_and_changes_no_answer(prepared, step) -> None:
    plain = LstmPredictor(step=step)
    assert plain.stage_timer is None and LstmPredictor.stage_timer is None
    timed = LstmPredictor(step=step)
    rec = StageRecorder()
    timed.stage_timer = rec
    a = replay(plain, prepared, 0.2)
    b = replay(timed, prepared, 0.2)
    np.testing.assert_array_equal(a.future_xy, b.future_xy)
    np.testing.assert_array_equal(a.now_xy, b.now_xy)
    assert len(rec.ns["inference"]) > 100
    n = len(rec.ns["inference"])
    assert {k: len(v) for k, v in rec.ns.items() if v} == {s: n for s in timed.stages}
    rec.clear()
    assert all(not v for v in rec.ns.values())


def test_last_step_is_the_step_behind_the_future_answer(prepared) -> None:
    p = LstmPredictor()
    assert p.last_step() is None
    g = prepared.gps
    # always moving: no standstill hold stands in for the network's answer
    assert (np.hypot(np.diff(g.x), np.diff(g.y)) / np.diff(g.t)).min() > 1.0
    final = FixedGridFit(np.append(GRID_OFFSETS, DT))
    checked = 0
    held: LstmStep | None = None
    for i in range(len(g)):
        t = float(g.t[i])
        p.observe_gps(t, float(g.x[i]), float(g.y[i]))
        step = p.last_step()
        if t - float(g.t[0]) < MIN_SPAN_S:  # fixes span < 2 s: start-up line
            assert step is None
            continue
        assert step.t_fix == t and step.horizon_s == DT and not step.bridged
        assert step.grid.shape == (8, 2) and step.pred.shape == (2,)
        # the future answer is the cubic through exactly these 8 inputs and the prediction
        cf = final.fit(np.vstack([step.grid, step.pred]))
        want = cf[0] + cf[1] * DT + cf[2] * DT**2 + cf[3] * DT**3
        got = p.position_at(t + DT)
        np.testing.assert_allclose(got, want, atol=1e-9)
        assert np.hypot(*(np.asarray(got) - step.pred)) < 0.05  # and it is near the prediction
        assert np.hypot(step.grid[-1, 0] - g.x[i], step.grid[-1, 1] - g.y[i]) < 0.2
        held = held or step
        checked += 1
    assert checked > 100 and held is not None
    # copies, read-only: later steps do not change a step already handed out
    before = held.grid.copy()
    assert not held.grid.flags.writeable and not held.pred.flags.writeable
    assert not np.shares_memory(held.grid, p.last_step().grid)
    np.testing.assert_array_equal(held.grid, before)
    with pytest.raises(AttributeError):
        held.t_fix = 0.0  # type: ignore[misc]
    # a query far past the prediction bridges: the newest step is a bridged one
    t_last = float(g.t[-1])
    p.position_at(t_last + 1.0)
    step = p.last_step()
    assert step.bridged and step.t_fix > t_last
    p.reset()
    assert p.last_step() is None


def test_bundled_model_declares_its_training_drives() -> None:
    p = LstmPredictor()
    info = json.loads(bundled_model().with_suffix(".json").read_text())
    assert p.training_drives() and isinstance(p.training_drives(), tuple)
    assert list(p.training_drives()) == info["data"]["train_drives"]
    assert p.model_description() == {"model": BUNDLED_TEXT, "bundled": True}
    assert BUNDLED_TEXT == "bundled (predictors/lstm/bundled/model.onnx)"


def test_models_without_learning_declare_nothing() -> None:
    for name in ("cv", "kf-paper"):
        p = create(name)
        assert p.model_description() is None and p.training_drives() == ()


def test_authors_model_records_no_training_drives(authors_models_dir) -> None:
    path = authors_models_dir / "gps_interpolation_model3.onnx"
    p = create("lstm-authors", model=str(path))
    assert p.training_drives() == ()
    assert p.model_description() == {"model": str(path), "bundled": False}


def _model_copy(tmp_path: Path, train_drives: list[str]) -> Path:
    dst = tmp_path / "my-model"
    shutil.copytree(bundled_model().parent, dst)
    info = json.loads((dst / "model.json").read_text())
    info["data"]["train_drives"] = train_drives
    (dst / "model.json").write_text(json.dumps(info))
    return dst


def test_learned_models_asks_the_predictors(tmp_path) -> None:
    model = _model_copy(tmp_path, ["a", "b"])
    cfg = RunConfig(
        predictors=("cv", "lstm", "lstm@mine"),
        predictor_options={"lstm@mine": {"model": str(model)}},
    )
    out = learned_models(cfg)
    bundled = list(LstmPredictor().training_drives())
    assert out == {
        "lstm": {
            "model": "bundled (predictors/lstm/bundled/model.onnx)",
            "bundled": True,
            "train_drives": bundled,
        },
        "lstm@mine": {
            "model": str(model / "model.onnx"),
            "bundled": False,
            "train_drives": ["a", "b"],
        },
    }


class Learned(Predictor):
    """A picklable predictor with the optional seams (module level, so pickle finds it)."""

    name = "learned"

    def __init__(self) -> None:
        self.fixes: list[float] = []
        self.knob = 1

    def reset(self) -> None:
        self.fixes = []

    def observe_gps(self, t: float, x: float, y: float) -> None:
        self.fixes.append(t)

    def position_at(self, t: float) -> tuple[float, float]:
        return (t, 0.0)

    def training_drives(self) -> tuple[str, ...]:
        return ("d1", "d2")

    def model_description(self) -> dict:
        return {"model": "m.onnx", "bundled": False}

    def last_step(self) -> tuple[float, ...]:
        return tuple(self.fixes)


def test_gate_forwards_the_seams_and_pickles() -> None:
    g = GatedPredictor(Learned())
    g.reset()
    for i in range(5):
        g.observe_gps(0.2 * i, 2.0 * i, 0.0)
    assert g.training_drives() == ("d1", "d2")
    assert g.model_description() == {"model": "m.onnx", "bundled": False}
    assert g.last_step() == tuple(0.2 * i for i in range(5))
    g.knob = 5  # a name the wrapped predictor has is set there
    assert g.inner.knob == 5 and "knob" not in vars(g)
    g.mine = 3  # one it lacks stays the gate's
    assert g.mine == 3 and not hasattr(g.inner, "mine")
    with pytest.raises(AttributeError, match="nothing"):
        _ = g.nothing
    for h in (pickle.loads(pickle.dumps(g)), copy.deepcopy(g)):
        assert type(h) is GatedPredictor and h.inner is not g.inner
        assert h.last_step() == g.last_step() and h.training_drives() == ("d1", "d2")
        assert h.gate.accepted == g.gate.accepted == 5 and h.knob == 5
        h.observe_gps(1.0, 10.0, 0.0)  # the copy's bound hot-path methods are its own
        assert h.position_at(1.2) == (1.2, 0.0)
        assert len(h.inner.fixes) == 6 and len(g.inner.fixes) == 5
    # a model-less predictor behind the gate keeps the base's answers
    plain = GatedPredictor(create("cv"))
    assert plain.training_drives() == () and plain.model_description() is None


def test_gate_forwards_the_lstm_seams(prepared) -> None:
    g = GatedPredictor(LstmPredictor())
    rec = StageRecorder()
    g.stage_timer = rec
    assert g.inner.stage_timer is rec and "stage_timer" not in vars(g)
    replay(g, prepared, 0.2)
    assert len(rec.ns["inference"]) > 100
    assert g.training_drives() == LstmPredictor().training_drives()
    assert g.model_description() == {"model": BUNDLED_TEXT, "bundled": True}
    step = g.last_step()
    assert isinstance(step, LstmStep)
    np.testing.assert_array_equal(step.grid, g.inner.last_step().grid)
    assert g.steps == g.inner.steps > 0


def test_latency_stages_use_the_hook() -> None:
    from posbench.predictor_tools.latency import lstm_fused_stages, lstm_stages

    drive = generate_drive(seed=3, route="mixed", duration_s=20.0)
    fused = lstm_fused_stages(drive, 30)
    assert list(fused) == list(FUSED_STAGES)
    assert all(fused[s]["count"] == 30 and fused[s]["p50"] > 0 for s in FUSED_STAGES)
    out = lstm_stages(drive, 30)
    assert list(out) == [*STAGES, "cubic_fit_closed_form", "cubic_fit_lbfgs"]
    for s in STAGES:
        assert out[s]["count"] == 30 and out[s]["p50"] > 0
    assert out["cubic_fit_closed_form"]["count"] == 30
    assert out["cubic_fit_lbfgs"]["p50"] > out["cubic_fit_closed_form"]["p50"]
