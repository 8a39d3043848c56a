"""The white-jerk spectral density ``q`` [m^2/s^5] of a reference track, for the bound
(:mod:`posbench.metrics.pcrb`): one value per track, its profile along the track, and the
track's own white noise taken out first. Pure functions on arrays; seconds, metres, ENU.
"""

from __future__ import annotations

import math

import numpy as np

#: the variance of the third difference at spacing h of a white-jerk position, / (q h^5)
#: (the cardinal B-spline identity: the integral of N_3^2 is N_6(3) = 11/20)
THIRD_DIFFERENCE_GAIN = 11.0 / 20.0


#: the largest third difference [m] of a track that is taken as it is (beyond any vehicle's
#: by a hundred orders of magnitude; its square and sums of squares stay finite)
MAX_THIRD_DIFFERENCE_M = 1e100


def check_times(t: np.ndarray, what: str) -> None:
    """``t`` must be a 1-D array of finite, non-decreasing times [s] (ValueError naming
    ``what`` otherwise)."""
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"{what}: a 1-D array of finite times [s]")
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise ValueError(f"{what}: times must be non-decreasing")


def _third_differences(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, dt: float | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """The track on a uniform grid (see :func:`jerk_psd_from_track`): per third difference
    its mean square over both axes [m^2], whether it is valid, its middle [s], and the grid
    spacing [s]; None with fewer than 4 grid points."""
    tt = np.asarray(t, dtype=float)
    check_times(tt, "t")
    xy = np.column_stack([np.asarray(x, dtype=float), np.asarray(y, dtype=float)])
    good = np.isfinite(xy).all(axis=1)
    tt, xy = tt[good], xy[good]
    if tt.size < 4 or tt[-1] <= tt[0]:
        return None
    step = float(np.median(np.diff(tt))) if dt is None else float(dt)
    if not step > 0:
        raise ValueError(f"dt: a positive grid spacing [s], not {step}")
    n = int(math.floor((tt[-1] - tt[0]) / step + 1e-9)) + 1
    if n < 4:
        return None
    grid = tt[0] + step * np.arange(n)
    px, py = np.interp(grid, tt, xy[:, 0]), np.interp(grid, tt, xy[:, 1])
    # the track's own interval around each grid point; a gap > 2 dt invalidates the point
    idx = np.clip(np.searchsorted(tt, grid, side="left"), 1, tt.size - 1)
    ok = (tt[idx] - tt[idx - 1]) <= 2.0 * step
    ok |= np.isin(grid, tt)  # a grid point on a sample needs no interpolation
    # held at MAX_THIRD_DIFFERENCE_M: a glitch far out (1e200 m) leaves a finite square,
    # and sums of them stay finite (no overflow, no inf - inf in a window's sum)
    cap = MAX_THIRD_DIFFERENCE_M
    d3x, d3y = (np.clip(np.diff(v, 3), -cap, cap) for v in (px, py))
    valid = ok[:-3] & ok[1:-2] & ok[2:-1] & ok[3:]
    return 0.5 * (d3x**2 + d3y**2), valid, grid[:-3] + 1.5 * step, step


def jerk_psd_from_track(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    *,
    dt: float | None = None,
    noise_var: float = 0.0,
) -> float:
    """The white-jerk PSD ``q`` [m^2/s^5] that explains a reference track's own motion.

    The track (``t`` [s] non-decreasing, ``x``, ``y`` [m] ENU) is resampled by linear
    interpolation on a uniform grid of spacing ``dt`` [s] (default: its median sampling
    interval, so a uniform track is used as it is). Under the model, the third difference
    of positions ``p_{i+3} - 3 p_{i+2} + 3 p_{i+1} - p_i`` has variance
    ``11/20 q dt^5`` (:data:`THIRD_DIFFERENCE_GAIN`) per axis, whatever the velocity and
    acceleration; so ``q = mean(third difference^2 over both axes) / (11/20 dt^5)``.
    Differences that span a gap of the track longer than ``2 dt`` are left out (the
    interpolation would draw a straight line through it). White position noise of variance
    ``noise_var`` [m^2] per axis adds ``20 noise_var`` to each squared difference; it is
    subtracted (0 for a truth track). Real jerk is not white, so ``q`` depends on ``dt``:
    take ``dt`` near the fix interval the bound is used at. NaN with fewer than 4 grid
    points; never below 0.
    """
    diffs = _third_differences(t, x, y, dt)
    if diffs is None:
        return math.nan
    sq, valid, _, step = diffs
    if not valid.any():
        return math.nan
    ms = float(np.mean(sq[valid]))
    return max(0.0, (ms - 20.0 * noise_var) / (THIRD_DIFFERENCE_GAIN * step**5))


def track_noise_variance(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, *, dt: float | None = None
) -> float:
    """The white noise [m^2 per axis] on a reference track's positions, from its third
    differences at two scales (the grid ``dt`` [s], default the track's median interval,
    and ``2 dt``).

    Under white jerk a third difference's mean square is ``m(dt) = 11/20 q dt^5 + 20 s2``
    per axis, ``s2`` the positions' white noise: the motion's part grows 32-fold from ``dt``
    to ``2 dt``, the noise's not at all, so ``20 s2 = (32 m(dt) - m(2 dt)) / 31``, held in
    ``[0, m(dt)]``. A measured truth (an INS solution at 10 Hz) carries millimetres of such
    noise, and at a 0.1 s grid they outweigh the motion: a third difference amplifies
    white noise 20-fold and the motion's by ``11/20 dt^5`` = 5.5e-6. Jerk that is not white
    but smooth grows faster than 32-fold and gives 0, as a noise-free track does. NaN
    where either scale gives no difference.
    """
    d1 = _third_differences(t, x, y, dt)
    if d1 is None or not d1[1].any():
        return math.nan
    d2 = _third_differences(t, x, y, 2.0 * d1[3])
    if d2 is None or not d2[1].any():
        return math.nan
    m1 = float(np.mean(d1[0][d1[1]]))
    m2 = float(np.mean(d2[0][d2[1]]))
    return min(max((32.0 * m1 - m2) / 31.0, 0.0), m1) / 20.0


def jerk_psd_profile(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    *,
    dt: float | None = None,
    window_s: float = 2.0,
    noise_var: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The jerk PSD of a track as it varies along it: ``(times [s], q [m^2/s^5])``, a
    profile the bound takes for ``q`` (:data:`JerkPsd`).

    :func:`jerk_psd_from_track`'s estimate in a moving window of ``window_s`` [s] (the
    mean of the squared third differences whose middle lies within ``window_s / 2`` of each
    difference's middle; at least one difference), so that a drive's stops, cruising and
    manoeuvres each get their own q: real jerk comes in bursts, and one q for a whole drive
    overstates it where the drive is calm (a predictor that adapts beats such a bound) and
    understates it in its manoeuvres. Where a window holds no valid difference, the whole
    track's q. Empty arrays where the track gives no q at all.
    """
    diffs = _third_differences(t, x, y, dt)
    if diffs is None or not diffs[1].any():
        return np.empty(0), np.empty(0)
    sq, valid, mid, step = diffs
    v = np.where(valid, sq - 20.0 * noise_var, 0.0)
    half = max(0, int(round(0.5 * window_s / step)))
    csum = np.concatenate([[0.0], np.cumsum(v)])
    ccount = np.concatenate([[0], np.cumsum(valid)])
    lo = np.clip(np.arange(v.size) - half, 0, v.size)
    hi = np.clip(np.arange(v.size) + half + 1, 0, v.size)
    count = ccount[hi] - ccount[lo]
    overall = max(0.0, float(np.mean(v[valid])) / (THIRD_DIFFERENCE_GAIN * step**5))
    with np.errstate(invalid="ignore", divide="ignore"):
        local = (csum[hi] - csum[lo]) / count / (THIRD_DIFFERENCE_GAIN * step**5)
    q = np.where(count > 0, np.clip(local, 0.0, None), overall)
    return mid, q
