"""Irregular streams on a regular time grid: bin means, gap-aware interpolation and
NaN-aware Gaussian smoothing (pure numpy; times in seconds)."""

from __future__ import annotations

import numpy as np


def gaussian_kernel(sigma_s: float, dt: float) -> np.ndarray:
    """A normalised Gaussian kernel of standard deviation ``sigma_s`` [s] sampled every
    ``dt`` [s], out to 3 sigma."""
    half = max(1, int(np.ceil(3 * sigma_s / dt)))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) * dt / sigma_s) ** 2)
    return k / k.sum()


def smooth(values: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Normalised convolution: NaNs are gaps; a point keeps a value only where >= 90 %
    of the kernel's weight fell on valid samples."""
    ok = np.isfinite(values)
    num = np.convolve(np.where(ok, values, 0.0), kernel, mode="same")
    den = np.convolve(ok.astype(float), kernel, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[den < 0.9] = np.nan
    return out


def bin_mean(t: np.ndarray, v: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Mean of samples ``v`` (at times ``t`` [s]) in each grid cell centred on ``grid``
    (cell width = grid step); NaN for an empty cell. O(n) through cumulative sums."""
    dt = grid[1] - grid[0] if grid.size > 1 else 1.0
    ok = np.isfinite(v)
    t, v = t[ok], v[ok]
    edges = np.concatenate([grid - dt / 2, grid[-1:] + dt / 2])
    idx = np.searchsorted(t, edges)
    cs = np.concatenate([[0.0], np.cumsum(v)])
    n = np.diff(idx)
    s = cs[idx[1:]] - cs[idx[:-1]]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def interp_gapped(t: np.ndarray, v: np.ndarray, grid: np.ndarray, max_gap_s: float) -> np.ndarray:
    """``v`` linearly interpolated at ``grid``; NaN outside ``t`` or inside a gap between
    samples longer than ``max_gap_s`` [s]."""
    out = np.interp(grid, t, v)
    i = np.clip(np.searchsorted(t, grid), 1, max(t.size - 1, 1))
    gap = t[i] - t[i - 1] if t.size > 1 else np.full(grid.shape, np.inf)
    bad = (grid < t[0]) | (grid > t[-1]) | (gap > max_gap_s)
    out[bad] = np.nan
    return out
