"""Training data of the ``hybrid`` (numpy only): windows, kf prior and residual targets.

For one drive and its (possibly degraded) fixes, one row per ``lstm`` training window
(:func:`posbench.predictors.lstm.windows.drive_windows`, matched to its fix by the fix time):

- ``X`` (B, 8, 6): the lstm's features (heading frame);
- ``prior`` (B, 4, 2) [m]: ``kf.position_at(t_fix + h) - p_last`` for h in
  :data:`~posbench.predictors.hybrid.predictor.HORIZONS`, rotated by -psi (heading frame), where the
  kf is a fresh ``KalmanBank(**kf_params)`` (the ``kf``) replayed over the drive's streams in the
  runner's order (:func:`kf_prior_at_fixes`) and asked right after each fix;
- ``target`` (B, 4, 2) [m]: ``reference(t_fix + h) - kf.position_at(t_fix + h)``, rotated
  by -psi: the residual the network learns to add. The reference is the drive's truth
  (linearly interpolated) when it has one, else the centred cubic through the fixes
  within +-1 s (:func:`posbench.predictors.lstm.resample.centred_cubic_batch`, the lstm's
  convention). Windows whose reference does not cover t_fix + 0.8 s are dropped.

Frames: positions in local ENU [m]; heading frame = rotated by -psi (x along the heading
of the window's cubic at the fix, y to the left).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from posbench.predictors.hybrid.model_info import HORIZONS, N_H
from posbench.predictors.kalman.kf import KalmanBank
from posbench.predictors.lstm.resample import N_STEPS, centred_cubic_batch
from posbench.predictors.lstm.windows import drive_windows
from posbench.scenarios.drive import Drive, GpsStream

_GPS, _IMU, _SPEED = 0, 1, 2


@dataclass
class HybridWindows:
    """Training rows of one or more drives. B rows; metres; see the module doc."""

    X: np.ndarray  # (B, 8, 6) lstm features (heading frame)
    prior: np.ndarray  # (B, 4, 2) kf answer minus p_last, heading frame [m]
    target: np.ndarray  # (B, 4, 2) reference minus kf answer, heading frame [m]
    psi: np.ndarray  # (B,) heading of the window's cubic at the fix [rad]
    p_last: np.ndarray  # (B, 2) newest grid point [m, ENU]
    kf_future: np.ndarray  # (B, 2) kf answer at t_fix + 0.2 s [m, ENU]
    truth_future: np.ndarray  # (B, 2) reference at t_fix + 0.2 s [m, ENU]
    t_end: np.ndarray  # (B,) fix time [s]
    label: np.ndarray  # (B,) scenario label (str)
    drive: np.ndarray  # (B,) drive name (str)
    condition: np.ndarray  # (B,) GPS condition of the fixes (str: a profile, or "native")

    def __len__(self) -> int:
        return int(self.X.shape[0])

    def take(self, idx: np.ndarray) -> HybridWindows:
        return HybridWindows(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    @staticmethod
    def concat(sets: list[HybridWindows]) -> HybridWindows:
        sets = [s for s in sets if len(s)]
        if not sets:
            return empty_hybrid_windows()
        return HybridWindows(
            **{
                f.name: np.concatenate([getattr(s, f.name) for s in sets])
                for f in fields(HybridWindows)
            }
        )


def empty_hybrid_windows() -> HybridWindows:
    z = np.zeros
    return HybridWindows(
        z((0, N_STEPS, 6)),
        z((0, N_H, 2)),
        z((0, N_H, 2)),
        z(0),
        z((0, 2)),
        z((0, 2)),
        z((0, 2)),
        z(0),
        np.array([], dtype=object),
        np.array([], dtype=object),
        np.array([], dtype=object),
    )


def _to_heading(v: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """World vectors (B, K, 2) rotated by -psi (B,): heading frame."""
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    return np.stack([c * v[..., 0] + s * v[..., 1], c * v[..., 1] - s * v[..., 0]], axis=-1)


def kf_prior_at_fixes(
    drive: Drive, gps: GpsStream, kf_params: dict, horizons: tuple[float, ...] = HORIZONS
) -> np.ndarray:
    """(n_fixes, len(horizons), 2) [m, ENU]: ``kf.position_at(t_fix + h)`` asked right after
    each fix of ``gps``, from a fresh ``KalmanBank(**kf_params)`` (the ``kf``) fed the
    drive's IMU and speed and ``gps`` (sigma = the stated accuracy where finite and
    positive, else None) in the runner's order (:mod:`posbench.replay.loop`: by time; at
    equal times fixes, then IMU, then speed). NaN rows for fixes before the kf has a
    state (a non-finite first fix)."""
    kf = KalmanBank(**kf_params)
    parts_t = [gps.t]
    parts_k = [np.full(len(gps), _GPS)]
    imu, spd = drive.imu, drive.speed
    if imu is not None:
        parts_t.append(imu.t)
        parts_k.append(np.full(len(imu), _IMU))
    if spd is not None:
        parts_t.append(spd.t)
        parts_k.append(np.full(len(spd), _SPEED))
    t = np.concatenate(parts_t)
    k = np.concatenate(parts_k)
    idx = np.concatenate([np.arange(p.size) for p in parts_t])
    order = np.lexsort((k, t))
    gt, gx, gy = gps.t.tolist(), gps.x.tolist(), gps.y.tolist()
    acc = gps.accuracy.tolist() if gps.accuracy is not None else [math.nan] * len(gps)
    gs = [a if 0.0 < a < math.inf else None for a in acc]
    if imu is not None:
        it, iax, iay = imu.t.tolist(), imu.ax.tolist(), imu.ay.tolist()
        iyaw = imu.yaw.tolist() if imu.yaw is not None else [math.nan] * len(imu)
        irate = imu.yaw_rate.tolist() if imu.yaw_rate is not None else [math.nan] * len(imu)
    if spd is not None:
        st, sv = spd.t.tolist(), spd.v.tolist()
    out = np.full((len(gps), len(horizons), 2), np.nan)
    hz = list(horizons)
    obs_gps, obs_imu, obs_speed, pos = (
        kf.observe_gps,
        kf.observe_imu,
        kf.observe_speed,
        kf.position_at,
    )
    for kind, i in zip(k[order].tolist(), idx[order].tolist(), strict=True):
        if kind == _IMU:
            obs_imu(it[i], iax[i], iay[i], iyaw[i], irate[i])
        elif kind == _GPS:
            tf = gt[i]
            obs_gps(tf, gx[i], gy[i], sigma=gs[i])
            out[i] = [pos(tf + h) for h in hz]
        else:
            obs_speed(st[i], sv[i])
    return out


def hybrid_windows(
    drive: Drive,
    gps: GpsStream | None = None,
    kf_params: dict | None = None,
    frame: str = "heading",
    condition: str = "native",
) -> HybridWindows:
    """The hybrid's training rows of one drive (see the module doc); ``gps`` replaces the
    drive's fixes (e.g. degraded), ``kf_params`` configure the prior's kf (its defaults if
    None), ``condition`` names the fixes' GPS condition in the rows. Only the heading frame
    is supported."""
    if frame != "heading":
        raise ValueError(f"the hybrid works in the heading frame, not {frame!r}")
    gps = drive.gps if gps is None else gps
    ws = drive_windows(drive, gps, frame)
    if not len(ws):
        return empty_hybrid_windows()
    kf_all = kf_prior_at_fixes(drive, gps, dict(kf_params or {}))
    fix = np.searchsorted(gps.t, ws.t_end)
    fix = np.minimum(fix, len(gps) - 1)
    matched = gps.t[fix] == ws.t_end
    kf_at = kf_all[fix]
    tq = ws.t_end[:, None] + np.asarray(HORIZONS)[None, :]
    tr = drive.truth
    if tr is not None and len(tr) > 1:
        ok = (tq[:, 0] >= tr.t[0]) & (tq[:, -1] <= tr.t[-1])
        ref = np.stack([np.interp(tq, tr.t, tr.x), np.interp(tq, tr.t, tr.y)], axis=-1)
    else:
        xy = np.stack([gps.x, gps.y], axis=1)
        ref_flat, okf = centred_cubic_batch(gps.t, xy, tq.ravel())
        ref = ref_flat.reshape(tq.shape + (2,))
        ok = okf.reshape(tq.shape).all(axis=1)
    ok &= matched & np.isfinite(kf_at).all(axis=(1, 2)) & np.isfinite(ref).all(axis=(1, 2))
    if not ok.any():
        return empty_hybrid_windows()
    ws = ws.take(np.flatnonzero(ok))
    kf_at, ref = kf_at[ok], ref[ok]
    return HybridWindows(
        X=ws.X,
        prior=_to_heading(kf_at - ws.p_last[:, None, :], ws.psi),
        target=_to_heading(ref - kf_at, ws.psi),
        psi=ws.psi,
        p_last=ws.p_last,
        kf_future=kf_at[:, 0],
        truth_future=ref[:, 0],
        t_end=ws.t_end,
        label=ws.label,
        drive=ws.drive,
        condition=np.full(len(ws), condition, dtype=object),
    )
