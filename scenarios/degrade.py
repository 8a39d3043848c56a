"""Turn a reference track into a realistic GPS stream:
irregular fix times, noise, latency (dropouts: :mod:`posbench.scenarios.dropouts`).

Everything here is seeded and deterministic. Times are seconds from the drive's
start, positions metres in the drive's local frame (ENU: x east, y north).

Fix times
    :func:`draw_fix_times` draws irregular intervals from a distribution:
    ``"aslan"`` (default) is the fix-interval distribution of the paper's routes,
    ``"uniform:a,b"`` draws intervals uniformly in [a, b] seconds.

Noise profiles (:data:`GPS_PROFILES`, per axis, independent for x and y)
    ``"none"``      exact: the truth interpolated at the fix times;
    ``"rtk"``       white noise, sigma 0.02 m;
    ``"consumer"``  white noise sigma 0.5 m plus a first-order Gauss-Markov error
                    (sigma 1.0 m, time constant 45 s): slowly wandering metre-level error.

Stated accuracy (``GpsStream.accuracy``, per-axis 1-sigma [m], :data:`STATED_SIGMA_M`)
    What the simulated receiver *says* about each fix, as a real one does:
    ``"rtk"`` states its true sigma, 0.02 m. ``"consumer"`` states only its white part,
    0.5 m, and so **under-states** its true per-axis error sqrt(0.5^2 + 1.0^2) = 1.118 m
    by a factor 2.24 (:data:`CONSUMER_UNDERSTATEMENT`): like a real receiver, whose
    covariance reflects the measurement noise it sees fix to fix, not the slowly wandering
    multipath / atmosphere error it cannot see. The fix-to-fix error over the 0.1-0.4 s
    between fixes is nearly all white (the Gauss-Markov part changes by ~1.0 * sqrt(2 dt /
    45 s) ~ 0.1 m), so 0.5 m is what a filter's fix-to-fix R needs; its absolute position
    is 2.24x worse than stated. ``"none"`` adds no noise and states none (``None``). A
    ``latency_s`` is not part of the stated accuracy (receivers do not state it either).

Latency
    ``latency_s`` models a receiver that reports late: a fix stamped ``t`` carries the
    position the vehicle had at ``t - latency_s`` (a stale position). A predictor that
    trusts the stamp is thus ``latency_s`` behind the truth.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from posbench.scenarios.drive import GpsStream, TruthStream
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.aslan import (
    ASLAN_FIX_INTERVAL_QUANTILES_S as _ASLAN_MEASURED_QUANTILES_S,
)

GPS_PROFILES = ("none", "rtk", "consumer")

#: Fix-interval distribution [s] of the paper's routes: the 21 quantiles (0, 5, ..., 100 %)
#: measured over all 15 routes by ``posbench.scenarios.loaders.aslan.fix_interval_quantiles``, with
#: the tails clipped to 100-400 ms. The unclipped extremes (17 ms stale repeats, 1.0 s gaps) are
#: receiver glitches and outages, which the dropout profiles model separately.
ASLAN_FIX_INTERVAL_QUANTILES_S: np.ndarray = np.clip(_ASLAN_MEASURED_QUANTILES_S, 0.100, 0.400)

#: Noise parameters per profile: (white sigma [m], Gauss-Markov sigma [m], GM time constant [s]).
NOISE_PARAMS: dict[str, tuple[float, float, float]] = {
    "none": (0.0, 0.0, 1.0),
    "rtk": (0.02, 0.0, 1.0),
    "consumer": (0.5, 1.0, 45.0),
}

#: Stated per-axis 1-sigma [m] of each profile's fixes (``GpsStream.accuracy``; see the
#: module doc): rtk its true sigma, consumer its white part only, none nothing.
STATED_SIGMA_M: dict[str, float | None] = {"none": None, "rtk": 0.02, "consumer": 0.5}
#: consumer's true per-axis sigma / its stated sigma (sqrt(0.5^2 + 1^2) / 0.5 = 2.236)
CONSUMER_UNDERSTATEMENT: float = float(np.hypot(0.5, 1.0) / 0.5)


# ----------------------------------------------------------------------------- fix times


def _quantile_table(
    q: Mapping[float, float] | Sequence[float] | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(probabilities, intervals) from a {p: q} mapping or a sequence of quantiles at even p."""
    if isinstance(q, Mapping):
        p = np.asarray(sorted(q), dtype=float)
        v = np.asarray([q[k] for k in sorted(q)], dtype=float)
    else:
        v = np.asarray(q, dtype=float)
        p = np.linspace(0.0, 1.0, v.size)
    return p, np.maximum.accumulate(v)


