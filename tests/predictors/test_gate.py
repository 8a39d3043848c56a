"""The GPS outlier gate (replay.gps_outliers): what it rejects, what it never rejects, the
wrapper that hides rejected fixes from a predictor, and the runner / report / CLI wiring."""

from __future__ import annotations

import math

import numpy as np
import pytest

from posbench.aggregation.aggregate import gate_summary
from posbench.config import RunConfig
from posbench.predictors import registry
from posbench.predictors.base import Predictor
from posbench.replay.gps_outliers import FixGate, GatedPredictor
from posbench.replay.runner import run_drive
from posbench.report.sections import gate_lines
from posbench.scenarios.degrade import degrade_gps
from posbench.scenarios.drive import Drive, DriveMeta, GpsStream
from posbench.scenarios.errors import DataError
from posbench.scenarios.synthetic import generate_drive


def run_gate(gate: FixGate, t, x, y) -> np.ndarray:
    return np.array(
        [gate.check(float(a), float(b), float(c)) for a, b, c in zip(t, x, y, strict=True)]
    )


def line_fixes(
    n: int = 200,
    v: float = 9.0,
    dt: float = 0.2,
    noise: float = 0.0,
    seed: int = 0,
    jitter: float = 0.0,
):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt + rng.uniform(-jitter, jitter, n)
    x = v * t + rng.normal(0, noise, n) if noise else v * t
    y = rng.normal(0, noise, n) if noise else np.zeros(n)
    return t, x, y


@pytest.mark.parametrize("noise,dt", [(0.0, 0.1), (0.02, 0.1), (0.02, 0.2), (0.5, 0.2)])
def test_plain_noise_is_never_rejected(noise, dt):
    # rtk noise (2 cm) at 10 Hz, and 0.5 m consumer noise once the estimate has settled
    t, x, y = line_fixes(600, noise=noise, dt=dt, seed=3)
    g = FixGate()
    ok = run_gate(g, t, x, y)
    assert ok.all(), np.flatnonzero(~ok)
    assert g.rejected == 0 and g.accepted == t.size


def test_synthetic_drives_pass_untouched_under_every_profile():
    d = generate_drive(seed=2, route="mixed")
    for profile in ("none", "rtk", "consumer"):
        gps = degrade_gps(d.truth, profile=profile, seed=5)
        g = FixGate()
        run_gate(g, gps.t, gps.x, gps.y)
        assert g.rejected == 0, profile


def test_single_jump_is_rejected_and_the_next_fix_accepted():
    t, x, y = line_fixes(60, v=9.0)
    x = x.copy()
    x[30] += 8.0  # one fix 8 m off (= 40 m/s extra over 0.2 s)
    g = FixGate()
    ok = run_gate(g, t, x, y)
    assert np.flatnonzero(~ok).tolist() == [30]
    assert g.rejected == 1


def test_speed_limit_alone_rejects():
    g = FixGate(accel_limit=1e4, speed_limit=50.0)
    assert g.check(0.0, 0.0, 0.0)
    assert not g.check(1.0, 70.0, 0.0)  # 70 m/s from the only fix
    assert g.check(2.0, 20.0, 0.0)


def test_stale_repeat_while_moving_is_rejected_but_not_at_standstill():
    # the paper's routes: a fix repeated unchanged 0.16 s later, the real one 0.04 s after
    t = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2, 2.36, 2.4, 2.6]
    x = [9.0 * s for s in t]
    x[12] = x[11]  # stale
    g = FixGate()
    ok = run_gate(g, t, x, [0.0] * len(t))
    assert np.flatnonzero(~ok).tolist() == [12]
    # standing still: identical fixes are what a parked receiver reports
    g = FixGate()
    assert run_gate(g, np.arange(50) * 0.1, np.zeros(50), np.zeros(50)).all()


def test_persistent_jump_is_followed_after_max_consecutive():
    t, x, y = line_fixes(40, v=5.0)
    x = x.copy()
    x[20:] += 30.0  # the receiver re-converged 30 m away: genuine from here on
    g = FixGate(max_consecutive=3)
    ok = run_gate(g, t, x, y)
    assert np.flatnonzero(~ok).tolist() == [20, 21, 22]
    assert g.resets == 1 and ok[23:].all()


def test_first_fix_outlier_is_recovered():
    t, x, y = line_fixes(30, v=5.0)
    x = x.copy()
    x[0] = 500.0
    g = FixGate()
    ok = run_gate(g, t, x, y)
    assert not ok[1:4].any() and ok[4:].all()


def test_long_outage_then_return_is_accepted():
    g = FixGate()
    t, x, y = line_fixes(30, v=10.0)
    assert run_gate(g, t, x, y).all()
    # 30 s without fixes, the car turned and slowed meanwhile: the return is plausible
    assert g.check(t[-1] + 30.0, x[-1] + 150.0, 120.0)


def test_unjudgeable_fixes_pass_through():
    g = FixGate()
    assert g.check(0.0, 0.0, 0.0)
    assert g.check(1.0, math.nan, 0.0)
    assert g.check(0.0, 999.0, 0.0)  # not after the anchor: not the gate's business
    assert g.check(-1.0, 999.0, 0.0)
    assert g.rejected == 0


