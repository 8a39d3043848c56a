"""The steps of :mod:`posbench.predictors.kalman.tuning.gradient`'s batched Kalman filter (numpy
only).

One drive becomes a time-ordered list of *steps* in the runner's order (at equal times the
fix first, then the IMU, then the speed): a **fix step** (a position measurement) or a
**sensor step** (the IMU sample and / or the wheel speed stamped at that time). Each step
is one linear measurement of the state ``[x, y, vx, vy, ax, ay]`` (m, m/s, m/s^2, local
ENU) with up to 4 rows, ``z = H s + noise``: rows 0-1 hold the fix (x, y) or the IMU's
world acceleration (ax, ay), rows 2-3 the speed along the heading (row 2) or, below the
stop speed, a zero-velocity update (rows 2 and 3). An unused row has ``H = 0``, ``z = 0``
and unit variance, so it changes nothing. The vehicle-frame IMU sample ``(a_fwd, a_left)``
is rotated to ENU with the IMU's yaw psi, ``(c a_fwd - s a_left, s a_fwd + c a_left)``
with ``c, s = cos psi, sin psi``, as ``LinearKalman`` does;
where the IMU states no yaw the heading is left to the filter (``need_heading``: the
filter takes it from its velocity, as LinearKalman does).

A drive is cut into overlapping **segments** (:func:`segment`): each starts at a fix (the
filter's initial state, as LinearKalman starts at its first fix), runs a burn-in, then
scores the fixes of its own window; windows tile the drive, so every fix after the
drive's first burn-in is scored once. Segments of all drives are padded to a common
number of steps (padding: ``dt = 0``, no measurement) and stacked (:class:`Batch`), so an
epoch is one pass of a few tensor operations per step over all segments at once.

The fit's reference for a fix at ``t`` is the drive's truth at ``t + 0.2 s`` (linearly
interpolated) where it has one; else the later fix nearest ``t + 0.2 s`` (within 1 s),
at its own horizon, whose own noise then adds to the predicted covariance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from posbench.predictors.kalman.inputs import SpeedInput, stopped
from posbench.scenarios.drive import Drive, GpsStream

#: the horizon [s] of the fit's reference after each fix (the benchmark's future point)
HORIZON_S = 0.2
#: the longest horizon [s] of a reference taken from a later fix (drives without truth)
MAX_FIX_HORIZON_S = 1.0
#: the wheel speed input of the kf (its fixed noise)
KF_SPEED = SpeedInput()
#: step kinds
FIX, SENSOR, PAD = 0, 1, -1
#: measurement rows of a step and state size
NZ, NX = 4, 6


@dataclass(frozen=True)
class DriveSteps:
    """One drive's steps (module docstring); per step, NaN where a field does not apply.

    Attributes:
        t: step times [s]. kind: :data:`FIX` or :data:`SENSOR`.
        H, z: measurement rows (n, 4, 6) and values (n, 4) with the heading applied where
            the IMU states it (m, m/s, m/s^2, ENU).
        fix_w: the fix's noise as a multiple of the fitted fix noise R (0 on sensor steps).
        acc_on: whether rows 0-1 hold an IMU acceleration. var: the fixed variance of each
            row (n, 4): speed rows their noise [m^2/s^2], unused rows 1, fix / IMU rows 0.
        need_heading: sensor steps whose IMU or speed rows wait for the filter's heading;
            yaw: the heading [rad, ENU] the step's rows were built with (NaN: none known);
            a_veh (n, 2): the vehicle-frame acceleration [m/s^2] (NaN: none); along: whether
            row 2 holds a speed along the heading; yaw_rate [rad/s] (NaN: none).
        ref (n, 2), ref_h, ref_w: the fit's reference of a fix step [m, ENU], its horizon
            [s] and its noise as a multiple of R (0 for truth); NaN ref: none.
    """

    t: np.ndarray
    kind: np.ndarray
    H: np.ndarray
    z: np.ndarray
    fix_w: np.ndarray
    acc_on: np.ndarray
    var: np.ndarray
    need_heading: np.ndarray
    yaw: np.ndarray
    a_veh: np.ndarray
    along: np.ndarray
    yaw_rate: np.ndarray
    ref: np.ndarray
    ref_h: np.ndarray
    ref_w: np.ndarray

    def __len__(self) -> int:
        return int(self.t.size)


def fix_weights(gps: GpsStream, sigma_ref: float | None) -> np.ndarray:
    """Per fix, its noise as a multiple of the fitted R: ``(stated / sigma_ref)^2`` for a fix
    stating a per-axis 1-sigma (finite, > 0) when ``sigma_ref`` [m] is given, else 1."""
    w = np.ones(len(gps))
    if gps.accuracy is not None and sigma_ref:
        a = gps.accuracy
        ok = np.isfinite(a) & (a > 0.0)
        w[ok] = (a[ok] / sigma_ref) ** 2
    return w


def _references(drive: Drive, gps: GpsStream, w: np.ndarray) -> tuple[np.ndarray, ...]:
    """(ref (n, 2), horizon (n,), ref weight (n,)) per fix (module docstring)."""
    n = len(gps)
    ref = np.full((n, 2), np.nan)
    h = np.full(n, np.nan)
    rw = np.zeros(n)
    tr = drive.truth
    if tr is not None and len(tr) > 1:
        tq = gps.t + HORIZON_S
        ok = (tq >= tr.t[0]) & (tq <= tr.t[-1])
        ref[ok, 0] = np.interp(tq[ok], tr.t, tr.x)
        ref[ok, 1] = np.interp(tq[ok], tr.t, tr.y)
        h[ok] = HORIZON_S
        return ref, h, rw
    if n < 2:
        return ref, h, rw
    # the later fix nearest t + 0.2 s: the first fix at or after it, or the one before
    # that if it is later than the fix itself
    idx = np.arange(n)
    j = np.searchsorted(gps.t, gps.t + HORIZON_S)
    cand = np.stack([np.minimum(j, n - 1), j - 1], axis=1)
    dist = np.abs(gps.t[cand] - (gps.t + HORIZON_S)[:, None])
    dist[j >= n, 0] = np.inf
    dist[j - 1 <= idx, 1] = np.inf
    k = np.argmin(dist, axis=1)
    best = cand[idx, k]
    hh = gps.t[best] - gps.t
    ok = np.isfinite(dist[idx, k]) & (hh > 0.0) & (hh <= MAX_FIX_HORIZON_S)
    ref[ok] = np.stack([gps.x[best[ok]], gps.y[best[ok]]], axis=1)
    h[ok] = hh[ok]
    rw[ok] = w[best[ok]]
    return ref, h, rw


def drive_steps(
    drive: Drive,
    gps: GpsStream,
    sigma_ref: float | None,
    use_imu: bool = True,
    speed: SpeedInput | None = KF_SPEED,
) -> DriveSteps:
    """The steps of ``drive`` with fixes ``gps`` (module docstring): fixes weighed by
    :func:`fix_weights`, the IMU's acceleration if ``use_imu``, the wheel speed with
    ``speed``'s fixed noise (None: no speed). Non-finite fixes are dropped; sensor samples
    before the first fix start nothing (the filter starts at its first fix)."""
    ok = np.isfinite(gps.x) & np.isfinite(gps.y) & np.isfinite(gps.t)
    gps = GpsStream(
        gps.t[ok], gps.x[ok], gps.y[ok], accuracy=None if gps.accuracy is None else gps.accuracy[ok]
    )
    w = fix_weights(gps, sigma_ref)
    ref, ref_h, ref_w = _references(drive, gps, w)
    imu = drive.imu if use_imu else None
    spd = drive.speed if speed is not None else None
    # sensor samples: IMU and speed stamped at the same time share a step
    ts = [a.t for a in (imu, spd) if a is not None and len(a)]
    st = np.unique(np.concatenate(ts)) if ts else np.zeros(0)
    if len(gps):
        st = st[st >= gps.t[0]]
    n_f, n_s = len(gps), st.size
    t = np.concatenate([gps.t, st])
    kind = np.concatenate([np.full(n_f, FIX), np.full(n_s, SENSOR)])
    order = np.lexsort((kind, t))
    n = t.size
    H = np.zeros((n, NZ, NX))
    z = np.zeros((n, NZ))
    var = np.ones((n, NZ))
    a_veh = np.full((n, 2), np.nan)
    v = np.full(n, np.nan)
    yaw = np.full(n, np.nan)
    rate = np.full(n, np.nan)
    # fixes (rows 0-1 of the first n_f entries before ordering)
    H[:n_f, 0, 0] = H[:n_f, 1, 1] = 1.0
    z[:n_f, 0], z[:n_f, 1] = gps.x, gps.y
    var[:n_f, :2] = 0.0
    fix_w = np.concatenate([w, np.zeros(n_s)])
    if imu is not None and len(imu):
        i = n_f + np.searchsorted(st, imu.t)
        keep = (imu.t >= st[0]) if n_s else np.zeros(len(imu), bool)
        i, sel = i[keep], np.flatnonzero(keep)
        a_veh[i, 0], a_veh[i, 1] = imu.ax[sel], imu.ay[sel]
        if imu.yaw is not None:
            yaw[i] = imu.yaw[sel]
        if imu.yaw_rate is not None:
            rate[i] = imu.yaw_rate[sel]
    has_acc = np.isfinite(a_veh).all(axis=1)
    if spd is not None and len(spd):
        i = n_f + np.searchsorted(st, spd.t)
        keep = (spd.t >= st[0]) if n_s else np.zeros(len(spd), bool)
        v[i[keep]] = spd.v[np.flatnonzero(keep)]
    # the heading of a sensor step: its IMU's yaw, else (a speed alone) the newest yaw the
    # IMU stated at or before it, before the first fix too (LinearKalman's last heading);
    # NaN: left to the filter
    if imu is not None and imu.yaw is not None and n_s:
        fin = np.isfinite(imu.yaw)
        j = np.searchsorted(imu.t[fin], st, side="right") - 1
        carried = np.where(j >= 0, imu.yaw[fin][np.maximum(j, 0)], np.nan)
        sens = np.arange(n_f, n)
        yaw[sens] = np.where(np.isfinite(yaw[sens]) | has_acc[sens], yaw[sens], carried)
    c, s = np.cos(yaw), np.sin(yaw)
    hd = np.isfinite(yaw)
    # IMU rows: their noise always (sigma_a^2, acc_on); H and z where the heading is known
    acc_on = has_acc
    var[has_acc, :2] = 0.0
    acc = has_acc & hd
    H[acc, 0, 4] = H[acc, 1, 5] = 1.0
    z[acc, 0] = c[acc] * a_veh[acc, 0] - s[acc] * a_veh[acc, 1]
    z[acc, 1] = s[acc] * a_veh[acc, 0] + c[acc] * a_veh[acc, 1]
    along = np.zeros(n, bool)
    if speed is not None:
        has_v = np.isfinite(v)
        r_spd = speed.sigma**2
        stop = has_v & stopped(v, speed.stop_speed)
        H[stop, 2, 2] = H[stop, 3, 3] = 1.0
        var[stop, 2:] = r_spd
        along = has_v & ~stop
        z[along, 2] = v[along]
        var[along, 2] = r_spd + (speed.rel_sigma * v[along]) ** 2
        known = along & hd
        H[known, 2, 2], H[known, 2, 3] = c[known], s[known]
    need = (has_acc | along) & ~hd
    a_veh[~has_acc] = np.nan
    return DriveSteps(
        t=t[order],
        kind=kind[order],
        H=H[order],
        z=z[order],
        fix_w=fix_w[order],
        acc_on=acc_on[order],
        var=var[order],
        need_heading=need[order],
        yaw=yaw[order],
        a_veh=a_veh[order],
        along=along[order],
        yaw_rate=rate[order],
        ref=np.concatenate([ref, np.full((n_s, 2), np.nan)])[order],
        ref_h=np.concatenate([ref_h, np.full(n_s, np.nan)])[order],
        ref_w=np.concatenate([ref_w, np.zeros(n_s)])[order],
    )


@dataclass(frozen=True)
class Batch:
    """Segments padded to ``T`` steps and stacked: arrays (T, B, ...) in the fields of
    :class:`DriveSteps`, plus ``dt`` (T, B) [s] since the previous step, the initial fix of
    each segment ``x0`` (B, 2) [m] with its noise weight ``w0`` (B,), and the scored fixes
    as (step, segment) indices ``score_k``, ``score_b`` with their ``ref``, ``ref_h``,
    ``ref_w``; ``segment_drive`` (B,) names each segment's drive by index."""

    dt: np.ndarray
    kind: np.ndarray
    H: np.ndarray
    z: np.ndarray
    fix_w: np.ndarray
    acc_on: np.ndarray
    var: np.ndarray
    need_heading: np.ndarray
    yaw: np.ndarray
    a_veh: np.ndarray
    along: np.ndarray
    yaw_rate: np.ndarray
    t: np.ndarray
    x0: np.ndarray
    w0: np.ndarray
    score_k: np.ndarray
    score_b: np.ndarray
    ref: np.ndarray
    ref_h: np.ndarray
    ref_w: np.ndarray
    segment_drive: np.ndarray

    @property
    def size(self) -> tuple[int, int]:
        """(steps T, segments B)."""
        return int(self.dt.shape[0]), int(self.dt.shape[1])


