"""The built-in synthetic data set: kinematic drives with GPS, IMU, CAN speed and exact truth.

A route is a list of :class:`Segment` s (straight / arc / stop). The simulation is
fully vectorised:

1. geometry on an arc-length grid (5 cm): curvature per segment, smoothed over 4 m
   (transition curves), heading = integral of curvature, position = integral of heading;
2. a speed limit along the path (segment target speed, lateral acceleration <= 3 m/s^2
   in curves, 0 at stops), made reachable by forward / backward passes in v^2
   (acceleration <= 1.5 m/s^2, braking <= 2 m/s^2, as running minima);
3. time along the path from ds / v, with each stop's dwell inserted; resampled to
   100 Hz, speed smoothed twice with a 0.6 s box kernel (bounded jerk, exactly 0 at
   standstill) and re-integrated, so position, heading and speed are consistent.

The limits above are the defaults of :func:`simulate`'s keyword arguments (the built-in
data set); :mod:`posbench.scenarios.corpus` draws them per drive for the training corpus.

Streams (t in seconds from the start, ENU metres about :data:`ORIGIN_LAT`, :data:`ORIGIN_LON`,
the truth starting at (0, 0)):

- truth at 100 Hz: x, y, yaw (ENU, wrapped to [-pi, pi)), v;
- IMU at 50 Hz: ax = dv/dt, ay = v * yaw_rate (vehicle frame, y left) with white noise
  (0.05 m/s^2) and a small constant bias (sigma 0.05 m/s^2); yaw (noise 0.005 rad) and
  yaw_rate (noise 0.005 rad/s);
- CAN speed at 50 Hz (offset 10 ms from the IMU), noise 0.02 m/s, exactly 0 at standstill;
- GPS fixes at irregular 0.1-0.6 s intervals (the paper's distribution, with ~4 % late
  fixes 0.4-0.6 s), white noise 0.03 m plus a Gauss-Markov error (0.05 m, 30 s), and
  about one 1-2 s dropout per 40 s; lat/lon by the inverse ENU projection.

``meta.extra`` holds ``seed``, ``route`` and ``segments``: a list of
``[label, t_start, t_end]`` giving when each manoeuvre (straight, turn, roundabout,
start_stop = a standstill) happens.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from posbench.scenarios.degrade import (
    draw_intervals,
    drop_windows,
    enu_to_latlon,
    gps_noise,
    outage_windows,
)
from posbench.scenarios.drive import (
    FIXES_FROM_TRUTH,
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)

ORIGIN_LAT = 45.8
ORIGIN_LON = 16.0
EPOCH_S = 1_700_000_000.0
DT_TRUTH = 0.01
DS = 0.05
A_ACC = 1.5
A_DEC = 2.0
AY_MAX = 3.0
KAPPA_SMOOTH_M = 4.0
V_SMOOTH_S = 0.6
GPS_WHITE_SD = 0.03
GPS_GM_SD = 0.05
GPS_GM_TAU_S = 30.0
DEFAULT_ROUTES = ("mixed", "turns", "roundabout", "stop_and_go")


@dataclass(frozen=True)
class Segment:
    """One route piece.

    kind: ``"straight"`` (``length_m``), ``"arc"`` (signed heading change ``angle_rad``,
    + = left / counter-clockwise, at ``radius_m``) or ``"stop"`` (standstill ``dwell_s``).
    ``speed_mps`` is the target speed; ``label`` the scenario label (one of
    :data:`posbench.scenarios.labels.LABELS`) it belongs to; ``manoeuvre`` the finer kind (e.g.
    ``"lane_change"``, ``"u_turn"``; empty = ``label``); ``cont`` marks a segment that
    continues the previous segment's manoeuvre (the ring and exit of a roundabout, the
    second arc of a lane change), so the two share one time span.
    """

    kind: str
    length_m: float = 0.0
    angle_rad: float = 0.0
    radius_m: float = 0.0
    speed_mps: float = 0.0
    dwell_s: float = 0.0
    label: str = "straight"
    manoeuvre: str = ""
    cont: bool = False

    @property
    def path_length_m(self) -> float:
        if self.kind == "arc":
            return abs(self.angle_rad) * self.radius_m
        return self.length_m if self.kind == "straight" else 0.0


def straight(length_m: float, speed_mps: float) -> Segment:
    return Segment("straight", length_m=length_m, speed_mps=speed_mps, label="straight")


def turn(angle_deg: float, radius_m: float, speed_mps: float, label: str = "turn") -> Segment:
    return Segment(
        "arc", angle_rad=np.radians(angle_deg), radius_m=radius_m, speed_mps=speed_mps, label=label
    )


def stop(dwell_s: float) -> Segment:
    return Segment("stop", dwell_s=dwell_s, label="start_stop")


def roundabout(
    rng: np.random.Generator,
    j: Callable[[float, float], float],
    radius_m: float | None = None,
    speed_mps: float | None = None,
) -> list[Segment]:
    """Enter with a right turn, ~270 deg counter-clockwise around the ring, exit right.

    Default (both ``None``): ring radius 15-20 m at 7 m/s, entry / exit radius 10-12 m at
    6 m/s (the draws of the built-in routes). With ``radius_m`` [m] (and ``speed_mps``, the
    ring's target speed [m/s], default 7): entry / exit radius 0.6 x the ring's (6-15 m) at
    0.85 x the ring speed, ring angle 240-300 deg.
    """
    entry = j(30, 40)
    if radius_m is None:
        r_in = j(10, 12)
        ring = Segment(
            "arc",
            angle_rad=np.radians(j(260, 280)),
            radius_m=j(15, 20),
            speed_mps=7.0,
            label="roundabout",
            cont=True,
        )
        r_out, v_io = j(10, 12), 6.0
    else:
        v_ring = 7.0 if speed_mps is None else float(speed_mps)
        r_in = r_out = float(np.clip(0.6 * radius_m, 6.0, 15.0))
        ring = Segment(
            "arc",
            angle_rad=np.radians(j(240, 300)),
            radius_m=float(radius_m),
            speed_mps=v_ring,
            label="roundabout",
            cont=True,
        )
        v_io = 0.85 * v_ring
    return [
        turn(-entry, r_in, v_io, "roundabout"),
        ring,
        Segment(
            "arc",
            angle_rad=np.radians(-entry),
            radius_m=r_out,
            speed_mps=v_io,
            label="roundabout",
            cont=True,
        ),
    ]


def route_segments(route: str, rng: np.random.Generator) -> list[Segment]:
    """The segment list of a named route, lengths/speeds jittered by ``rng``."""

    def j(lo: float, hi: float) -> float:
        return float(rng.uniform(lo, hi))

    side = 1.0 if rng.random() < 0.5 else -1.0
    if route == "mixed":
        return [
            straight(j(70, 90), j(13, 15)),
            turn(-90, j(10, 13), 6.0),
            straight(j(110, 140), j(15, 18)),
            *roundabout(rng, j),
            straight(j(80, 100), j(11, 13)),
            stop(j(4, 6)),
            straight(j(100, 120), j(14, 16)),
            turn(90, j(12, 15), 6.5),
            straight(j(120, 150), j(16, 19)),
        ]
    if route == "turns":
        return [
            straight(j(60, 80), j(11, 13)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(90, 110), j(12, 14)),
            turn(-90 * side, j(10, 12), 5.5),
            straight(j(70, 90), j(11, 13)),
            turn(-90 * side, j(12, 14), 6.0),
            straight(j(100, 120), j(13, 15)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(80, 100), j(12, 14)),
            stop(j(3, 5)),
            straight(j(60, 80), j(10, 12)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(80, 100), j(13, 15)),
        ]
    if route == "roundabout":
        return [
            straight(j(100, 120), j(13, 15)),
            *roundabout(rng, j),
            straight(j(170, 200), j(15, 18)),
            *roundabout(rng, j),
            straight(j(140, 170), j(14, 17)),
        ]
    if route == "stop_and_go":
        return [
            straight(j(50, 70), j(10, 12)),
            stop(j(5, 8)),
            straight(j(60, 80), j(11, 13)),
            stop(j(3, 5)),
            straight(j(30, 40), j(8, 10)),
            stop(j(6, 9)),
            straight(j(90, 110), j(12, 14)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(50, 70), j(10, 12)),
            stop(j(4, 6)),
            straight(j(80, 100), j(12, 14)),
        ]
    if route == "straight":
        return [
            straight(j(400, 500), j(16, 20)),
            straight(j(300, 400), j(10, 12)),
            straight(j(400, 500), j(17, 20)),
        ]
    raise ValueError(
        f"unknown synthetic route {route!r}; choose one of {(*DEFAULT_ROUTES, 'straight')}"
    )


ROUTES = (*DEFAULT_ROUTES, "straight")


def _box(v: np.ndarray, width: int) -> np.ndarray:
    """Centred box filter (odd width) with edge padding; exact 0 where the window is all 0."""
    h = width // 2
    p = np.concatenate([np.full(h, v[0]), v, np.full(h, v[-1])])
    return np.convolve(p, np.full(2 * h + 1, 1.0 / (2 * h + 1)), mode="valid")


@dataclass(frozen=True)
class _Sim:
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray  # unwrapped [rad]
    v: np.ndarray
    yaw_rate: np.ndarray
    ax: np.ndarray
    segments: list[list]  # [label, t_start, t_end], label in scenarios.labels.LABELS
    manoeuvres: list[list]  # [manoeuvre, t_start, t_end], the finer kinds


def simulate(
    segments: list[Segment],
    yaw0: float = 0.0,
    dt: float = DT_TRUTH,
    *,
    a_acc: float = A_ACC,
    a_dec: float = A_DEC,
    ay_max: float = AY_MAX,
    v_smooth_s: float = V_SMOOTH_S,
    kappa_smooth_m: float = KAPPA_SMOOTH_M,
    ay_window_m: float = 0.0,
) -> _Sim:
    """Kinematic simulation of a route at ``dt`` [s] (see module doc). Starts at the first
    segment's target speed (0 if it is a stop).

    The vehicle limits default to the module constants (the built-in data set):
    ``a_acc`` acceleration and ``a_dec`` braking [m/s^2] of the reachable speed profile,
    ``ay_max`` lateral acceleration [m/s^2] of the curve speed limit, ``v_smooth_s`` the
    box kernel [s] the speed is smoothed with twice (bounds the jerk), ``kappa_smooth_m``
    the arc length [m] the curvature is smoothed over (transition curves). ``ay_window_m``
    [m] > 0 makes the curve speed limit hold that far before and after each point of the
    path (a running minimum): the speed smoothing averages over +-``v_smooth_s``, which
    otherwise carries the faster approach into a curve's entry and overshoots ``ay_max``;
    a window of at least ``v_smooth_s`` x the top speed keeps |v^2 kappa| <= ``ay_max``.
    """
    plen = np.array([s.path_length_m for s in segments])
    edges = np.concatenate([[0.0], np.cumsum(plen)])
    n_s = int(round(edges[-1] / DS)) + 1
    s = np.arange(n_s) * DS
    idx = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(segments) - 1)
    kseg = np.array(
        [np.sign(g.angle_rad) / g.radius_m if g.kind == "arc" else 0.0 for g in segments]
    )
    vseg = np.array([g.speed_mps for g in segments])
    kappa = _box(kseg[idx], int(kappa_smooth_m / DS) | 1)
    theta = yaw0 + np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * DS)])
    c, si = np.cos(theta), np.sin(theta)
    xs = np.concatenate([[0.0], np.cumsum(0.5 * (c[1:] + c[:-1]) * DS)])
    ys = np.concatenate([[0.0], np.cumsum(0.5 * (si[1:] + si[:-1]) * DS)])

    # speed limit and reachable profile (v^2 passes as running minima)
    vlat = np.sqrt(ay_max / np.maximum(np.abs(kappa), 1e-9))
    if ay_window_m > 0.0:
        from scipy.ndimage import minimum_filter1d

        vlat = minimum_filter1d(vlat, 2 * int(np.ceil(ay_window_m / DS)) + 1, mode="nearest")
    vlim = np.minimum(vseg[idx], vlat)
    stops = [(k, g.dwell_s) for k, g in enumerate(segments) if g.kind == "stop"]
    k_stop = np.array([int(round(edges[k] / DS)) for k, _ in stops], dtype=int)
    dwell = np.array([d for _, d in stops], dtype=float)
    vlim[k_stop] = 0.0
    u = vlim**2
    i = np.arange(n_s)
    uf = 2 * a_acc * DS * i + np.minimum.accumulate(u - 2 * a_acc * DS * i)
    ub = -2 * a_dec * DS * i + np.minimum.accumulate((u + 2 * a_dec * DS * i)[::-1])[::-1]
    vs = np.sqrt(np.maximum(np.minimum(uf, ub), 0.0))

    # time along the path, dwell inserted at the stops
    ts = np.concatenate([[0.0], np.cumsum(2 * DS / np.maximum(vs[1:] + vs[:-1], 1e-6))])
    off = np.zeros(n_s + 1)
    np.add.at(off, k_stop + 1, dwell)
    ts = ts + np.cumsum(off)[:-1]
    t_knots = np.insert(ts, k_stop + 1, ts[k_stop] + dwell)
    s_knots = np.insert(s, k_stop + 1, s[k_stop])

    t = np.arange(0.0, t_knots[-1], dt)
    s_raw = np.interp(t, t_knots, s_knots)
    v_raw = np.gradient(s_raw, dt)
    v_raw[np.interp(t, t_knots, np.insert(vs, k_stop + 1, 0.0)) == 0.0] = 0.0
    w = int(v_smooth_s / dt) | 1
    v = np.maximum(_box(_box(v_raw, w), w), 0.0)
    st = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    st = np.minimum(st, s[-1])
    x, y = np.interp(st, s, xs), np.interp(st, s, ys)
    yaw = np.interp(st, s, theta)
    yaw_rate = np.interp(st, s, kappa) * v
    ax = np.gradient(v, dt)

    # when each manoeuvre happens
    spans: list[list] = []
    n = t.size
    edges = edges.copy()
    for (k, _), ks in zip(stops, k_stop, strict=True):
        edges[k] = edges[k + 1] = s[ks]
    tol = 0.01  # [m] the smoothed speed stops within ~1 mm of a stop's arc length
    t_from = t[np.clip(np.searchsorted(st, edges + tol, side="right") - 1, 0, n - 1)]
    t_to = t[np.clip(np.searchsorted(st, edges - tol, side="left"), 0, n - 1)]
    still = v == 0.0
    d = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    r0, r1 = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    mans: list[list] = []
    for k, g in enumerate(segments):
        if g.kind == "stop":
            # the standstill run at this stop's arc length
            m = np.flatnonzero(np.abs(st[r0] - edges[k]) < 1.0)
            if m.size:
                spans.append(["start_stop", float(t[r0[m[0]]]), float(t[r1[m[0]]])])
                mans.append([g.manoeuvre or "start_stop", *spans[-1][1:]])
            continue
        if spans and (
            spans[-1][0] == g.label == "roundabout" or (g.cont and spans[-1][0] == g.label)
        ):
            spans[-1][2] = float(t_to[k + 1])
        else:
            spans.append([g.label, float(t_from[k]), float(t_to[k + 1])])
        if mans and g.cont:
            mans[-1][2] = float(t_to[k + 1])
        else:
            mans.append([g.manoeuvre or g.label, float(t_from[k]), float(t_to[k + 1])])
    return _Sim(t, x, y, yaw, v, yaw_rate, ax, spans, mans)


def _hermite(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, tq: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite interpolation of the truth (positions and velocities) at times tq."""
    k = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    h = t[k + 1] - t[k]
    u = (tq - t[k]) / h
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2

    def f(p: np.ndarray, dp: np.ndarray) -> np.ndarray:
        return h00 * p[k] + h10 * h * dp[k] + h01 * p[k + 1] + h11 * h * dp[k + 1]

    return f(x, vx), f(y, vy)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def imu_stream(
    t: np.ndarray,
    yaw: np.ndarray,
    v: np.ndarray,
    yaw_rate: np.ndarray,
    ax: np.ndarray,
    rng: np.random.Generator,
    step: int = 2,
    accel_sd: float = 0.05,
    bias_sd: float = 0.05,
    yaw_sd: float = 0.005,
    yaw_rate_sd: float = 0.005,
    gyro_bias_sd: float = 0.0,
) -> ImuStream:
    """IMU samples from the 100 Hz truth: every ``step``-th sample (2 = 50 Hz, 1 = 100 Hz).

    ax = dv/dt, ay = v * yaw_rate [m/s^2, vehicle frame x forward, y left] with white noise
    ``accel_sd`` and a constant bias per axis drawn with sigma ``bias_sd``; yaw [rad, ENU,
    wrapped] with white noise ``yaw_sd``; yaw_rate [rad/s] with white noise ``yaw_rate_sd``
    and (if ``gyro_bias_sd`` > 0) a constant bias drawn with that sigma.
    """
    ii = np.arange(0, t.size, step)
    m = ii.size
    bias = rng.normal(0.0, bias_sd, 2)
    fax = ax[ii] + bias[0] + rng.normal(0.0, accel_sd, m)
    fay = v[ii] * yaw_rate[ii] + bias[1] + rng.normal(0.0, accel_sd, m)
    fyaw = _wrap(yaw[ii] + rng.normal(0.0, yaw_sd, m))
    fyr = yaw_rate[ii] + rng.normal(0.0, yaw_rate_sd, m)
    if gyro_bias_sd > 0.0:
        fyr = fyr + rng.normal(0.0, gyro_bias_sd)
    return ImuStream(t[ii], fax, fay, fyaw, fyr)


def can_speed_stream(t: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> SpeedStream:
    """CAN speed at 50 Hz from the 100 Hz truth (the odd samples, 10 ms after the IMU's):
    white noise 0.02 m/s, never negative, exactly 0 at standstill."""
    jj = np.arange(1, t.size, 2)
    vc = np.maximum(v[jj] + rng.normal(0.0, 0.02, jj.size), 0.0)
    vc[v[jj] == 0.0] = 0.0
    return SpeedStream(t[jj], vc)


def gps_stream(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    yaw: np.ndarray,
    v: np.ndarray,
    r_times: np.random.Generator,
    r_gps: np.random.Generator,
    r_drop: np.random.Generator,
) -> tuple[GpsStream, list[tuple[float, float]]]:
    """GPS fixes from the truth (t [s], x/y [m ENU], yaw [rad], v [m/s]) and the dropouts.

    Fix intervals from the paper's distribution clipped to 0.1-0.6 s with ~4 % late fixes
    (0.4-0.6 s); positions by cubic Hermite interpolation of the truth plus white noise
    (:data:`GPS_WHITE_SD`) and a Gauss-Markov error (:data:`GPS_GM_SD`, :data:`GPS_GM_TAU_S`),
    stated accuracy their combined per-axis sigma; one 1-2 s dropout per ~40 s.
    Returns the stream and the outages ``[(t_last_fix, t_next_fix), ...]`` [s].
    """
    span = t[-1] - t[0]
    k = int(span / 0.2 * 1.3) + 16
    d = np.clip(draw_intervals(k, r_times, "aslan"), 0.1, 0.6)
    late = r_times.random(k) < 0.04
    d[late] = r_times.uniform(0.4, 0.6, int(late.sum()))
    tf = t[0] + r_times.random() * 0.2 + np.concatenate([[0.0], np.cumsum(d)])
    tf = tf[tf <= t[-1]]
    gx, gy = _hermite(t, x, y, v * np.cos(yaw), v * np.sin(yaw), tf)
    e = gps_noise(tf, r_gps, GPS_WHITE_SD, GPS_GM_SD, GPS_GM_TAU_S)
    gx, gy = gx + e[:, 0], gy + e[:, 1]
    lat, lon = enu_to_latlon(gx, gy, ORIGIN_LAT, ORIGIN_LON)
    # stated accuracy: the true per-axis 1-sigma of the noise added (an honest receiver)
    acc = np.full(tf.size, float(np.hypot(GPS_WHITE_SD, GPS_GM_SD)))
    gps = GpsStream(tf, gx, gy, lat, lon, acc)
    n_out = max(1, int(round(span / 40.0)))
    win = outage_windows(
        float(tf[0]),
        float(tf[-1]),
        r_drop.uniform(1.0, 2.0, n_out),
        r_drop,
        min_sep_s=10.0,
        repeat=False,
    )
    return drop_windows(gps, win)


def generate_drive(
    seed: int = 0, name: str | None = None, route: str = "mixed", duration_s: float | None = None
) -> Drive:
    """One synthetic drive (see module doc). Deterministic for (seed, route, duration_s).

    Args:
        seed: random seed (route jitter, start heading, sensor noise, fix times, dropouts).
        name: drive name; default ``"synthetic-<route>-s<seed>"``.
        route: one of :data:`ROUTES`.
        duration_s: cut the drive to this length [s]; the route repeats if it is shorter.
    """
    if route not in ROUTES:
        raise ValueError(f"unknown synthetic route {route!r}; choose one of {ROUTES}")
    if duration_s is not None and not duration_s > 1.0:
        raise ValueError(f"duration_s must be > 1 s, got {duration_s!r}")
    ss = np.random.SeedSequence([int(seed), zlib.crc32(route.encode())])
    r_route, r_imu, r_speed, r_times, r_gps, r_drop = (
        np.random.default_rng(q) for q in ss.spawn(6)
    )
    segs = route_segments(route, r_route)
    yaw0 = float(r_route.uniform(-np.pi, np.pi))
    sim = simulate(segs, yaw0)
    while duration_s is not None and sim.t[-1] < duration_s:
        reps = int(np.ceil(duration_s / max(sim.t[-1], 1.0))) + 1
        sim = simulate(segs * reps, yaw0)
    n = sim.t.size if duration_s is None else int(np.searchsorted(sim.t, duration_s, "right"))
    t, x, y, yaw, v = sim.t[:n], sim.x[:n], sim.y[:n], sim.yaw[:n], sim.v[:n]
    yaw_rate, ax = sim.yaw_rate[:n], sim.ax[:n]
    truth = TruthStream(t, x, y, _wrap(yaw), v)

    imu = imu_stream(t, yaw, v, yaw_rate, ax, r_imu)
    speed = can_speed_stream(t, v, r_speed)
    gps, outages = gps_stream(t, x, y, yaw, v, r_times, r_gps, r_drop)

    segments = [sp for sp in sim.segments if sp[1] < t[-1]]
    if segments:
        segments[-1][2] = min(segments[-1][2], float(t[-1]))
    meta = DriveMeta(
        fix_source=FIXES_FROM_TRUTH,
        name=name or f"synthetic-{route}-s{seed}",
        source=f"synthetic:{route}:s{seed}",
        format="synthetic",
        epoch_s=EPOCH_S,
        origin_lat=ORIGIN_LAT,
        origin_lon=ORIGIN_LON,
        projection="enu",
        time_source="simulated",
        extra={
            "seed": int(seed),
            "route": route,
            "segments": segments,
            "gps_outages": [list(o) for o in outages],
        },
    )
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)


def default_drives(seed: int = 0) -> list[Drive]:
    """The built-in default data set: 4 drives (mixed, turns, roundabout, stop_and_go),
    60-120 s each, a few minutes in all."""
    return [generate_drive(seed=seed, route=r) for r in DEFAULT_ROUTES]