def test_bad_configuration_is_a_data_error():
    with pytest.raises(DataError, match="speed_limit"):
        FixGate(speed_limit=-1.0)


class Recorder(Predictor):
    name = "rec"

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.gps, self.imu, self.speed, self.resets = [], [], [], getattr(self, "resets", 0) + 1

    def observe_gps(self, t, x, y):
        self.gps.append(t)

    def observe_imu(self, t, ax, ay, yaw, yaw_rate):
        self.imu.append(t)

    def observe_speed(self, t, v):
        self.speed.append(t)

    def position_at(self, t):
        return (t, -t)

    def config(self):
        return {"k": 1}


def test_wrapper_forwards_everything_but_rejected_fixes():
    inner = Recorder()
    p = GatedPredictor(inner)
    assert p.name == "rec"
    p.reset()
    for i in range(10):
        p.observe_gps(0.2 * i, 2.0 * i if i != 5 else 50.0, 0.0)
        p.observe_imu(0.2 * i + 0.1, 0.0, 0.0, 0.0, 0.0)
        p.observe_speed(0.2 * i + 0.1, 10.0)
    assert inner.gps == [0.2 * i for i in range(10) if i != 5]
    assert len(inner.imu) == 10 and len(inner.speed) == 10
    assert p.position_at(3.0) == (3.0, -3.0)
    assert p.rejected == 1
    assert p.config() == {"k": 1, "gate": FixGate().config()}
    p.reset()
    assert p.rejected == 0 and inner.gps == []


@pytest.mark.parametrize("name", ["cv", "kf", "ekf"])
def test_gated_predictor_ignores_a_jump_the_bare_one_follows(name):
    t, x, y = line_fixes(40, v=9.0)
    x = x.copy()
    x[25] += 20.0
    out = {}
    for gated in (False, True):
        p = registry.create(name)
        p = GatedPredictor(p) if gated else p
        p.reset()
        for i in range(26):
            p.observe_gps(t[i], x[i], y[i])
        out[gated] = p.position_at(t[25] + 0.2)[0] - 9.0 * (t[25] + 0.2)
    assert abs(out[True]) < 0.5 < abs(out[False])


def _jumpy_drive() -> Drive:
    t, x, y = line_fixes(300, v=9.0)
    x = x.copy()
    x[[50, 120, 200]] += 12.0
    return Drive(DriveMeta("jumpy", "mem", "test", projection="source"), GpsStream(t, x, y))


def test_runner_counts_rejections_and_no_gate_turns_it_off():
    d = _jumpy_drive()
    cfg = RunConfig(predictors=("cv", "poly"), gps_profile="native")
    on = run_drive(d, cfg)
    assert on.rejected == {"cv": 3, "poly": 3}
    off = run_drive(d, RunConfig(predictors=("cv", "poly"), gps_profile="native", gate=False))
    assert off.rejected == {}
    # the reference (cubic through all fixes) is the same: scoring is never gated
    for kind in ("future", "now"):
        a = on.traces[(on.traces.kind == kind) & (on.traces.predictor == "cv")]
        b = off.traces[(off.traces.kind == kind) & (off.traces.predictor == "cv")]
        np.testing.assert_array_equal(a.x_ref.to_numpy(), b.x_ref.to_numpy())
    # the predictions differ around the jumps: the gated cv never chases them
    fa = on.traces[(on.traces.kind == "future") & (on.traces.predictor == "cv")].iloc[1:]
    fb = off.traces[(off.traces.kind == "future") & (off.traces.predictor == "cv")].iloc[1:]
    assert (
        np.nanmax(np.abs(fa.x - 9.0 * fa.t_query))
        < 0.5
        < np.nanmax(np.abs(fb.x - 9.0 * fb.t_query))
    )

    summ = gate_summary([on], cfg)
    assert summ["predictors"]["cv"] == {
        "rejected": 3,
        "fixes_fed": 300,
        "drives_with_rejections": 1,
    }
    res = {"gate": summ, "drives": [{"name": "jumpy", "gps_fed": 300, "rejected": on.rejected}]}
    text = "\n".join(gate_lines(res))
    assert "fixes rejected per predictor" in text and "| cv | 3 | 300 | 1.00 | 1 |" in text
    assert "| jumpy | 300 | 3 | 3 |" in text
    off_text = "\n".join(
        gate_lines({"gate": gate_summary([off], RunConfig(gate=False)), "drives": []})
    )
    assert "--no-gate" in off_text


def test_cli_no_gate_flag(tmp_path, monkeypatch):
    import posbench.cli.app as cli
    import posbench.cli.summary as summary
    import posbench.pipeline.run as pipeline

    seen = {}

    def fake_execute(plan, command, reporter):
        seen["gate"] = plan.config.gate

    monkeypatch.setattr(pipeline, "execute_run", fake_execute)
    monkeypatch.setattr(summary, "print_run_summary", lambda published, wide=False: None)
    from typer.testing import CliRunner

    for flag, want in (([], True), (["--no-gate"], False), (["--gate"], True)):
        r = CliRunner().invoke(cli.app, ["run", "-p", "cv", "--out", str(tmp_path)] + flag)
        assert r.exit_code == 0, r.output
        assert seen["gate"] is want
