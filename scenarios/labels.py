"""Scenario labels: "straight", "turn", "roundabout", "start_stop" per query time.

The reference track (truth or fitted fixes; t [s], x/y [m, local ENU]) is resampled
to a regular grid (cubic Hermite, so fix gaps in curves stay curved) and smoothed with a
Savitzky-Golay filter, which also gives velocity and acceleration; from them speed v [m/s],
tangential acceleration [m/s^2], yaw rate [rad/s] (= (x' y'' - y' x'') / v^2) and
curvature [1/m] (= yaw rate / v). A CAN / wheel speed stream, when given, replaces the
track's speed for the standstill and acceleration tests. Then, on the grid (thresholds in
:class:`LabelThresholds`):

- ``start_stop``: standstill (v < 0.15 km/h, the paper's threshold), or within
  ``near_stop_s`` of a standstill while |acceleration| > ``accel_mps2``;
- ``roundabout``: a run of same-sign turning (|yaw rate| > ``roundabout_yaw_rate_rps``,
  interruptions < ``roundabout_gap_s`` bridged) whose heading change exceeds
  ``roundabout_heading_deg``, at a mean radius (path length / heading change) below
  ``roundabout_radius_m`` and a mean turning rate of at least that heading change per
  ``roundabout_window_s``; opposite-sign turning runs that end within ``entry_exit_s``
  before it (the entry turn) or start within ``entry_exit_s`` after it (the exit turn)
  belong to it, with the time between;
- ``turn``: |yaw rate| > ``turn_yaw_rate_rps`` or, while moving (v > ``moving_mps``),
  |curvature| > ``turn_curvature_inv_m``, sustained for at least ``turn_min_duration_s``;
- ``straight``: everything else.

Priority: start_stop > roundabout > turn > straight. Query times outside the track take
the label of the nearest end. Long gaps in the track are bridged by a cubic through the
neighbouring fixes, which follows a curve for a second or two but not much longer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posbench.scenarios.errors import DataError

LABELS = ("straight", "turn", "roundabout", "start_stop")
LABEL_DTYPE = "<U10"


@dataclass(frozen=True)
class LabelThresholds:
    """Thresholds of :func:`label_times` (units in the names: s, m, m/s, m/s^2, rad/s, deg)."""

    #: step [s] of the regular grid the track is resampled to
    grid_dt_s: float = 0.05
    #: Savitzky-Golay window [s] (cubic) smoothing the track
    smooth_s: float = 1.5
    #: standstill below this speed [m/s]: the paper's 0.15 km/h
    standstill_mps: float = 0.15 / 3.6
    #: accelerating / braking this close [s] to a standstill counts as start_stop
    near_stop_s: float = 3.0
    #: |tangential acceleration| [m/s^2] that counts as starting / stopping
    accel_mps2: float = 0.3
    #: below this speed [m/s] heading is undefined and yaw rate taken as 0
    heading_min_speed_mps: float = 0.5
    #: |yaw rate| [rad/s] of a turn
    turn_yaw_rate_rps: float = 0.1
    #: |curvature| [1/m] of a turn while moving (radius < 50 m)
    turn_curvature_inv_m: float = 1.0 / 50.0
    #: "moving" for the curvature test [m/s]
    moving_mps: float = 1.0
    #: a turn must last at least this long [s]
    turn_min_duration_s: float = 1.0
    #: |yaw rate| [rad/s] for a sample to be part of a roundabout's turning run
    roundabout_yaw_rate_rps: float = 0.1
    #: interruptions [s] of a turning run that are bridged
    roundabout_gap_s: float = 0.5
    #: heading change [deg] a roundabout's run must exceed
    roundabout_heading_deg: float = 200.0
    #: ... at an average rate of at least that change per this time [s]
    roundabout_window_s: float = 30.0
    #: ... at a mean radius [m] below this
    roundabout_radius_m: float = 30.0
    #: opposite entry / exit turns this close [s] to the run belong to the roundabout
    entry_exit_s: float = 3.0


def _savgol(a: np.ndarray, win: int, deriv: int, dt: float) -> np.ndarray:
    """Cubic Savitzky-Golay smoothing / derivative (odd ``win`` <= len(a)), like
    ``scipy.signal.savgol_filter(mode="interp")``: the end windows' fits give the ends."""
    h = win // 2
    z = np.arange(-h, h + 1, dtype=float)
    vander = np.vander(z, 4, increasing=True)
    pinv = np.linalg.pinv(vander)  # (4, win): data -> coefficients in z
    # derivative of order `deriv` of sum c_k z^k, at every z of the window
    k = np.arange(4)
    fact = np.array([np.prod(np.arange(j - deriv + 1, j + 1)) if j >= deriv else 0.0 for j in k])
    powz = np.where(k >= deriv, z[:, None] ** np.maximum(k - deriv, 0), 0.0) * fact
    ev = powz @ pinv / dt**deriv  # (win, win): window data -> derivative at each position
    out = np.convolve(a, ev[h][::-1], mode="same")
    out[:h] = ev[:h] @ a[:win]
    out[-h:] = ev[h + 1 :] @ a[-win:]
    return out


