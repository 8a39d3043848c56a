"""The runner: event order, no future information, references, worker-count invariance."""

from __future__ import annotations

import numpy as np
import pytest

from posbench.config import RunConfig
from posbench.predictors.base import Predictor
from posbench.predictors.catalogue import register
from posbench.replay.loop import replay
from posbench.replay.prepare import prepare_drive
from posbench.replay.reference import cubic_through_fixes, truth_at
from posbench.replay.runner import run
from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, ImuStream, SpeedStream


class SpyPredictor(Predictor):
    """Records every call; fails if asked about a time before its newest observation."""

    name = "spy"

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.last_obs = -np.inf
        self.last = (np.nan, np.nan)
        self.violations = 0
        self.calls = 0

    def _obs(self, t: float) -> None:
        assert t >= self.last_obs, "observations out of time order"
        self.last_obs = t

    def observe_gps(self, t, x, y):
        self._obs(t)
        self.last = (x, y)

    def observe_imu(self, t, ax, ay, yaw, yaw_rate):
        self._obs(t)

    def observe_speed(self, t, v):
        self._obs(t)

    def position_at(self, t):
        self.calls += 1
        if t < self.last_obs:
            self.violations += 1
        return self.last


class LineOracle(Predictor):
    """Knows the motion is x = 10 t: a perfect constant-velocity extrapolator from the last fix."""

    name = "line"

    def __init__(self) -> None:
        self.reset()

    def reset(self):
        self.t = self.x = self.y = np.nan

    def observe_gps(self, t, x, y):
        self.t, self.x, self.y = t, x, y

    def position_at(self, t):
        return (self.x + 10.0 * (t - self.t), self.y)


register("spy", "test_runner:SpyPredictor", "test spy")
register("line", "test_runner:LineOracle", "test oracle")


def line_drive(name: str = "line", seed: int = 0, n: int = 200) -> Drive:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.1, 0.4, n))
    imu_t = np.arange(t[0], t[-1], 0.02)
    sp_t = np.arange(t[0], t[-1], 0.05)
    return Drive(
        DriveMeta(name, "mem", "test", projection="source"),
        GpsStream(t, 10.0 * t, np.zeros(n)),
        ImuStream(imu_t, np.zeros_like(imu_t), np.zeros_like(imu_t)),
        SpeedStream(sp_t, np.full_like(sp_t, 10.0)),
    )


def test_no_observation_after_query_time():
    prep = prepare_drive(line_drive(), RunConfig(predictors=("spy",)))
    spy = SpyPredictor()
    res = replay(spy, prep, horizon_s=0.2)
    assert spy.calls == len(prep.gps) + prep.now.t_query.size
    assert spy.violations == 0
    assert res.step_ns.min() > 0 and res.query_ns.min() > 0


def test_line_oracle_is_exact_against_fix_cubic_reference():
    cfg = RunConfig(predictors=("line",))
    [r] = run([line_drive()], cfg)
    fut = r.traces[r.traces.kind == "future"]
    ok = fut.error_m.notna()
    assert ok.sum() > 150  # ends lack fixes on both sides
    assert fut.error_m[ok].max() < 1e-9
    assert r.reference == "cubic through surrounding fixes"


def test_truth_reference_interpolates():
    t = np.arange(0, 10, 0.1)
    ref = truth_at(t, 3 * t**2, -t, np.array([1.05, 5.55, 20.0]))
    assert ref[0] == pytest.approx([3 * 1.05**2, -1.05], abs=1e-9)
    assert ref[1] == pytest.approx([3 * 5.55**2, -5.55], abs=1e-9)
    assert np.all(np.isnan(ref[2]))


