"""Training windows from :class:`~posbench.scenarios.drive.Drive` objects (numpy only).

One window per GPS fix that has >= 2 s of history: the same resampling and features
as the runtime (:mod:`posbench.predictors.lstm.resample`, :mod:`posbench.predictors.lstm.features`,
batched), plus many-to-many targets: for input sample i (time t_i) the target is the
sample 200 ms later. Target dx, dy = reference position at t_i + 0.2 minus the input
grid position at t_i (in the feature frame), so the last target is exactly what the
runtime adds to the newest grid point to get the point 200 ms ahead. Target ax, ay,
yaw, t = the next input row's values (the last row repeats the newest IMU values with
t = 1.6 s: the runtime never uses predicted IMU values, it reads the real IMU).

Reference positions ("truth"): the drive's truth stream (linearly interpolated) when it
has one, else the paper's convention: a cubic through the real fixes within +-1 s of
the target time (past and future). Windows whose targets the reference does not cover,
and windows where the vehicle stands still (reference moves < 5 cm over the window;
the runtime holds the position there instead), are not used.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from posbench.predictors.lstm.features import compute_features, gps_substitute_imu, wrap
from posbench.predictors.lstm.resample import (
    DEGREE,
    DT,
    GRID_OFFSETS,
    MIN_SPAN_S,
    N_STEPS,
    centred_cubic_batch,
    deriv_poly,
    resample_imu_batch,
    resample_positions_batch,
    window_starts,
)
from posbench.scenarios.drive import Drive, GpsStream

STILL_PATH_M = 0.05
TURN_HEADING_RAD = 0.2


@dataclass
class WindowSet:
    """Windows of one or more drives. Shapes: B windows, 8 steps, 6 features; metres, ENU."""

    X: np.ndarray  # (B, 8, 6) input features
    Y: np.ndarray  # (B, 8, 6) targets (next sample of each step)
    psi: np.ndarray  # (B,) frame heading [rad]
    p_last: np.ndarray  # (B, 2) newest grid position [m]
    truth_future: np.ndarray  # (B, 2) reference position 200 ms after the newest fix [m]
    cubic_pred: np.ndarray  # (B, 2) plain cubic extrapolation of the same fixes [m]
    cv_pred: np.ndarray  # (B, 2) constant velocity from the last two fixes [m]
    t_end: np.ndarray  # (B,) newest fix time [s]
    label: np.ndarray  # (B,) scenario label (str)
    drive: np.ndarray  # (B,) drive name (str)

    def __len__(self) -> int:
        return int(self.X.shape[0])

    def take(self, idx: np.ndarray) -> WindowSet:
        return WindowSet(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    @staticmethod
    def concat(sets: list[WindowSet]) -> WindowSet:
        sets = [s for s in sets if len(s)]
        if not sets:
            return empty_windows()
        return WindowSet(
            **{
                f.name: np.concatenate([getattr(s, f.name) for s in sets])
                for f in fields(WindowSet)
            }
        )


def empty_windows() -> WindowSet:
    z = np.zeros
    return WindowSet(
        z((0, N_STEPS, 6)),
        z((0, N_STEPS, 6)),
        z(0),
        z((0, 2)),
        z((0, 2)),
        z((0, 2)),
        z((0, 2)),
        z(0),
        np.array([], dtype=object),
        np.array([], dtype=object),
    )


def unwrap_finite(a: np.ndarray) -> np.ndarray:
    """np.unwrap over the finite entries, NaN kept where it was."""
    out = np.array(a, dtype=float)
    ok = np.isfinite(out)
    if ok.any():
        out[ok] = np.unwrap(out[ok])
    return out


def _labels(drive: Drive, t_end: np.ndarray, psi_first: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Scenario labels at the window ends: scenarios.labels.label_times when it exists,
    else "turn" when the fitted heading turns by > 0.2 rad over the window."""
    try:
        from posbench.scenarios.labels import label_times
    except ImportError:
        turn = np.abs(wrap(psi - psi_first)) > TURN_HEADING_RAD
        return np.where(turn, "turn", "straight").astype(object)
    src = drive.truth if drive.truth is not None else drive.gps
    sp = drive.speed
    return np.asarray(
        label_times(
            t_end,
            src.t,
            src.x,
            src.y,
            None if sp is None else sp.t,
            None if sp is None else sp.v,
        ),
        dtype=object,
    )


