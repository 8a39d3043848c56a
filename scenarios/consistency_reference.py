"""The reference kinematics every IMU and speed stream is judged against (pure numpy).

With a truth the reference is the truth (:func:`truth_kinematics`): its x/y [m, local ENU],
and its ``yaw`` [rad, ENU] and ``v`` [m/s] columns where it has them; without one, the GPS
fixes (:func:`gps_kinematics`). Positions are linearly interpolated onto the grid of
:attr:`Tolerances.grid_hz` (not across gaps longer than :attr:`Tolerances.max_fix_gap_s`),
smoothed with a Gaussian of :attr:`Tolerances.smooth_s` and differentiated (central
differences) into velocity, speed, course and course rate.

Noise gates: differentiating positions amplifies their white noise (sigma per axis,
sampled every T): the velocity noise is ``g_v sigma`` and the acceleration noise
``g_a sigma`` (:func:`derivative_noise_gains`), so the course carries ``g_v sigma / v``
[rad] and the course rate ``g_a sigma / v`` [rad/s]. A course sample is used only above the
speed where its noise reaches :attr:`Tolerances.course_noise_deg` (:func:`course_gate_mps`);
course-rate samples only above the speed where their noise stays below
:attr:`Tolerances.course_rate_noise_ratio` x the turning signal they carry
(:func:`rate_gate_mps`); neither below :attr:`Tolerances.moving_mps`. sigma is the white
scatter measured on the positions (:func:`~posbench.scenarios.consistency_stats.fix_scatter`),
which is what differentiation sees (a stated accuracy is mostly slow error: multipath,
atmosphere, an INS's drift); the stated accuracy only where too few samples measure it.
A truth's yaw column (an INS
heading) needs no such gate: its rate is the heading-rate reference of a gyro while
rolling, provided the heading follows the truth's own course.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from posbench.scenarios.consistency_model import TOLERANCES, Tolerances
from posbench.scenarios.consistency_stats import fix_scatter, scatter_1d
from posbench.scenarios.drive import Drive, GpsStream, TruthStream
from posbench.scenarios.grid import gaussian_kernel, interp_gapped, smooth
from posbench.scenarios.imu_frames import circular_offset
from posbench.scenarios.time_axis import grid_size


@dataclass(frozen=True)
class Reference:
    """What the reference (the truth, else the fixes) implies on the grid ``t`` [s].

    ``source`` (``"truth"`` or ``"GPS"``) names it in every reason. ``speed`` [m/s] (the
    truth's ``v`` column where it has one, else of the smoothed positions) and ``dvdt``
    [m/s^2]; ``course`` [rad, ENU] and ``course_rate`` [rad/s] of the smoothed positions,
    NaN below their noise gates (``course_gate_mps``, ``rate_gate_mps`` [m/s]);
    ``heading`` [rad, ENU] and ``heading_rate`` [rad/s] from a truth yaw column (None
    without one, or when it does not follow the course: ``note`` says why);
    ``course_rate_sign`` the course rate above the looser ``sign_gate_mps``
    (:attr:`Tolerances.sign_noise_ratio`: good for a gyro's sign only); ``rolling``
    where ``speed`` > :attr:`Tolerances.rolling_mps`, ``moving`` where the course is
    usable; ``noise_m`` the white position noise [m, per axis] the gates come from.
    """

    source: str
    t: np.ndarray
    speed: np.ndarray
    dvdt: np.ndarray
    course: np.ndarray
    course_rate: np.ndarray
    rolling: np.ndarray
    moving: np.ndarray
    noise_m: float
    course_gate_mps: float
    rate_gate_mps: float
    heading: np.ndarray | None = None
    heading_rate: np.ndarray | None = None
    note: str = ""
    sign_gate_mps: float = float("inf")
    course_rate_sign: np.ndarray | None = None

    def rate(self) -> tuple[np.ndarray, str]:
        """The yaw-rate reference [rad/s] (NaN where unusable) and its name: the heading
        rate while rolling where there is a heading, else the gated course rate."""
        if self.heading_rate is not None:
            return np.where(self.rolling, self.heading_rate, np.nan), f"{self.source} heading rate"
        return self.course_rate, f"{self.source} course rate"

    def direction(self) -> tuple[np.ndarray, str]:
        """The yaw reference [rad, ENU] (NaN where unusable) and its name: the heading
        while rolling where there is one, else the gated course."""
        if self.heading is not None:
            return np.where(self.rolling, self.heading, np.nan), f"{self.source} yaw"
        return self.course, f"{self.source} course"


#: the kinematics of a drive as the GPS implies them (the name the checks had first)
GpsKinematics = Reference


def derivative_noise_gains(sample_dt: float, sigma_s: float) -> tuple[float, float]:
    """(g_v [1/s], g_a [1/s^2]): the sd of the first and second derivative of white noise
    of sd 1 sampled every ``sample_dt`` [s] after a Gaussian smoothing of sd ``sigma_s``
    [s]: sqrt(T / (4 sqrt(pi) s^3)) and sqrt(3 T / (8 sqrt(pi) s^5)), with s widened to
    sqrt(s^2 + T^2 / 6) by the linear interpolation onto the grid (a triangle of width T)."""
    t = float(sample_dt)
    s = float(np.sqrt(sigma_s**2 + t**2 / 6))
    return (
        float(np.sqrt(t / (4 * np.sqrt(np.pi) * s**3))),
        float(np.sqrt(3 * t / (8 * np.sqrt(np.pi) * s**5))),
    )


def course_gate_mps(noise_m: float, sample_dt: float, tol: Tolerances = TOLERANCES) -> float:
    """Speed [m/s] below which positions with white noise ``noise_m`` [m, per axis] sampled
    every ``sample_dt`` [s] give a course noisier than :attr:`Tolerances.course_noise_deg`;
    never below :attr:`Tolerances.moving_mps`."""
    g_v, _ = derivative_noise_gains(max(sample_dt, 1.0 / tol.grid_hz), tol.smooth_s)
    return float(max(tol.moving_mps, g_v * noise_m / np.radians(tol.course_noise_deg)))


def rate_gate_mps(
    speed: np.ndarray,
    rate: np.ndarray,
    noise_m: float,
    sample_dt: float,
    tol: Tolerances = TOLERANCES,
    ratio: float | None = None,
) -> float:
    """The lowest speed [m/s] (>= :attr:`Tolerances.moving_mps`) such that, on the samples
    of the course rate ``rate`` [rad/s] at ``speed`` [m/s] above it, the predicted noise
    N (RMS of g_a ``noise_m`` / v) is at most ``ratio`` (default
    :attr:`Tolerances.course_rate_noise_ratio`) x the signal S = sqrt(var(rate) - N^2);
    inf when no such speed leaves a sample.
    Vectorised over every candidate gate (the samples sorted by speed, fastest first)."""
    _, g_a = derivative_noise_gains(max(sample_dt, 1.0 / tol.grid_hz), tol.smooth_s)
    ok = np.isfinite(rate) & np.isfinite(speed) & (speed > tol.moving_mps)
    if ok.sum() < 3:
        return float("inf")
    order = np.argsort(-speed[ok])
    v, r = speed[ok][order], rate[ok][order]
    k = np.arange(1, v.size + 1)
    n2 = np.cumsum((g_a * noise_m / v) ** 2) / k
    mean = np.cumsum(r) / k
    var = np.cumsum(r * r) / k - mean**2
    q2 = (tol.course_rate_noise_ratio if ratio is None else ratio) ** 2
    good = (n2 * (1 + q2) <= q2 * var) & (var - n2 >= tol.min_turn_rad_s**2) & (k >= 3)
    if not good.any():
        return float("inf")
    last = int(np.flatnonzero(good)[-1])
    if last == v.size - 1:
        return float(tol.moving_mps)
    return float(0.5 * (v[last] + v[last + 1]))  # between the slowest used and the next


def position_noise_m(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    accuracy: np.ndarray | None,
    tol: Tolerances = TOLERANCES,
) -> float:
    """White noise [m, per axis] of sampled positions: their measured scatter
    (:func:`fix_scatter` / sqrt(2)), or the median stated accuracy where fewer than 8
    samples measure it; at least :attr:`Tolerances.min_position_noise_m`."""
    sigma = fix_scatter(t, x, y) / np.sqrt(2) if t.size >= 8 else float("nan")
    if not np.isfinite(sigma) and accuracy is not None and np.any(np.isfinite(accuracy)):
        sigma = float(np.nanmedian(accuracy))
    return (
        float(max(sigma, tol.min_position_noise_m))
        if np.isfinite(sigma)
        else tol.min_position_noise_m
    )


def _grid(t: np.ndarray, tol: Tolerances, source: str | None = None) -> np.ndarray | None:
    """The reference grid [s] every 1 / :attr:`Tolerances.grid_hz` over the samples at
    ``t`` [s] (None for fewer than 4 samples or 8 grid points); its size is checked before it
    is allocated (:func:`~posbench.scenarios.time_axis.grid_size`: a DataError naming
    ``source`` beyond :data:`~posbench.scenarios.time_axis.MAX_GRID_POINTS`)."""
    dt = 1.0 / tol.grid_hz
    if t.size < 4:
        return None
    grid_size(float(t[0]), float(t[-1]), dt, source)
    grid = np.arange(t[0], t[-1] + dt / 2, dt)
    return grid if grid.size >= 8 else None


def _gated(speed: np.ndarray, gate: float, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``values`` where ``speed`` > ``gate`` at a sample and both neighbours, else NaN."""
    with np.errstate(invalid="ignore"):
        fast = speed > gate
    ok = fast & np.roll(fast, 1) & np.roll(fast, -1)
    ok[[0, -1]] = False
    return ok, np.where(ok, values, np.nan)


def _reference(
    source: str,
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    grid: np.ndarray,
    noise: float,
    v_col: np.ndarray | None,
    tol: Tolerances,
) -> Reference:
    """Kinematics of positions ``x``, ``y`` [m] at times ``t`` [s] on ``grid``, with a
    speed column ``v_col`` [m/s] on the grid (NaN where absent) preferred to theirs."""
    dt = 1.0 / tol.grid_hz
    k = gaussian_kernel(tol.smooth_s, dt)
    xs = smooth(interp_gapped(t, x, grid, tol.max_fix_gap_s), k)
    ys = smooth(interp_gapped(t, y, grid, tol.max_fix_gap_s), k)
    vx, vy = np.gradient(xs, dt), np.gradient(ys, dt)
    speed = np.hypot(vx, vy)
    if v_col is not None:
        speed = np.where(np.isfinite(v_col), v_col, speed)
    course = np.arctan2(vy, vx)
    dc = np.angle(np.exp(1j * (course[2:] - course[:-2]))) / (2 * dt)
    rate = np.concatenate([[np.nan], dc, [np.nan]])
    gaps = np.diff(t)
    sample_dt = (
        float(np.mean(gaps[gaps <= tol.max_fix_gap_s]))
        if np.any(gaps <= tol.max_fix_gap_s)
        else float(np.median(gaps))
    )
    g_course = course_gate_mps(noise, sample_dt, tol)
    moving, course = _gated(speed, g_course, course)
    _, rate = _gated(speed, tol.moving_mps, rate)
    g_rate = rate_gate_mps(speed, rate, noise, sample_dt, tol)
    g_sign = rate_gate_mps(speed, rate, noise, sample_dt, tol, tol.sign_noise_ratio)
    _, rate_sign = _gated(speed, g_sign, rate)
    _, rate = _gated(speed, g_rate, rate)
    with np.errstate(invalid="ignore"):
        rolling = speed > tol.rolling_mps
    return Reference(
        source,
        grid,
        speed,
        np.gradient(speed, dt),
        course,
        rate,
        rolling,
        moving,
        noise,
        g_course,
        g_rate,
        sign_gate_mps=g_sign,
        course_rate_sign=rate_sign,
    )


def gps_kinematics(drive: Drive, tol: Tolerances = TOLERANCES) -> Reference | None:
    """The reference the fixes imply (fixes stating more than
    :attr:`Tolerances.max_fix_accuracy_m` left out), or None when too few remain."""
    g: GpsStream = drive.gps
    if g.accuracy is not None:
        g = g.take(~(g.accuracy > tol.max_fix_accuracy_m))
    grid = _grid(g.t, tol, drive.meta.source)
    if grid is None:
        return None
    noise = position_noise_m(g.t, g.x, g.y, g.accuracy, tol)
    return _reference("GPS", g.t, g.x, g.y, grid, noise, None, tol)


def truth_kinematics(drive: Drive, tol: Tolerances = TOLERANCES) -> Reference | None:
    """The reference the truth implies: its positions, its ``v`` column for the speed and
    its ``yaw`` column for the heading (when it follows the truth's course), or None
    without a truth of at least a few samples. Truth samples stating an accuracy worse than
    :attr:`Tolerances.max_fix_accuracy_m` are left out, as such fixes are (an INS stating
    20 m has lost its GNSS aiding or not converged: its velocity and heading drift too)."""
    tr: TruthStream | None = drive.truth
    if tr is None:
        return None
    if tr.accuracy is not None:
        tr = _take(tr, ~(tr.accuracy > tol.max_fix_accuracy_m))
    grid = _grid(tr.t, tol, drive.meta.source)
    if grid is None:
        return None
    k = gaussian_kernel(tol.smooth_s, 1.0 / tol.grid_hz)
    v_col = None
    if tr.v is not None and np.any(np.isfinite(tr.v)):
        v_col = smooth(_interp_finite(tr.t, tr.v, grid, tol), k)
    noise = position_noise_m(tr.t, tr.x, tr.y, tr.accuracy, tol)
    ref = _reference("truth", tr.t, tr.x, tr.y, grid, noise, v_col, tol)
    if tr.yaw is None or not np.any(np.isfinite(tr.yaw)):
        return ref
    ok = np.isfinite(tr.yaw)
    unwrapped = np.unwrap(tr.yaw[ok])
    h = smooth(interp_gapped(tr.t[ok], unwrapped, grid, tol.max_fix_gap_s), k)
    h_rate = np.gradient(h, 1.0 / tol.grid_hz)
    heading = np.angle(np.exp(1j * h))
    why = _heading_refused(heading, ref.course, scatter_1d(tr.t[ok], unwrapped), tr.t[ok], tol)
    if why:
        return replace(ref, note=why)
    return replace(ref, heading=heading, heading_rate=h_rate)


def _interp_finite(t: np.ndarray, v: np.ndarray, grid: np.ndarray, tol: Tolerances) -> np.ndarray:
    ok = np.isfinite(v)
    if ok.sum() < 2:
        return np.full(grid.shape, np.nan)
    return interp_gapped(t[ok], v[ok], grid, tol.max_fix_gap_s)


def _heading_refused(
    heading: np.ndarray, course: np.ndarray, yaw_scatter: float, t: np.ndarray, tol: Tolerances
) -> str:
    """Why a truth yaw column is no heading reference ("" when it is): its rate noisier
    than :attr:`Tolerances.min_turn_rad_s`, or an offset or spread about the
    truth's own course beyond :attr:`Tolerances.yaw_offset_fail_deg` (checked where
    enough moving samples allow)."""
    g_v, _ = derivative_noise_gains(
        max(float(np.median(np.diff(t))), 1.0 / tol.grid_hz), tol.smooth_s
    )
    if np.isfinite(yaw_scatter) and g_v * yaw_scatter > tol.min_turn_rad_s:
        return f"truth yaw too noisy (scatter {np.degrees(yaw_scatter):.1f} deg)"
    ok = np.isfinite(heading) & np.isfinite(course)
    if ok.sum() / tol.grid_hz < tol.min_samples_s:
        return ""
    off, spread = (float(np.degrees(a)) for a in circular_offset(heading[ok] - course[ok]))
    if abs(off) > tol.yaw_offset_fail_deg or spread > tol.yaw_offset_fail_deg:
        return (
            f"truth yaw does not follow its course (offset {off:+.0f} deg, spread {spread:.0f} deg)"
        )
    return ""


def _take(tr: TruthStream, keep: np.ndarray) -> TruthStream:
    """The truth samples where ``keep``."""

    def opt(c: np.ndarray | None) -> np.ndarray | None:
        return None if c is None else c[keep]

    return TruthStream(
        tr.t[keep], tr.x[keep], tr.y[keep], yaw=opt(tr.yaw), v=opt(tr.v), accuracy=opt(tr.accuracy)
    )
