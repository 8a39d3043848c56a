"""Cubic resampling: closed form vs iterative, exact resampling, batched == single path."""

from __future__ import annotations

import numpy as np

from posbench.predictors.cubic import fit_cubic_lbfgs
from posbench.predictors.lstm.resample import (
    GRID_OFFSETS,
    FixedGridFit,
    centred_cubic_batch,
    eval_poly,
    fit_poly,
    resample_imu,
    resample_imu_batch,
    resample_positions,
    resample_positions_batch,
    window_start,
    window_starts,
)


def _irregular_times(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 100.0 + np.cumsum(rng.uniform(0.1, 0.4, n))


def test_closed_form_equals_lbfgs() -> None:
    t = _irregular_times(10)
    rng = np.random.default_rng(1)
    y = np.stack([3 + 2 * (t - t[0]) - 0.5 * (t - t[0]) ** 2, 1 + 0.1 * (t - t[0]) ** 3], 1)
    y += rng.normal(0, 0.05, y.shape)
    scale = t[-1] - t[0]
    c_closed = fit_poly(t, y, t[-1], scale)
    c_iter = fit_cubic_lbfgs(t, y, t_ref=t[-1], scale=scale).coef
    s = np.linspace(-1, 0.2, 25)
    np.testing.assert_allclose(eval_poly(c_closed, s), eval_poly(c_iter, s), atol=1e-6)
    np.testing.assert_allclose(c_closed, c_iter, atol=1e-6)


def test_known_cubic_resamples_exactly_from_irregular_fixes() -> None:
    t = _irregular_times(14, seed=3)

    def f(tt: np.ndarray) -> np.ndarray:
        u = tt - 100.0
        return np.stack([5 + 10 * u - 0.3 * u**2 + 0.02 * u**3, -2 + u**2 - 0.1 * u**3], 1)

    end = t.size - 1
    start = window_start(t, end)
    assert t[end] - t[start] >= 2.0 and t[end] - t[start + 1] < 2.0
    grid, coef, scale = resample_positions(t, f(t), start, end)
    np.testing.assert_allclose(grid, f(t[end] + GRID_OFFSETS), atol=1e-9)
    # speed of the fit: derivative of the known cubic at the newest fix
    u = t[end] - 100.0
    v = np.array([10 - 0.6 * u + 0.06 * u**2, 2 * u - 0.3 * u**2])
    np.testing.assert_allclose(coef[1] / scale, v, atol=1e-8)


def test_imu_resampled_on_the_same_grid() -> None:
    ti = np.arange(0.0, 5.0, 0.02) + 0.003
    vals = np.stack([0.5 + 0.1 * ti, -0.2 * ti**2, 0.3 * ti], 1)
    out = resample_imu(ti, vals, 2.5, 4.7)
    tg = 4.7 + GRID_OFFSETS
    np.testing.assert_allclose(
        out, np.stack([0.5 + 0.1 * tg, -0.2 * tg**2, 0.3 * tg], 1), atol=1e-9
    )
    # glitches are left out of the fit
    vals_g = vals.copy()
    vals_g[200, 0] = 400.0
    np.testing.assert_allclose(resample_imu(ti, vals_g, 2.5, 4.7), out, atol=1e-9)
    assert resample_imu(ti, vals, 10.0, 11.0) is None


def test_batched_paths_equal_single_window() -> None:
    t = _irregular_times(60, seed=5)
    rng = np.random.default_rng(2)
    xy = np.cumsum(rng.normal(0, 1, (60, 2)), axis=0)
    ends = np.arange(20, 60)
    starts = window_starts(t, ends)
    pos, coef, scale = resample_positions_batch(t, xy, starts, ends, np.array([0.2]))
    ti = np.arange(t[0], t[-1], 0.02)
    iv = rng.normal(0, 1, (ti.size, 3))
    ib, ok = resample_imu_batch(ti, iv, t[starts], t[ends])
    assert ok.all()
    for b, (s, e) in enumerate(zip(starts, ends, strict=True)):
        assert s == window_start(t, e)
        g, c, sc = resample_positions(t, xy, s, e)
        np.testing.assert_allclose(pos[b, :8], g, atol=1e-9)
        np.testing.assert_allclose(pos[b, 8], eval_poly(c, 0.2 / sc), atol=1e-9)
        np.testing.assert_allclose(ib[b], resample_imu(ti, iv, t[s], t[e]), atol=1e-9)


def test_fixed_grid_fit_and_centred_cubic() -> None:
    times = np.append(GRID_OFFSETS, 0.2)
    fit = FixedGridFit(times)
    y = np.stack([1 + 2 * times + times**3, times**2], 1)
    np.testing.assert_allclose(fit.fit(y), fit_poly(times, y, 0.0, 1.0), atol=1e-10)
    np.testing.assert_allclose(eval_poly(fit.fit(y), times), y, atol=1e-10)
    t = _irregular_times(40, seed=7)
    xy = np.stack([t**2 / 10, -t], 1)
    tq = np.array([t[0] - 1, t[10] + 0.05, t[-1]])
    ref, ok = centred_cubic_batch(t, xy, tq)
    assert ok.tolist() == [False, True, False]
    np.testing.assert_allclose(ref[1], [tq[1] ** 2 / 10, -tq[1]], atol=1e-8)