def _parse_intervals(intervals: str) -> tuple[np.ndarray, np.ndarray]:
    """Inverse-CDF table (probabilities, intervals [s]) for an ``intervals`` spec."""
    if intervals == "aslan":
        return _quantile_table(ASLAN_FIX_INTERVAL_QUANTILES_S)
    if intervals.startswith("uniform:"):
        try:
            lo, hi = (float(v) for v in intervals[len("uniform:") :].split(","))
        except ValueError:
            lo = hi = float("nan")
        if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo <= hi):
            raise DataError(
                None, f"fix intervals {intervals!r}: expected 'uniform:a,b' with 0 < a <= b seconds"
            )
        return np.array([0.0, 1.0]), np.array([lo, hi])
    raise DataError(None, f"unknown fix intervals {intervals!r}; use 'aslan' or 'uniform:a,b'")


def draw_intervals(n: int, rng: np.random.Generator, intervals: str = "aslan") -> np.ndarray:
    """``n`` fix intervals [s] drawn from the ``intervals`` distribution."""
    p, v = _parse_intervals(intervals)
    return np.interp(rng.random(n), p, v)


def draw_fix_times(
    t_start: float, t_end: float, rng: np.random.Generator, intervals: str = "aslan"
) -> np.ndarray:
    """Irregular fix times [s] in [t_start, t_end].

    The first fix falls a random fraction of one interval after ``t_start`` (random
    phase); later fixes follow at intervals drawn from ``intervals`` (see module doc).
    """
    span = float(t_end) - float(t_start)
    if not np.isfinite(span) or span < 0:
        raise DataError(None, f"fix times: bad time range [{t_start}, {t_end}]")
    p, v = _parse_intervals(intervals)
    mean = float(np.trapezoid(v, p)) if p.size > 1 else float(v[0])
    n = int(span / mean * 1.25) + 16
    d = np.interp(rng.random(n), p, v)
    d[0] *= rng.random()
    while d.sum() <= span:  # rare: extend with more draws (keeps determinism)
        d = np.concatenate([d, np.interp(rng.random(n), p, v)])
    t = t_start + np.cumsum(d)
    return t[t <= t_end]


# ----------------------------------------------------------------------------- noise


def gauss_markov(
    t: np.ndarray, sigma: float, tau_s: float, rng: np.random.Generator, dims: int = 2
) -> np.ndarray:
    """Stationary first-order Gauss-Markov error [m] at times t [s], shape (len(t), dims).

    Simulated on a regular grid (step min(0.1 s, tau/20)) as the AR(1) recursion
    ``e[k] = phi e[k-1] + sigma sqrt(1 - phi^2) w[k]`` (phi = exp(-step / tau)), solved in
    closed form block-wise with cumulative sums, then interpolated linearly to ``t``:
    autocorrelation exp(-|dt| / tau), standard deviation ``sigma``.
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0 or sigma <= 0:
        return np.zeros((t.size, dims))
    step = min(0.1, tau_s / 20.0)
    n = int(np.ceil((t[-1] - t[0]) / step)) + 2
    phi = np.exp(-step / tau_s)
    w = rng.standard_normal((n, dims)) * (sigma * np.sqrt(1.0 - phi * phi))
    w[0] = rng.standard_normal(dims) * sigma  # stationary start
    out = np.empty_like(w)
    block = max(1, int(40.0 * tau_s / step))  # phi**-block stays ~e^40
    prev = np.zeros(dims)
    for b0 in range(0, n, block):
        wb = w[b0 : b0 + block]
        k = np.arange(1, wb.shape[0] + 1, dtype=float)[:, None]
        g = np.exp(-step / tau_s * k)  # phi**k
        out[b0 : b0 + block] = g * (prev + np.cumsum(wb / g, axis=0))
        prev = out[b0 + wb.shape[0] - 1]
    grid = t[0] + step * np.arange(n)
    return np.stack([np.interp(t, grid, out[:, k]) for k in range(dims)], axis=1)


def gps_noise_parts(
    t: np.ndarray,
    rng: np.random.Generator,
    white_sd: float,
    gm_sd: float = 0.0,
    gm_tau_s: float = 45.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The two parts of :func:`gps_noise` [m], each (len(t), 2): the white error (sigma
    ``white_sd``) and the slow, Gauss-Markov error (``gm_sd``, ``gm_tau_s`` [s]; zeros
    without one), drawn from ``rng`` in that order (their sum is :func:`gps_noise`'s)."""
    t = np.asarray(t, dtype=float)
    white = rng.standard_normal((t.size, 2)) * white_sd
    slow = gauss_markov(t, gm_sd, gm_tau_s, rng) if gm_sd > 0 else np.zeros((t.size, 2))
    return white, slow


def gps_noise(
    t: np.ndarray,
    rng: np.random.Generator,
    white_sd: float,
    gm_sd: float = 0.0,
    gm_tau_s: float = 45.0,
) -> np.ndarray:
    """Position error [m] (len(t), 2): white (sigma ``white_sd``) plus Gauss-Markov (``gm_sd``)."""
    white, slow = gps_noise_parts(t, rng, white_sd, gm_sd, gm_tau_s)
    return white + slow if gm_sd > 0 else white