def segment(
    steps: DriveSteps, segment_s: float, burn_in_s: float
) -> list[tuple[int, int, np.ndarray]]:
    """Cut one drive's steps into segments: (first step, end step, steps scored). Segment j
    starts at the first fix at or after ``t0 + j segment_s - burn_in_s`` (``t0``: the first
    fix) and scores the fixes of ``[t0 + j segment_s, t0 + (j + 1) segment_s)`` that have a
    reference and lie at least ``burn_in_s`` after its start; ``segment_s`` <= 0: one
    segment for the whole drive."""
    fixes = np.flatnonzero(steps.kind == FIX)
    if fixes.size < 2:
        return []
    t = steps.t
    t0, t1 = t[fixes[0]], t[-1]
    span = segment_s if segment_s > 0.0 else math.inf
    n_seg = 1 if not math.isfinite(span) else max(1, math.ceil((t1 - t0) / span))
    has_ref = np.isfinite(steps.ref).all(axis=1)
    out = []
    for j in range(n_seg):
        lo, hi = (t0 + j * span, t0 + (j + 1) * span) if n_seg > 1 else (t0, math.inf)
        first = fixes[np.searchsorted(t[fixes], max(t0, lo - burn_in_s))]
        end = int(np.searchsorted(t, hi, side="left")) if math.isfinite(hi) else t.size
        cand = fixes[(fixes > first) & (fixes < end)]
        tc = t[cand]
        scored = cand[(tc >= lo) & (tc >= t[first] + burn_in_s) & has_ref[cand]]
        if end > first + 1:
            out.append((int(first), end, scored))
    return out


