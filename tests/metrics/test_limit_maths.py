"""A drive's limit from its arrays (metrics/limit.py): the noise estimates recover what was
put in, glitches do not move them, the per-query bounds add the slow floor only against an
independent truth, the IMU lowers them, a latency is a shift of the fixes, and the mean-only
interval (metrics/limit.mean_ci) is the summary interval's mean."""

from __future__ import annotations

import math

import numpy as np
import pytest

from posbench.metrics.bootstrap import summary_ci
from posbench.metrics.limit import (
    MIN_FIX_VAR_M2,
    fix_error_variance,
    fix_white_variance,
    imu_white_variance,
    mean_ci,
    mean_error_bounds,
)
from posbench.metrics.pcrb import position_variance_bound
from posbench.metrics.pcrb_mean_error import mean_error_bound


def _ca_track(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Irregular times (0.1-0.3 s apart) and a smooth constant-acceleration path [m]."""
    t = np.cumsum(rng.uniform(0.1, 0.3, n))
    return t, 3.0 + 8.0 * t + 0.4 * t * t, -2.0 + 5.0 * t - 0.2 * t * t


def test_fix_white_variance_recovers_white_noise_and_ignores_glitches():
    rng = np.random.default_rng(1)
    t, x, y = _ca_track(4000, rng)
    sigma = 0.3
    xn, yn = x + rng.normal(0, sigma, t.size), y + rng.normal(0, sigma, t.size)
    est = fix_white_variance(t, xn, yn)
    assert est == pytest.approx(sigma**2, rel=0.08)
    glitched = xn.copy()
    glitched[::97] += 50.0  # rare jumps of 50 m
    assert fix_white_variance(t, glitched, yn) == pytest.approx(est, rel=0.1)
    assert fix_white_variance(t, x, y) == MIN_FIX_VAR_M2  # exact fixes: the floor
    assert math.isnan(fix_white_variance(t[:3], x[:3], y[:3]))


def test_imu_white_variance_recovers_noise_beside_bias_and_glitches():
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 200.0, 0.02)
    true_ax, true_ay = 0.5 * np.sin(0.3 * t), 0.8 * np.cos(0.2 * t)
    sd = 0.05
    ax = true_ax + 0.1 + rng.normal(0, sd, t.size)  # a bias of 0.1 m/s^2 is not noise
    ay = true_ay - 0.2 + rng.normal(0, sd, t.size)
    ax[::500] += 300.0  # glitches of hundreds of m/s^2
    assert imu_white_variance(t, ax, ay) == pytest.approx(sd**2, rel=0.1)


def test_fix_error_variance_is_the_mean_square_without_glitches():
    rng = np.random.default_rng(3)
    ex, ey = rng.normal(0.4, 1.0, 5000), rng.normal(-0.3, 1.0, 5000)
    expected = (np.mean(ex**2) + np.mean(ey**2)) / 2.0  # bias included
    ex[10] = 500.0
    assert fix_error_variance(ex, ey) == pytest.approx(expected, rel=0.02)
    assert math.isnan(fix_error_variance(np.array([np.nan]), np.array([1.0])))


def test_bounds_are_the_pcrb_with_the_slow_floor_only_against_a_truth():
    t_fix = np.arange(0.0, 20.0, 0.2)
    t_issue = np.arange(0.3, 19.0, 0.05)
    t_query = t_issue + 0.2
    r, q, slow = 0.04, 2.0, 0.5
    var = position_variance_bound(t_fix, r, q, t_query, t_issue=t_issue)
    truth, _ = mean_error_bounds(t_fix, r, q, t_issue, t_query, slow_var=slow)
    fixes, _ = mean_error_bounds(
        t_fix, r, q, t_issue, t_query, slow_var=slow, independent_truth=False
    )
    np.testing.assert_allclose(truth, mean_error_bound(var + slow), rtol=1e-12)
    np.testing.assert_allclose(fixes, mean_error_bound(var), rtol=1e-12)


def test_the_imu_lowers_the_bound_and_a_latency_shifts_the_fixes():
    t_fix = np.arange(0.0, 20.0, 0.2)
    t_issue = np.arange(0.3, 19.0, 0.05)
    t_query = t_issue.copy()
    t_acc = np.arange(0.0, 20.0, 0.02)
    plain, imu = mean_error_bounds(t_fix, 0.04, 2.0, t_issue, t_query, t_acc=t_acc, r_acc=0.01)
    assert imu is not None and np.all(imu <= plain + 1e-15) and imu.mean() < 0.8 * plain.mean()
    late, _ = mean_error_bounds(t_fix, 0.04, 2.0, t_issue, t_query, latency_s=0.1)
    var = position_variance_bound(t_fix - 0.1, 0.04, 2.0, t_query, t_issue=t_issue - 0.1)
    np.testing.assert_allclose(late, mean_error_bound(var), rtol=1e-12)
    assert late.mean() > plain.mean()  # older news, larger error


def test_no_bound_without_q_or_fixes():
    t = np.arange(1.0, 2.0, 0.1)
    b, i = mean_error_bounds(np.arange(0.0, 3.0, 0.2), 0.04, math.nan, t, t, t_acc=t, r_acc=0.1)
    assert np.isnan(b).all() and i is not None and np.isnan(i).all()
    b, i = mean_error_bounds(np.empty(0), 0.04, 1.0, t, t)
    assert np.isnan(b).all() and i is None


@pytest.mark.parametrize("clusters", [1, 5])
def test_mean_ci_is_the_summary_intervals_mean(clusters):
    rng = np.random.default_rng(4)
    values = rng.gamma(2.0, 0.05, 3000)
    codes = np.repeat(np.arange(clusters), 3000 // clusters)
    times = np.arange(3000) * 0.05
    full = summary_ci(values, codes, times)
    mine = mean_ci(values, codes, times)
    assert mine["mean_m"] == full["mean_m"]
    assert mine["clusters"] == full["clusters"] and mine["block_len"] == full["block_len"]
    assert all(math.isnan(v) for v in (*mine["median_m"], *mine["p95_m"]))


def test_a_constant_q_profile_is_the_one_value_and_a_calm_stretch_lowers_the_bound():
    t_fix = np.arange(0.0, 30.0, 0.2)
    tq = np.arange(1.0, 29.0, 0.05)
    one = position_variance_bound(t_fix, 0.01, 3.0, tq + 0.2, t_issue=tq)
    grid = np.arange(0.0, 30.0, 0.5)
    flat = position_variance_bound(
        t_fix, 0.01, (grid, np.full(grid.size, 3.0)), tq + 0.2, t_issue=tq
    )
    np.testing.assert_allclose(flat, one, rtol=1e-12)
    calm = np.where((grid > 10) & (grid < 20), 0.01, 3.0)
    varying = position_variance_bound(t_fix, 0.01, (grid, calm), tq + 0.2, t_issue=tq)
    inside = (tq > 13) & (tq < 19)
    assert np.all(varying[inside] < 0.5 * one[inside])
    np.testing.assert_allclose(varying[tq < 9], one[tq < 9], rtol=1e-12)


def test_the_q_profile_follows_the_motion_s_regimes():
    """A track drawn with q = 0.2 for 200 s, then q = 20: each half's profile is near its
    own q, the whole drive's one value between them."""
    from posbench.metrics.jerk_psd import jerk_psd_from_track, jerk_psd_profile
    from posbench.metrics.pcrb import process_noise

    rng = np.random.default_rng(5)
    dt = 0.1
    t = np.arange(0.0, 400.0, dt)
    q_true = np.where(t < 200.0, 0.2, 20.0)
    state = np.zeros((2, 3))
    f = np.array([[1, dt, dt * dt / 2], [0, 1, dt], [0, 0, 1]])
    pos = np.empty((t.size, 2))
    for k in range(t.size):
        chol = np.linalg.cholesky(process_noise(dt, q_true[k]) + 1e-15 * np.eye(3))
        state = state @ f.T + (chol @ rng.standard_normal((3, 2))).T
        pos[k] = state[:, 0]
    mid, q = jerk_psd_profile(t, pos[:, 0], pos[:, 1], dt=0.2, window_s=10.0)
    assert np.median(q[mid < 190]) == pytest.approx(0.2, rel=0.3)
    assert np.median(q[mid > 210]) == pytest.approx(20.0, rel=0.3)
    assert 0.2 < jerk_psd_from_track(t, pos[:, 0], pos[:, 1], dt=0.2) < 20.0
