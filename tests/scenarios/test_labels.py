"""Scenario labels on drives with known manoeuvres."""

from __future__ import annotations

import numpy as np
import pytest

from posbench.scenarios.errors import DataError
from posbench.scenarios.labels import LABELS, LabelThresholds, label_shares, label_times
from posbench.scenarios.synthetic import generate_drive
from posbench.scenarios.synthetic_motion import simulate, stop, straight, turn


def _roundabout() -> list:
    return [
        turn(-35, 11, 6.0, "roundabout"),
        turn(270, 18, 7.0, "roundabout"),
        turn(-35, 11, 6.0, "roundabout"),
    ]


ROUTE = [
    straight(150, 14),
    turn(90, 12, 6.0),
    straight(150, 14),
    *_roundabout(),
    straight(150, 14),
    stop(6.0),
    straight(150, 14),
    turn(-90, 10, 5.5),
    straight(100, 13),
]


@pytest.fixture(scope="module")
def sim():
    return simulate(ROUTE, yaw0=0.3)


def _interior(label: str, a: float, b: float) -> tuple[float, float]:
    """The part of a segment a label must hold: straights keep clear of the neighbouring
    manoeuvres (transition curves, braking within 3 s of a stop)."""
    trim = 4.0 if label == "straight" else 0.5
    return a + trim, b - trim


def _check_segments(t: np.ndarray, labels: np.ndarray, segments: list) -> None:
    seen = set()
    for lab, a, b in segments:
        lo, hi = _interior(lab, a, b)
        m = (t >= lo) & (t <= hi)
        if m.sum() < 20:
            continue
        share = np.mean(labels[m] == lab)
        assert share > 0.9, (lab, a, b, share)
        seen.add(lab)
    assert seen == set(LABELS)


def test_truth_labels_match_segments(sim) -> None:
    labels = label_times(sim.t, sim.t, sim.x, sim.y)
    assert labels.dtype == np.dtype("<U10")
    assert labels.shape == sim.t.shape
    _check_segments(sim.t, labels, sim.segments)


def test_labels_from_gps_fixes_with_can_speed() -> None:
    d = generate_drive(2, route="mixed")
    tq = d.truth.t[::10]
    labels = label_times(tq, d.gps.t, d.gps.x, d.gps.y, d.speed.t, d.speed.v)
    _check_segments(tq, labels, d.meta.extra["segments"])
    truth_labels = label_times(tq, d.truth.t, d.truth.x, d.truth.y)
    assert np.mean(labels == truth_labels) > 0.95


def test_start_stop_around_standstill(sim) -> None:
    labels = label_times(sim.t, sim.t, sim.x, sim.y)
    a, b = next((a, b) for lab, a, b in sim.segments if lab == "start_stop")
    # braking just before the standstill and pulling away after it are start_stop too
    for tq in (a - 1.0, b + 1.0):
        assert label_times(np.array([tq]), sim.t, sim.x, sim.y)[0] == "start_stop"
    # far from it, cruising is straight
    assert labels[np.searchsorted(sim.t, a - 9.0)] == "straight"


def test_speed_stream_drives_standstill() -> None:
    t = np.arange(0.0, 60.0, 0.1)
    x = np.where(t < 20, 10 * t, 200.0 + 10 * np.clip(t - 30, 0, None))
    y = np.zeros_like(t)
    # a speed sensor saying 0 during [20, 30] (position stands still there too)
    v = np.where((t >= 20) & (t < 30), 0.0, 10.0)
    labels = label_times(t, t, x, y, t, v)
    assert np.all(labels[(t > 21) & (t < 29)] == "start_stop")
    assert np.all(labels[(t > 5) & (t < 15)] == "straight")


def test_city_block_loop_is_turns_not_roundabout() -> None:
    # four left 90-deg turns at r = 10 m within ~30 s: 360 deg, but separate turns
    segs = (
        [straight(60, 10)]
        + [seg for _ in range(4) for seg in (turn(90, 10, 5.0), straight(25, 8))]
        + [straight(60, 10)]
    )
    s = simulate(segs)
    labels = label_times(s.t, s.t, s.x, s.y)
    assert "roundabout" not in set(labels)
    assert np.mean(labels == "turn") > 0.2


def test_wide_circle_is_turn_not_roundabout() -> None:
    s = simulate([straight(80, 10), turn(300, 60, 12.0), straight(80, 10)])
    labels = label_times(s.t, s.t, s.x, s.y)
    a, b = s.segments[1][1:]
    m = (s.t > a + 1) & (s.t < b - 1)
    assert np.mean(labels[m] == "turn") > 0.9
    assert "roundabout" not in set(labels)


def test_thresholds_change_labels(sim) -> None:
    strict = LabelThresholds(roundabout_heading_deg=400.0)
    labels = label_times(sim.t, sim.t, sim.x, sim.y, thresholds=strict)
    assert "roundabout" not in set(labels)
    assert "turn" in set(labels)


def test_query_edges_and_errors(sim) -> None:
    out = label_times(np.array([-5.0, 1e6]), sim.t, sim.x, sim.y)
    full = label_times(sim.t[[0, -1]], sim.t, sim.x, sim.y)
    assert list(out) == list(full)
    assert label_times(np.array([]), sim.t, sim.x, sim.y).shape == (0,)
    with pytest.raises(DataError):
        label_times(np.array([0.0]), np.array([1.0, 0.0]), np.zeros(2), np.zeros(2))
    with pytest.raises(DataError):
        label_times(np.array([0.0]), np.arange(3.0), np.zeros(2), np.zeros(3))


def test_label_shares() -> None:
    labels = np.array(["straight", "turn", "turn", "start_stop"], dtype="<U10")
    sh = label_shares(labels)
    assert set(sh) == set(LABELS)
    assert sh["turn"] == 0.5 and sh["roundabout"] == 0.0
    assert abs(sum(sh.values()) - 1.0) < 1e-12
    assert label_shares(np.array([], dtype="<U10"))["straight"] == 0.0
