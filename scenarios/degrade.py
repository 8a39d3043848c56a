"""Turn a reference track into a realistic GPS stream:
irregular fix times, noise, latency, dropouts.

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

Dropouts (:func:`apply_dropouts`, profiles listed in :data:`DROPOUT_PROFILES`)
    ``"none"``        keep every fix;
    ``"random:p"``    lose each fix independently with probability p (0 <= p < 1);
    ``"outages"``     outages of 0.5, 1, 2 and 5 s (:data:`OUTAGE_LENGTHS_S`), in random
                      order at seeded random non-overlapping times, each preceded and
                      followed by >= 10 s of normal reception (the first starts >= 10 s
                      into the stream); the set is repeated ``floor(T / (2 (sum L + 10 n)))``
                      times (at least once) on long streams of duration T; when turn times
                      are given, half of the outages (rounded up) are centred on a turn
                      time where one fits. Lengths that no longer fit are left out: the
                      returned outage list says which were placed;
    ``"outage:L"``    like ``"outages"`` with the single length L seconds;
    ``"outage-lengths"`` outages of the lengths the GNSS/INS field reports, 1, 2, 5, 10, 30
                      and 60 s (:data:`FIELD_OUTAGE_LENGTHS_S`), placed by
                      :func:`packed_outage_windows`: longest first, each length the
                      stream still has room for (the same >= 10 s of reception before each
                      outage, the last ending >= 1 s before the stream does), so a short
                      drive gets its short lengths and only a long drive a 60 s one; the
                      set is repeated on long streams as for ``"outages"``.
    Every fix stamped inside an outage window [a, a + L] is removed.
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
DROPOUT_PROFILES = ("none", "random:p", "outages", "outage:L", "outage-lengths")
OUTAGE_LENGTHS_S = (0.5, 1.0, 2.0, 5.0)
#: the profile whose outages are the lengths the GNSS/INS field reports errors after
FIELD_OUTAGES = "outage-lengths"
#: its lengths [s] (error after 10, 30 and 60 s of GNSS outage is what IMU bridging reports)
FIELD_OUTAGE_LENGTHS_S = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0)
OUTAGE_SEPARATION_S = 10.0

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


def nominal_accuracy_m(profile: str) -> float:
    """Horizontal RMS error [m] of a noise profile (sqrt of both axes' variances)."""
    _check_profile(profile)
    w, g, _ = NOISE_PARAMS[profile]
    return float(np.sqrt(2.0 * (w * w + g * g)))


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


# ----------------------------------------------------------------------------- dropouts


def _free_intervals(lo: float, hi: float, forbidden: list[tuple[float, float]]) -> np.ndarray:
    """[lo, hi] minus the union of open ``forbidden`` intervals, as an (k, 2) array."""
    if hi < lo:
        return np.empty((0, 2))
    out = []
    cur = lo
    for a, b in sorted(forbidden):
        if b <= cur:
            continue
        if a > cur:
            out.append((cur, min(a, hi)))
        cur = max(cur, b)
        if cur >= hi:
            break
    if cur <= hi:
        out.append((cur, hi))
    arr = np.asarray([(a, b) for a, b in out if b >= a], dtype=float)
    return arr.reshape(-1, 2)


def _sample_in(free: np.ndarray, rng: np.random.Generator) -> float:
    """A uniform point in a union of closed intervals (length-weighted)."""
    w = free[:, 1] - free[:, 0]
    if w.sum() <= 0:
        return float(free[rng.integers(free.shape[0]), 0])
    k = int(np.searchsorted(np.cumsum(w), rng.random() * w.sum(), side="right"))
    k = min(k, free.shape[0] - 1)
    return float(free[k, 0] + rng.random() * w[k])


def outage_windows(
    t_start: float,
    t_end: float,
    lengths: Sequence[float] | np.ndarray,
    rng: np.random.Generator,
    t_turns: np.ndarray | None = None,
    min_sep_s: float = OUTAGE_SEPARATION_S,
    repeat: bool = True,
) -> np.ndarray:
    """Seeded non-overlapping outage windows, shape (k, 2) of [start, end] [s], sorted.

    Each window is preceded by >= ``min_sep_s`` of reception (from ``t_start`` or the
    previous window) and followed by >= ``min_sep_s`` before the next one, and ends
    >= 1 s before ``t_end``. With ``repeat`` the length set is repeated
    ``max(1, floor(T / (2 (sum(lengths) + min_sep_s n))))`` times. With ``t_turns``
    (times of turning, [s]) the first half (rounded up) of the shuffled outages are
    centred on a random turn time where that fits. Lengths that do not fit are skipped.
    """
    length_set = np.asarray(lengths, dtype=float)
    span = float(t_end) - float(t_start)
    reps = 1
    if repeat and length_set.size:
        reps = max(1, int(span // (2.0 * (length_set.sum() + min_sep_s * length_set.size))))
    todo = rng.permutation(np.tile(length_set, reps))
    n_turn = int(np.ceil(todo.size / 2)) if t_turns is not None and np.size(t_turns) else 0
    turns = np.sort(np.asarray(t_turns, dtype=float)) if n_turn else np.empty(0)
    placed: list[tuple[float, float]] = []
    for i, length in enumerate(todo):
        lo, hi = t_start + min_sep_s, t_end - 1.0 - length
        forbidden = [(a - min_sep_s - length, b + min_sep_s) for a, b in placed]
        free = _free_intervals(lo, hi, forbidden)
        if free.size == 0:
            continue
        start = None
        if i < n_turn:
            cand = turns - length / 2.0
            k = np.searchsorted(free[:, 0], cand, side="right") - 1
            ok = (k >= 0) & (cand <= free[np.maximum(k, 0), 1])
            if np.any(ok):
                start = float(rng.choice(cand[ok]))
        if start is None:
            start = _sample_in(free, rng)
        placed.append((start, start + float(length)))
    return np.asarray(sorted(placed), dtype=float).reshape(-1, 2)


def packed_outage_windows(
    t_start: float,
    t_end: float,
    lengths: Sequence[float] | np.ndarray,
    rng: np.random.Generator,
    min_sep_s: float = OUTAGE_SEPARATION_S,
    repeat: bool = True,
) -> np.ndarray:
    """Seeded non-overlapping outage windows of as many of ``lengths`` [s] as fit, shape
    (k, 2) of [start, end] [s], sorted.

    Each window is preceded by >= ``min_sep_s`` of reception (from ``t_start`` or the
    previous window) and the last ends >= 1 s before ``t_end``, as in
    :func:`outage_windows`. The lengths are taken longest first (a long outage fits fewer
    drives than a short one), each kept while the kept ones and their separations still
    fit into the span; with ``repeat`` the set is taken ``max(1, floor(T / (2 (sum(lengths)
    + min_sep_s n))))`` times (as :func:`outage_windows` repeats it). The kept windows are
    then shuffled and the spare time is spread over the gaps at random (uniform spacings),
    so that where a length falls along the drive does not depend on its length.
    """
    length_set = np.sort(np.asarray(lengths, dtype=float))[::-1]
    span = float(t_end) - float(t_start) - 1.0
    reps = 1
    if repeat and length_set.size:
        reps = max(1, int((span + 1.0) // (2.0 * (length_set.sum() + min_sep_s * length_set.size))))
    kept: list[float] = []
    used = 0.0
    for length in np.tile(length_set, reps):
        if used + min_sep_s + length <= span:
            kept.append(float(length))
            used += min_sep_s + length
    if not kept:
        return np.empty((0, 2))
    order = rng.permutation(len(kept))
    spare = span - used
    cuts = np.sort(rng.random(len(kept))) * spare  # spare time before each window, cumulative
    placed, t = [], float(t_start)
    prev_cut = 0.0
    for i, k in enumerate(order):
        t += min_sep_s + (cuts[i] - prev_cut)
        prev_cut = cuts[i]
        placed.append((t, t + kept[k]))
        t += kept[k]
    return np.asarray(placed, dtype=float).reshape(-1, 2)


def parse_dropouts(profile: str) -> tuple[str, float]:
    bad = DataError(
        None,
        f"unknown dropout profile {profile!r}; use 'none', 'random:p' "
        f"(0 <= p < 1), 'outages', 'outage:L' (L > 0 seconds) or '{FIELD_OUTAGES}'",
    )
    if profile in ("none", "outages", FIELD_OUTAGES):
        return profile, float("nan")
    for kind in ("random", "outage"):
        if profile.startswith(kind + ":"):
            try:
                val = float(profile[len(kind) + 1 :])
            except ValueError:
                raise bad from None
            if (kind == "random" and 0.0 <= val < 1.0) or (
                kind == "outage" and 0.0 < val and np.isfinite(val)
            ):
                return kind, val
            raise bad
    raise bad


def _outage_bounds(t_kept: np.ndarray, a: np.ndarray, b: np.ndarray) -> list[tuple[float, float]]:
    """(last kept fix before a, first kept fix after b - or b itself if none) per window."""
    if a.size == 0:
        return []
    n = t_kept.size
    i = np.searchsorted(t_kept, a, side="left") - 1
    j = np.searchsorted(t_kept, b, side="right")
    padded = np.concatenate([t_kept, [np.nan]])  # index n -> nan
    before = np.where(i >= 0, padded[np.where(i >= 0, i, n)], a)
    after = np.where(j < n, padded[np.minimum(j, n)], b)
    return [(float(p), float(q)) for p, q in zip(before, after, strict=True)]


def apply_dropouts(
    gps: GpsStream, profile: str, seed: int, t_turns: np.ndarray | None = None
) -> tuple[GpsStream, list[tuple[float, float]]]:
    """Remove fixes by a dropout profile (see module doc).

    Returns:
        (thinned stream, outages) where each outage is (t of the last fix before it [s],
        t of the first fix after it [s], or the outage's end when no fix follows). For
        ``"random:p"`` an outage is each maximal run of lost fixes.
    """
    kind, val = parse_dropouts(profile)
    if kind == "none" or len(gps) == 0:
        return gps, []
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xD50]))
    t = gps.t
    if kind == "random":
        lost = rng.random(t.size) < val
        if not lost.any():
            return gps, []
        edges = np.diff(np.concatenate([[0], lost.astype(np.int8), [0]]))
        s, e = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        keep = ~lost
        out = [
            (
                float(t[i - 1]) if i > 0 else float(t[i]),
                float(t[j + 1]) if j + 1 < t.size else float(t[j]),
            )
            for i, j in zip(s, e, strict=True)
        ]
        return gps.take(keep), out
    if kind == FIELD_OUTAGES:
        win = packed_outage_windows(float(t[0]), float(t[-1]), FIELD_OUTAGE_LENGTHS_S, rng)
        return drop_windows(gps, win)
    lengths = OUTAGE_LENGTHS_S if kind == "outages" else (val,)
    win = outage_windows(float(t[0]), float(t[-1]), lengths, rng, t_turns)
    return drop_windows(gps, win)


def drop_windows(
    gps: GpsStream, windows: np.ndarray
) -> tuple[GpsStream, list[tuple[float, float]]]:
    """Remove fixes stamped inside closed windows [a, b] (k, 2); return stream and outages."""
    windows = np.asarray(windows, dtype=float).reshape(-1, 2)
    t = gps.t
    inside = np.zeros(t.size, dtype=bool)
    if windows.size:
        i0 = np.searchsorted(t, windows[:, 0], side="left")
        i1 = np.searchsorted(t, windows[:, 1], side="right")
        delta = np.zeros(t.size + 1, dtype=np.int64)
        np.add.at(delta, i0, 1)
        np.add.at(delta, i1, -1)
        inside = np.cumsum(delta[:-1]) > 0
    thin = gps.take(~inside)
    return thin, _outage_bounds(thin.t, windows[:, 0], windows[:, 1])