def _resample(t: np.ndarray, a: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation, slopes from the parabola through each fix and its two
    neighbours (second-order accurate on irregular times, dominated by the nearer
    neighbour): follows curves through fix gaps where linear interpolation cuts a chord."""
    if t.size < 3:
        return np.interp(tq, t, a)
    m = np.empty_like(a)
    h0, h1 = t[1:-1] - t[:-2], t[2:] - t[1:-1]
    m[1:-1] = (h0 * h0 * (a[2:] - a[1:-1]) + h1 * h1 * (a[1:-1] - a[:-2])) / (h0 * h1 * (h0 + h1))
    m[0] = (a[1] - a[0]) / (t[1] - t[0])
    m[-1] = (a[-1] - a[-2]) / (t[-1] - t[-2])
    k = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    h = t[k + 1] - t[k]
    u = np.clip((tq - t[k]) / h, 0.0, 1.0)
    u2, u3 = u * u, u * u * u
    return (
        (2 * u3 - 3 * u2 + 1) * a[k]
        + (u3 - 2 * u2 + u) * h * m[k]
        + (-2 * u3 + 3 * u2) * a[k + 1]
        + (u3 - u2) * h * m[k + 1]
    )


def _dilate(mask: np.ndarray, h: int) -> np.ndarray:
    """True within ``h`` samples of any True sample."""
    c = np.concatenate([[0], np.cumsum(mask, dtype=np.int64)])
    i = np.arange(mask.size)
    return (c[np.minimum(i + h + 1, mask.size)] - c[np.maximum(i - h, 0)]) > 0


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (inclusive) indices of the True runs of a 1-D boolean mask."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1


def _fill(n: int, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Boolean mask of length n, True on the inclusive ranges [starts, ends]."""
    delta = np.zeros(n + 1, dtype=np.int64)
    np.add.at(delta, starts, 1)
    np.add.at(delta, ends + 1, -1)
    return np.cumsum(delta[:-1]) > 0


def _keep_long(mask: np.ndarray, n_min: int) -> np.ndarray:
    """Only the True runs at least ``n_min`` samples long."""
    s, e = _runs(mask)
    ok = (e - s + 1) >= n_min
    return _fill(mask.size, s[ok], e[ok])


def _bridge(mask: np.ndarray, n_gap: int) -> np.ndarray:
    """Fill False runs shorter than ``n_gap`` samples lying between True samples."""
    s, e = _runs(~mask)
    inner = (s > 0) & (e < mask.size - 1) & ((e - s + 1) < n_gap)
    return mask | _fill(mask.size, s[inner], e[inner])


def _roundabouts(
    yr: np.ndarray, v: np.ndarray, moving: np.ndarray, dt: float, th: LabelThresholds
) -> np.ndarray:
    n = yr.size
    n_gap = max(1, int(round(th.roundabout_gap_s / dt)))
    heading = np.concatenate([[0.0], np.cumsum(yr * dt)])
    dist = np.concatenate([[0.0], np.cumsum(v * dt)])
    member = {
        sg: _bridge(moving & (sg * yr > th.roundabout_yaw_rate_rps), n_gap) for sg in (1.0, -1.0)
    }
    runs = {sg: _runs(m) for sg, m in member.items()}
    out = np.zeros(n, dtype=bool)
    h_min = np.radians(th.roundabout_heading_deg)
    gap = th.entry_exit_s / dt
    for sg in (1.0, -1.0):
        s, e = runs[sg]
        turned = np.abs(heading[e + 1] - heading[s])
        length = dist[e + 1] - dist[s]
        dur = (e - s + 1) * dt
        ok = (
            (turned > h_min)
            & (length < th.roundabout_radius_m * turned)
            & (turned / dur >= h_min / th.roundabout_window_s)
        )
        rs, re = s[ok], e[ok]
        if rs.size == 0:
            continue
        out |= _fill(n, rs, re)
        os_, oe = runs[-sg]
        if os_.size == 0:
            continue
        entry = ((rs[:, None] - oe[None, :]) >= 0) & ((rs[:, None] - oe[None, :]) <= gap)
        exit_ = ((os_[None, :] - re[:, None]) >= 0) & ((os_[None, :] - re[:, None]) <= gap)
        ie = np.nonzero(entry)
        ix = np.nonzero(exit_)
        out |= _fill(
            n, np.concatenate([os_[ie[1]], re[ix[0]]]), np.concatenate([rs[ie[0]], oe[ix[1]]])
        )
    return out


def label_grid(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    speed_t: np.ndarray | None = None,
    speed_v: np.ndarray | None = None,
    thresholds: LabelThresholds | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Labels on the regular grid: (grid times [s], labels '<U10'). See the module doc."""
    th = thresholds or LabelThresholds()
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.ndim != 1 or t.shape != x.shape or t.shape != y.shape:
        raise DataError(None, "labels: t, x, y must be 1-D arrays of one length")
    if t.size < 2 or not np.all(np.diff(t) > 0) or not np.all(np.isfinite(x) & np.isfinite(y)):
        raise DataError(
            None, "labels: reference track needs >= 2 finite samples with strictly increasing times"
        )
    dt = th.grid_dt_s
    g = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)
    n = g.size
    gx, gy = _resample(t, x, g), _resample(t, y, g)
    win = min(int(round(th.smooth_s / dt)) | 1, n if n % 2 else n - 1)

    def deriv(a: np.ndarray, order: int) -> np.ndarray:
        if win >= 5:
            return _savgol(a, win, order, dt)
        d = a
        for _ in range(order):
            d = np.gradient(d, dt) if n > 1 else np.zeros(n)
        return d

    dx, dy, ddx, ddy = deriv(gx, 1), deriv(gy, 1), deriv(gx, 2), deriv(gy, 2)
    v_pos = np.hypot(dx, dy)
    if speed_t is not None and speed_v is not None and np.size(speed_t) >= 2:
        v = np.interp(g, np.asarray(speed_t, float), np.asarray(speed_v, float))
    else:
        v = v_pos
    acc = deriv(v, 1)

    still = v < th.standstill_mps
    near = _dilate(still, int(round(th.near_stop_s / dt)))
    start_stop = still | (near & (np.abs(acc) > th.accel_mps2))

    has_heading = v_pos > th.heading_min_speed_mps
    yr = np.where(has_heading, (dx * ddy - dy * ddx) / np.maximum(v_pos, 1e-9) ** 2, 0.0)
    kappa = np.where(has_heading, yr / np.maximum(v_pos, 1e-9), 0.0)
    moving = v_pos > th.moving_mps
    turning = (np.abs(yr) > th.turn_yaw_rate_rps) | (
        moving & (np.abs(kappa) > th.turn_curvature_inv_m)
    )
    turn = _keep_long(turning, max(1, int(round(th.turn_min_duration_s / dt))))
    rb = _roundabouts(yr, v_pos, has_heading, dt, th)

    labels = np.full(n, "straight", dtype=LABEL_DTYPE)
    labels[turn] = "turn"
    labels[rb] = "roundabout"
    labels[start_stop] = "start_stop"
    return g, labels


def label_times(
    t_query: np.ndarray,
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    speed_t: np.ndarray | None = None,
    speed_v: np.ndarray | None = None,
    thresholds: LabelThresholds | None = None,
) -> np.ndarray:
    """Scenario label of each query time [s] from a reference track (see the module doc).

    Args:
        t_query: times [s] to label.
        t, x, y: reference track, t [s] strictly increasing, x/y [m] (local ENU).
        speed_t, speed_v: optional vehicle speed stream (t [s], v [m/s]).
        thresholds: :class:`LabelThresholds` (defaults if ``None``).
    Returns:
        array of ``'<U10'`` labels, one of :data:`LABELS` per query time.
    """
    tq = np.asarray(t_query, dtype=float)
    if tq.size == 0:
        return np.empty(tq.shape, dtype=LABEL_DTYPE)
    g, labels = label_grid(t, x, y, speed_t, speed_v, thresholds)
    dt = g[1] - g[0] if g.size > 1 else 1.0
    k = np.clip(np.rint((tq - g[0]) / dt), 0, g.size - 1).astype(np.int64)
    return labels[k]


def label_shares(labels: np.ndarray) -> dict[str, float]:
    """Fraction of samples [0..1] per label, for every label in :data:`LABELS` (0.0 if absent)."""
    labels = np.asarray(labels)
    n = labels.size
    return {lab: (float(np.count_nonzero(labels == lab)) / n if n else 0.0) for lab in LABELS}
