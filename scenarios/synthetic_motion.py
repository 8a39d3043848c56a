"""The kinematic simulator of the synthetic drives: a route as :class:`Segment` s (straight /
arc / stop) driven to a consistent truth (position, heading, speed, yaw rate,
acceleration).

The simulation is fully vectorised:

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

Lengths in metres, speeds in m/s, times in seconds from the start, positions ENU metres
starting at (0, 0), headings in radians (counter-clockwise from east).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DT_TRUTH = 0.01
DS = 0.05
A_ACC = 1.5
A_DEC = 2.0
AY_MAX = 3.0
KAPPA_SMOOTH_M = 4.0
V_SMOOTH_S = 0.6


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
