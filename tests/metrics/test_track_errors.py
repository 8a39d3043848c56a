"""Along/cross-track decomposition (metrics.track_errors): signs, turns and standstill."""

from __future__ import annotations

import numpy as np
import pytest

from posbench.metrics.track_errors import (
    HEADING_DT_S,
    STANDSTILL_MPS,
    inward_cross,
    reference_motion,
    track_errors,
    track_summary,
)

DT = HEADING_DT_S


def motion_of(path, t):
    """heading, speed, yaw rate of a track ``path(t) -> (N, 2)`` at times t."""
    return reference_motion(path(t - DT), path(t), path(t + DT))


def line(heading: float, speed: float):
    u = np.array([np.cos(heading), np.sin(heading)])
    return lambda t: np.asarray(t, dtype=float)[:, None] * speed * u


@pytest.mark.parametrize("heading", [0.0, 0.7, np.pi / 2, -2.5, np.pi])
def test_straight_line_with_a_lag_is_pure_along_track(heading):
    speed, lag_s = 12.0, 0.15
    path = line(heading, speed)
    t = np.linspace(1.0, 10.0, 50)
    h, v, r = motion_of(path, t)
    np.testing.assert_allclose(np.cos(h), np.cos(heading), atol=1e-9)
    np.testing.assert_allclose(np.sin(h), np.sin(heading), atol=1e-9)
    np.testing.assert_allclose(v, speed)
    np.testing.assert_allclose(r, 0.0, atol=1e-9)
    along, cross = track_errors(path(t - lag_s), path(t), h)
    np.testing.assert_allclose(along, -speed * lag_s)  # behind: negative, the lag distance
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)
    ahead, _ = track_errors(path(t + lag_s), path(t), h)
    np.testing.assert_allclose(ahead, speed * lag_s)


def test_constant_lateral_offset_is_pure_cross_track_left_positive():
    # heading north: left is west (-x)
    path = line(np.pi / 2, 8.0)
    t = np.linspace(0.5, 5.0, 20)
    h, _, _ = motion_of(path, t)
    ref = path(t)
    along, cross = track_errors(ref + [-0.3, 0.0], ref, h)
    np.testing.assert_allclose(cross, 0.3, atol=1e-12)  # west of a northbound car = left
    np.testing.assert_allclose(along, 0.0, atol=1e-12)
    _, cross_r = track_errors(ref + [0.3, 0.0], ref, h)
    np.testing.assert_allclose(cross_r, -0.3, atol=1e-12)


def test_along_and_cross_recompose_the_euclidean_error():
    rng = np.random.default_rng(1)
    ref = rng.normal(size=(100, 2)) * 50
    ans = ref + rng.normal(size=(100, 2))
    h = rng.uniform(-np.pi, np.pi, 100)
    a, c = track_errors(ans, ref, h)
    np.testing.assert_allclose(np.hypot(a, c), np.hypot(*(ans - ref).T))


@pytest.mark.parametrize("direction", [1.0, -1.0])  # counter-clockwise (left) / clockwise
def test_circle_lagging_point_is_behind_and_inside(direction):
    radius, omega, lag_s = 30.0, direction * 0.4, 0.5

    def path(t):
        t = np.asarray(t, dtype=float)
        return radius * np.column_stack([np.cos(omega * t), np.sin(omega * t)])

    t = np.linspace(1.0, 12.0, 40)
    h, v, r = motion_of(path, t)
    np.testing.assert_allclose(v, radius * abs(omega), rtol=1e-3)
    np.testing.assert_allclose(r, omega, rtol=1e-6)  # + = left turn
    along, cross = track_errors(path(t - lag_s), path(t), h)
    chord_angle = abs(omega) * lag_s
    assert np.all(along < 0)  # lagging
    np.testing.assert_allclose(along, -radius * np.sin(chord_angle), rtol=1e-3)
    # the lagging point on the circle lies inside the turn: left of a left turn
    np.testing.assert_allclose(np.sign(cross), direction)
    inward = inward_cross(cross, r)
    np.testing.assert_allclose(inward, radius * (1 - np.cos(chord_angle)), rtol=1e-3)
    # a point outside the circle (running wide) is outward whichever way it turns
    wide = path(t) * 1.02
    _, c_wide = track_errors(wide, path(t), h)
    assert np.all(inward_cross(c_wide, r) < 0)


def test_standstill_is_nan_and_counted():
    t = np.linspace(0.0, 3.0, 31)
    speed = np.where(t < 1.5, 0.0, 5.0)  # stopped, then moving east
    x = np.cumsum(speed) * 0.1
    pos = {round(ti, 6): xi for ti, xi in zip(t, x, strict=True)}

    def path(ts):
        return np.column_stack([[pos.get(round(s, 6), np.nan) for s in ts], np.zeros(len(ts))])

    tq = t[1:-1]
    h, v, r = motion_of(path, tq)
    still = v < STANDSTILL_MPS
    assert still.any() and (~still).any()
    assert np.isnan(h[still]).all() and np.isfinite(h[~still]).all()
    assert np.isnan(r[still]).all()
    ans = path(tq) + [0.2, 0.1]
    a, c = track_errors(ans, path(tq), h)
    assert np.isnan(a[still]).all() and np.isnan(c[still]).all()
    s = track_summary(a, c, inward_cross(c, r), np.hypot(0.2, 0.1) * np.ones(tq.size))
    assert s["standstill"] == int(still.sum()) and s["count"] == int((~still).sum())
    assert s["along_mean_m"] == pytest.approx(0.2) and s["cross_mean_m"] == pytest.approx(0.1)
    assert s["turning"] == 0 and np.isnan(s["inward_mean_m"])


def test_one_sided_heading_at_track_ends():
    path = line(0.3, 10.0)
    t = np.array([2.0])
    nan = np.full((1, 2), np.nan)
    h1, v1, r1 = reference_motion(nan, path(t), path(t + DT))
    h2, v2, _ = reference_motion(path(t - DT), path(t), nan)
    np.testing.assert_allclose([h1[0], h2[0]], 0.3)
    np.testing.assert_allclose([v1[0], v2[0]], 10.0)
    assert np.isnan(r1[0])  # no yaw rate without both neighbours
    h3, v3, _ = reference_motion(nan, nan, nan)
    assert np.isnan(h3[0]) and np.isnan(v3[0])


def test_summary_figures():
    a = np.array([-1.0, -2.0, 3.0, np.nan])
    c = np.array([0.5, -0.5, 1.0, np.nan])
    i = np.array([0.5, np.nan, -1.0, np.nan])
    e = np.array([1.0, 2.0, 3.0, 1.0])
    s = track_summary(a, c, i, e)
    assert s["count"] == 3 and s["standstill"] == 1 and s["turning"] == 2
    assert s["along_mean_m"] == pytest.approx(0.0)
    assert s["along_p95_abs_m"] == pytest.approx(np.percentile([1, 2, 3], 95))
    assert s["cross_mean_m"] == pytest.approx(1.0 / 3)
    assert s["cross_p95_abs_m"] == pytest.approx(np.percentile([0.5, 0.5, 1.0], 95))
    assert s["inward_mean_m"] == pytest.approx(-0.25)
    empty = track_summary(np.empty(0), np.empty(0), np.empty(0), np.empty(0))
    assert empty["count"] == 0 and np.isnan(empty["along_mean_m"])
