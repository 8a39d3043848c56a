"""Outage-length figures (posbench.metrics.outage_lengths) against hand-computed drives."""

from __future__ import annotations

import math

import numpy as np

from posbench.metrics.outage_lengths import (
    length_classes,
    length_figures,
    path_lengths,
    per_outage_ate,
)

V_MPS = 10.0


def _straight(t0: float = 0.0, t1: float = 100.0, dt: float = 0.05):
    """A straight drive east at V_MPS: (t [s], x, y [m])."""
    t = np.arange(t0, t1 + dt / 2, dt)
    return t, V_MPS * t, np.zeros_like(t)


def test_path_length_of_a_straight_line_is_speed_times_time():
    t, x, y = _straight()
    d = path_lengths(t, x, y, np.array([10.0, 20.02, 0.0]), np.array([15.0, 50.0, 100.0]))
    np.testing.assert_allclose(d, [50.0, 299.8, 1000.0], atol=1e-9)  # ends interpolated


def test_path_length_follows_the_path_not_the_chord():
    # a half circle of radius 10 m driven in 10 s: path pi*10, chord 20
    t = np.linspace(0.0, 10.0, 2001)
    ang = np.pi * t / 10.0
    d = path_lengths(t, 10 * np.cos(ang), 10 * np.sin(ang), np.array([0.0]), np.array([10.0]))
    assert math.isclose(d[0], 10 * np.pi, rel_tol=1e-5)


def test_path_length_outside_the_track_is_nan():
    t, x, y = _straight(5.0, 50.0)
    d = path_lengths(t, x, y, np.array([1.0, 10.0]), np.array([10.0, 60.0]))
    assert np.isnan(d).all()


def test_length_classes_take_the_longest_length_an_outage_reaches():
    lengths = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0)
    got = length_classes(np.array([0.9, 1.0, 1.3, 2.15, 9.99, 10.2, 65.0]), lengths)
    np.testing.assert_array_equal(got[1:], [1.0, 1.0, 2.0, 5.0, 10.0, 60.0])
    assert np.isnan(got[0])


def test_fde_ate_and_percent_of_distance_on_a_straight_drive():
    """Fix at t = 10 s, outage queries every 0.05 s to 15 s; the predictor falls behind by
    0.5 m per second without GPS: error 0.5 (t - 10). FDE = 2.5 m after 50 m driven: 5 %; ATE
    = RMS of 0.5 (t - 10) over the queries; a second outage (30 s, drift 1 m/s) at 300 m:
    FDE 30 m. Over both: 100 (2.5 + 30) / (50 + 300) %."""
    t, x, y = _straight()
    q1 = np.arange(10.05, 15.0 + 1e-9, 0.05)
    q2 = np.arange(40.05, 70.0 + 1e-9, 0.05)
    tq = np.concatenate([q1, q2])
    err = np.concatenate([0.5 * (q1 - 10.0), 1.0 * (q2 - 40.0)])
    ids = np.concatenate([np.zeros(q1.size, int), np.ones(q2.size, int)])
    ids_with_others = np.concatenate([ids, [-1, -1]])  # queries outside outages: left out
    uid, fde, ate, t_end = per_outage_ate(
        np.concatenate([err, [99.0, 99.0]]), np.concatenate([tq, [1.0, 2.0]]), ids_with_others
    )
    np.testing.assert_array_equal(uid, [0, 1])
    np.testing.assert_allclose(fde, [2.5, 30.0])
    np.testing.assert_allclose(
        ate, [np.sqrt(np.mean((0.5 * (q1 - 10)) ** 2)), np.sqrt(np.mean((q2 - 40) ** 2))]
    )
    np.testing.assert_allclose(t_end, [15.0, 70.0])
    dist = path_lengths(t, x, y, np.array([10.0, 40.0]), t_end)
    np.testing.assert_allclose(dist, [50.0, 300.0])
    one = length_figures(fde[:1], ate[:1], dist[:1])
    assert math.isclose(one["fde_pct"], 5.0) and one["outages"] == 1
    both = length_figures(fde, ate, dist)
    assert math.isclose(both["fde_pct"], 100 * 32.5 / 350)  # a ratio of sums
    assert math.isclose(both["fde_mean_m"], 16.25) and math.isclose(both["distance_mean_m"], 175)
    assert math.isclose(both["ate_pct"], 100 * ate.sum() / 350)


def test_an_outage_at_standstill_adds_its_error_and_no_distance():
    f = length_figures(np.array([1.0, 0.2]), np.array([0.5, 0.1]), np.array([20.0, 0.0]))
    assert math.isclose(f["fde_pct"], 100 * 1.2 / 20)
    stopped = length_figures(np.array([0.2]), np.array([0.1]), np.array([0.0]))
    assert math.isnan(stopped["fde_pct"]) and stopped["fde_mean_m"] == 0.2
    none = length_figures(np.empty(0), np.empty(0), np.empty(0))
    assert none["outages"] == 0 and math.isnan(none["fde_mean_m"])