def batch(drives_steps: Sequence[DriveSteps], segment_s: float, burn_in_s: float) -> Batch | None:
    """Every drive's segments (:func:`segment`) padded and stacked; None when none has a
    scored fix."""
    segs = [
        (d, a, b, sc)
        for d, st in enumerate(drives_steps)
        for a, b, sc in segment(st, segment_s, burn_in_s)
        if sc.size
    ]
    if not segs:
        return None
    T = max(b - a - 1 for _, a, b, _ in segs)
    B = len(segs)
    dt = np.zeros((T, B))
    kind = np.full((T, B), PAD)
    H = np.zeros((T, B, NZ, NX))
    z = np.zeros((T, B, NZ))
    fix_w = np.zeros((T, B))
    acc_on = np.zeros((T, B), bool)
    var = np.ones((T, B, NZ))
    need = np.zeros((T, B), bool)
    yaw = np.full((T, B), np.nan)
    a_veh = np.full((T, B, 2), np.nan)
    along = np.zeros((T, B), bool)
    rate = np.full((T, B), np.nan)
    tt = np.full((T, B), np.nan)
    x0 = np.zeros((B, 2))
    w0 = np.zeros(B)
    sk, sb, seg_d = [], [], np.zeros(B, int)
    for b, (d, a, e, sc) in enumerate(segs):
        st = drives_steps[d]
        n = e - a - 1
        sl = slice(a + 1, e)
        dt[:n, b] = np.diff(st.t[a:e])
        kind[:n, b] = st.kind[sl]
        H[:n, b], z[:n, b] = st.H[sl], st.z[sl]
        fix_w[:n, b], acc_on[:n, b], var[:n, b] = st.fix_w[sl], st.acc_on[sl], st.var[sl]
        need[:n, b], yaw[:n, b], a_veh[:n, b] = st.need_heading[sl], st.yaw[sl], st.a_veh[sl]
        along[:n, b], rate[:n, b], tt[:n, b] = st.along[sl], st.yaw_rate[sl], st.t[sl]
        x0[b] = st.z[a, :2]
        w0[b] = st.fix_w[a]
        sk.append(sc - a - 1)
        sb.append(np.full(sc.size, b))
        seg_d[b] = d
    k_idx = np.concatenate(sk)
    b_idx = np.concatenate(sb)
    ref = np.concatenate([drives_steps[segs[b][0]].ref[sc] for b, (_, _, _, sc) in enumerate(segs)])
    ref_h = np.concatenate([drives_steps[segs[b][0]].ref_h[sc] for b, (*_, sc) in enumerate(segs)])
    ref_w = np.concatenate([drives_steps[segs[b][0]].ref_w[sc] for b, (*_, sc) in enumerate(segs)])
    return Batch(
        dt, kind, H, z, fix_w, acc_on, var, need, yaw, a_veh, along, rate, tt, x0, w0,
        k_idx, b_idx, ref, ref_h, ref_w, seg_d,
    )  # fmt: skip