@pytest.mark.parametrize("block", [100, 1000, 4096])
def test_a_long_truth_splined_in_blocks_answers_as_the_whole_spline(block):
    """A truth longer than max_samples is splined a block at a time (hours of truth at
    100-200 Hz): at queries anywhere (outside the truth, on its samples, at its ends, in a
    gap longer than max_gap_s) it answers what one spline through all of it answers, to
    1e-9 m (measured: to the bit), NaN where that is NaN."""
    rng = np.random.default_rng(3)
    n = 20_000
    t = np.cumsum(rng.uniform(0.004, 0.006, n))
    t[n // 2 :] += 2.0  # a gap of 2 s
    x = np.cumsum(rng.normal(0, 0.05, n)) + 10 * np.sin(t / 7)
    y = np.cumsum(rng.normal(0, 0.05, n)) + 5 * np.cos(t / 3)
    tq = np.concatenate(
        [rng.uniform(t[0] - 1, t[-1] + 1, 5000), t[:20], t[-20:], t[n // 2 - 1 : n // 2 + 1]]
    )
    whole = truth_at(t, x, y, tq)
    blocks = truth_at(t, x, y, tq, max_samples=1000, block=block)
    np.testing.assert_array_equal(np.isnan(blocks), np.isnan(whole))
    ok = np.isfinite(whole)
    assert ok.sum() > 4000
    assert np.max(np.abs(blocks[ok] - whole[ok])) <= 1e-9


def test_cubic_through_fixes_is_exact_on_a_cubic():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.1, 0.4, 60))
    x, y = 0.5 * t**3 - t, 2 * t**2
    tq = np.linspace(t[5], t[-6], 40)
    ref = cubic_through_fixes(t, x, y, tq)
    assert np.allclose(ref[:, 0], 0.5 * tq**3 - tq, atol=1e-6)
    assert np.allclose(ref[:, 1], 2 * tq**2, atol=1e-6)


def test_results_identical_across_worker_counts():
    drives = [line_drive(f"d{i}", seed=i, n=80) for i in range(3)]
    cfg = RunConfig(predictors=("line", "spy"))
    a = run(drives, cfg, workers=1)
    b = run(drives, cfg, workers=2)
    for ra, rb in zip(a, b, strict=True):
        assert ra.name == rb.name
        np.testing.assert_array_equal(ra.traces.error_m.to_numpy(), rb.traces.error_m.to_numpy())


@pytest.mark.slow
def test_real_predictors_identical_across_worker_counts():
    from posbench.scenarios.synthetic import default_drives

    drives = default_drives(seed=3)[:2]
    cfg = RunConfig(predictors=("cv", "kf", "ekf"), gps_profile="consumer", dropouts="outages")
    a = run(drives, cfg, workers=1)
    b = run(drives, cfg, workers=2)
    for ra, rb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ra.traces.error_m.to_numpy(), rb.traces.error_m.to_numpy())
        assert ra.outages == rb.outages and len(ra.outages) > 0


def test_degraded_gps_depends_on_seed_not_workers():
    from posbench.scenarios.synthetic import default_drives

    d = default_drives()[0]
    p1 = prepare_drive(d, RunConfig(seed=1))
    p2 = prepare_drive(d, RunConfig(seed=1))
    p3 = prepare_drive(d, RunConfig(seed=2))
    np.testing.assert_array_equal(p1.gps.x, p2.gps.x)
    assert p1.gps.t.size != p3.gps.t.size or not np.array_equal(p1.gps.x, p3.gps.x)


def test_drive_window_cuts_every_stream():
    d = line_drive(n=100)
    w = d.window(5.0, 10.0)
    for s in (w.gps, w.imu, w.speed):
        assert s.t.min() >= 5.0 and s.t.max() <= 10.0 and len(s) > 0
    assert w.name == d.name


@pytest.mark.parametrize("events", [1, 5, 64, 1000, 1 << 30])
def test_event_windows_are_the_events_in_replay_order(events):
    """The replay orders its events one time window at a time (a long drive's event list is
    never held whole): the same (kind, index) sequence as ordering them all at once, also
    where streams share times (IMU, speed and now queries on common grids) and a window's
    cut falls on them."""
    from posbench.replay.loop import build_events, event_windows

    prep = prepare_drive(line_drive(n=300), RunConfig(predictors=("spy",), now_step_s=0.02))
    kinds, idxs = build_events(prep)
    windows = list(event_windows(prep, events))
    assert len(windows) >= min(kinds.size // max(events, 1) // 2, 10)
    np.testing.assert_array_equal(np.concatenate([w[0] for w in windows]), kinds)
    np.testing.assert_array_equal(np.concatenate([w[1] for w in windows]), idxs)