def drive_windows(
    drive: Drive,
    gps: GpsStream | None = None,
    frame: str = "heading",
    min_span: float = MIN_SPAN_S,
    fix_offset: bool = False,
) -> WindowSet:
    """All training windows of one drive, its GPS optionally replaced (e.g. degraded);
    ``fix_offset``: row 0 holds the newest fix minus the newest grid point
    (:mod:`posbench.predictors.lstm.features`)."""
    gps = drive.gps if gps is None else gps
    t = gps.t
    xy = np.stack([gps.x, gps.y], axis=1)
    n = t.size
    if n < DEGREE + 2:
        return empty_windows()
    ends = np.arange(1, n)
    starts = window_starts(t, ends, min_span)
    keep = (t[ends] - t[starts] >= min_span) & (ends - starts + 1 >= DEGREE + 1)
    ends, starts = ends[keep], starts[keep]
    if ends.size == 0:
        return empty_windows()
    t_end = t[ends]
    # reference positions at t_i + 0.2 for the 8 steps
    tq = t_end[:, None] + GRID_OFFSETS[None, :] + DT
    if drive.truth is not None and len(drive.truth) > 1:
        tr = drive.truth
        ok = (tq[:, 0] >= tr.t[0]) & (tq[:, -1] <= tr.t[-1])
        ref = np.stack([np.interp(tq, tr.t, tr.x), np.interp(tq, tr.t, tr.y)], axis=-1)
    else:
        ref_flat, okf = centred_cubic_batch(t, xy, tq.ravel())
        ref = ref_flat.reshape(tq.shape + (2,))
        ok = okf.reshape(tq.shape).all(axis=1)
    path = np.linalg.norm(np.diff(np.where(np.isfinite(ref), ref, 0.0), axis=1), axis=2).sum(1)
    ok &= path >= STILL_PATH_M
    if not ok.any():
        return empty_windows()
    ends, starts, t_end, ref = ends[ok], starts[ok], t_end[ok], ref[ok]

    pos9, coef, scale = resample_positions_batch(t, xy, starts, ends, np.array([DT]))
    pos = pos9[:, :N_STEPS]
    s_grid = GRID_OFFSETS[None, :] / scale[:, None]
    psi = np.arctan2(coef[:, 1, 1], coef[:, 1, 0])
    sub_ax, sub_ay, sub_yaw = gps_substitute_imu(coef, scale, s_grid)
    ax, ay, yaw = sub_ax.copy(), sub_ay.copy(), sub_yaw.copy()
    imu = drive.imu
    if imu is not None and len(imu) > DEGREE:
        yaw_col = unwrap_finite(imu.yaw) if imu.yaw is not None else np.full(len(imu), np.nan)
        vals = np.stack([imu.ax, imu.ay, yaw_col], axis=1)
        res, okimu = resample_imu_batch(imu.t, vals, t[starts], t_end)
        okimu &= np.isfinite(res[:, :, :2]).all(axis=(1, 2))
        ax[okimu], ay[okimu] = res[okimu, :, 0], res[okimu, :, 1]
        okyaw = okimu & np.isfinite(res[:, :, 2]).all(axis=1)
        yaw[okyaw] = res[okyaw, :, 2]
    X = compute_features(pos, ax, ay, yaw, psi, frame, fix_xy=xy[ends] if fix_offset else None)
    # targets: reference displacement from each input sample, next row's aux features
    Y = np.empty_like(X)
    d = ref - pos
    if frame == "heading":
        c, s = np.cos(-psi)[:, None], np.sin(-psi)[:, None]
        Y[..., 0] = c * d[..., 0] - s * d[..., 1]
        Y[..., 1] = s * d[..., 0] + c * d[..., 1]
    else:
        Y[..., 0], Y[..., 1] = d[..., 0], d[..., 1]
    Y[:, :-1, 2:] = X[:, 1:, 2:]
    Y[:, -1, 2:5] = X[:, -1, 2:5]
    Y[:, -1, 5] = N_STEPS * DT
    # baselines on the same windows
    dt_last = t_end - t[ends - 1]
    v_last = (xy[ends] - xy[ends - 1]) / dt_last[:, None]
    cv_pred = xy[ends] + v_last * DT
    d0 = deriv_poly(coef.transpose(1, 0, 2), s_grid[:, 0])
    psi_first = np.arctan2(d0[:, 1], d0[:, 0])
    names = np.full(ends.size, drive.name, dtype=object)
    return WindowSet(
        X=X,
        Y=Y,
        psi=psi,
        p_last=pos[:, -1],
        truth_future=ref[:, -1],
        cubic_pred=pos9[:, N_STEPS],
        cv_pred=cv_pred,
        t_end=t_end,
        label=_labels(drive, t_end, psi_first, psi),
        drive=names,
    )


def future_from_output(ws: WindowSet, out_dxdy: np.ndarray, frame: str = "heading") -> np.ndarray:
    """Predicted future positions (B, 2) [m] from the network's last-step dx, dy (B, 2)."""
    if frame == "world":
        return ws.p_last + out_dxdy
    c, s = np.cos(ws.psi), np.sin(ws.psi)
    return ws.p_last + np.stack(
        [c * out_dxdy[:, 0] - s * out_dxdy[:, 1], s * out_dxdy[:, 0] + c * out_dxdy[:, 1]], axis=1
    )