def interpolate_truth(truth: TruthStream, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Truth position (x, y) [m] at times t [s] by a cubic spline through the truth samples."""
    if len(truth) < 2:
        raise DataError(None, "truth: need at least 2 samples to interpolate")
    from scipy.interpolate import CubicSpline  # lazy: ~0.7 s to import

    cs = CubicSpline(truth.t, np.column_stack([truth.x, truth.y]), axis=0)
    p = cs(np.asarray(t, dtype=float))
    return p[:, 0], p[:, 1]


def _check_profile(profile: str) -> None:
    if profile not in GPS_PROFILES:
        raise DataError(None, f"unknown GPS profile {profile!r}; choose one of {GPS_PROFILES}")


def true_sigma_m(profile: str) -> float:
    """True per-axis 1-sigma [m] of a profile's fix error (white and Gauss-Markov together)."""
    _check_profile(profile)
    w, g, _ = NOISE_PARAMS[profile]
    return float(np.hypot(w, g))


def stated_sigma_m(profile: str) -> float | None:
    """Per-axis 1-sigma [m] a profile's fixes state in ``GpsStream.accuracy`` (None: none)."""
    _check_profile(profile)
    return STATED_SIGMA_M[profile]


@dataclass(frozen=True)
class DrawnGps:
    """A simulated receiver's fixes and the slow error the harness drew for them."""

    #: the fixes (:func:`degrade_gps`'s stream)
    gps: GpsStream
    #: the slow (Gauss-Markov) part of each fix's error [m], (len(gps), 2) east, north: the
    #: fix minus the truth at its time (less the latency) minus the white part; zeros for a
    #: profile without a slow error
    slow_xy: np.ndarray


def degrade_gps(
    truth: TruthStream,
    profile: str = "rtk",
    seed: int = 0,
    latency_s: float = 0.0,
    intervals: str = "aslan",
    origin: tuple[float, float] | None = None,
) -> GpsStream:
    """A GPS stream sampled from ``truth`` at irregular fix times, with profile noise.

    Args:
        truth: reference track (10-100 Hz), x/y [m].
        profile: one of :data:`GPS_PROFILES` (see module doc).
        seed: seed; fix times come from their own sub-stream (``SeedSequence(seed).spawn``),
            so one seed gives the same fix times under every profile.
        latency_s: receiver latency [s] >= 0: the fix stamped t holds the truth at t - latency_s.
        intervals: fix-interval distribution (``"aslan"`` or ``"uniform:a,b"``).
        origin: optional (lat, lon) [deg] of the ENU frame; when given, lat/lon are filled.
    Returns:
        GpsStream with t [s], x/y [m], lat/lon (if ``origin``), accuracy = the profile's
        stated per-axis 1-sigma [m] (:func:`stated_sigma_m`; ``None`` for ``"none"``).
        :func:`draw_gps` gives the same stream with the slow error it drew.
    """
    return draw_gps(truth, profile, seed, latency_s, intervals, origin).gps


def draw_gps(
    truth: TruthStream,
    profile: str = "rtk",
    seed: int = 0,
    latency_s: float = 0.0,
    intervals: str = "aslan",
    origin: tuple[float, float] | None = None,
) -> DrawnGps:
    """:func:`degrade_gps`'s stream (the same for the same arguments), with the slow
    error drawn for each fix (:class:`DrawnGps`): what no predictor can remove against the
    truth, on this drive."""
    _check_profile(profile)
    if not (np.isfinite(latency_s) and latency_s >= 0):
        raise DataError(None, f"latency {latency_s!r} s: must be >= 0")
    ss_times, ss_noise = np.random.SeedSequence(seed).spawn(2)
    t_fix = draw_fix_times(
        truth.t[0] + latency_s, truth.t[-1], np.random.default_rng(ss_times), intervals
    )
    x, y = interpolate_truth(truth, t_fix - latency_s)
    slow = np.zeros((t_fix.size, 2))
    if profile != "none":
        w, g, tau = NOISE_PARAMS[profile]
        white, slow = gps_noise_parts(t_fix, np.random.default_rng(ss_noise), w, g, tau)
        e = white + slow if g > 0 else white
        x, y = x + e[:, 0], y + e[:, 1]
    lat = lon = None
    if origin is not None:
        lat, lon = enu_to_latlon(x, y, origin[0], origin[1])
    stated = stated_sigma_m(profile)
    acc = None if stated is None else np.full(t_fix.size, stated)
    return DrawnGps(GpsStream(t_fix, x, y, lat, lon, acc), slow)


def enu_to_latlon(
    x: np.ndarray, y: np.ndarray, origin_lat: float, origin_lon: float
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of the ENU projection: (lat, lon) [deg] of local (x east, y north) [m], up = 0."""
    import pymap3d

    lat, lon, _ = pymap3d.enu2geodetic(
        np.asarray(x, float),
        np.asarray(y, float),
        np.zeros(np.size(x)),
        origin_lat,
        origin_lon,
        0.0,
    )
    return np.asarray(lat, dtype=float), np.asarray(lon, dtype=float)
