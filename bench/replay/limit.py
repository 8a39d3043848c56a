"""How far from the limit: the bound on one drive's scored queries (the ``limit`` row).

For each scored query of a prepared drive (past the warm-up, with a reference), the bound on
the mean error of a predictor that knows the constant-acceleration model and the noise of
the fixes it is fed (:mod:`posbench.metrics.pcrb`, :mod:`posbench.metrics.limit`), at the
drive's actual fix times, and a second one that also knows the IMU. What the bound takes,
per drive:

- **q**, the jerk PSD [m^2/s^5]: from the reference's own motion on the drive, as it varies
  along it (:func:`~posbench.metrics.jerk_psd.jerk_psd_profile`: the squared third differences
  on a grid of the drive's median fix interval, averaged over 2 s windows): its truth, or
  without one the cubic through its fixes that the queries are scored against. One q for a
  whole drive would overstate it where the drive is calm and understate it in manoeuvres;
  the drive's one value (:func:`~posbench.metrics.jerk_psd.jerk_psd_from_track`) is reported;
- **R**, the fixes' white noise [m^2] per axis: a simulated profile's own (``rtk`` 2 cm,
  ``consumer`` 0.5 m, ``none`` exact: :data:`~posbench.metrics.limit.MIN_FIX_VAR_M2`); a
  receiver's own fixes: estimated from the fixes
  (:func:`~posbench.metrics.limit.fix_white_variance`) and, where they state an accuracy,
  the white part of the statement as the filters split it
  (:func:`posbench.predictors.kalman.gnss_noise.white_share`; a statement held within 1 mm, the
  bound's floor, and :data:`MAX_STATED_SIGMA_M`, so its square neither underflows to 0 nor
  overflows);
- **the slow floor**, added where a truth is the reference (none where the receiver's own
  fixes are): fixes drawn by posbench (a GPS profile), the slow error it **drew** for this
  drive (``PreparedDrive.gps_slow_xy``), at each query's time an offset no predictor can
  remove (:func:`~posbench.metrics.limit.mean_error_offset`; ``consumer``: a 1 m
  Gauss-Markov error, whose realisation on one short drive can be far from its stationary
  variance); a receiver's own fixes: their mean square error against the truth at the fix
  times minus R (:func:`~posbench.metrics.limit.fix_error_variance`), a variance [m^2] per
  axis measured on few independent samples: ``slow_var_sd_m2`` says how uncertain
  (:func:`~posbench.metrics.limit.correlation_time_s`,
  :func:`~posbench.metrics.limit.slow_floor_sd`), and the aggregation widens the bound's
  interval by it;
- **the IMU**: every sample a known acceleration, with the white noise its samples show
  (:func:`~posbench.metrics.limit.imu_white_variance`).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import pandas as pd

from posbench.config import RunConfig
from posbench.metrics.jerk_psd import (
    jerk_psd_from_track,
    jerk_psd_profile,
    track_noise_variance,
)
from posbench.metrics.limit import (
    MIN_FIX_VAR_M2,
    OUTLIER_FACTOR,
    correlation_time_s,
    fix_error_variance,
    fix_white_variance,
    imu_white_variance,
    mean_error_bounds,
    slow_floor_sd,
)
from posbench.metrics.pcrb import JerkPsd
from posbench.replay.prepare import PreparedDrive
from posbench.replay.reference import TRUTH, cubic_through_fixes, truth_at

#: the columns of a drive's limit frame (``DriveRun.limit``): one row per scored query
LIMIT_COLUMNS = ("kind", "t_query", "label", "limit_m", "limit_imu_m")
#: the query columns :func:`drive_limit` reads (of :func:`posbench.replay.queries.query_frame`)
LIMIT_QUERY_COLUMNS = ("kind", "t_issue", "t_query", "x_ref", "y_ref", "label", "warmup")


#: the largest stated accuracy [m] the bound takes as it is (its square stays finite)
MAX_STATED_SIGMA_M = 1e150


def fix_noise(prep: PreparedDrive, cfg: RunConfig) -> dict[str, Any]:
    """What the bound takes of the fixes fed to ``prep``'s predictors: ``white_var_m2``
    (R per axis), ``slow_var_m2`` (the receiver's slow error per axis), ``slow_drawn``
    (the fixes' slow error was drawn by posbench: :func:`drawn_slow_offsets`),
    ``slow_var_sd_m2`` (the standard deviation of a measured ``slow_var_m2``: 0 where it is
    not measured), ``slow_samples`` (the independent samples it was measured on; None),
    ``latency_s`` and ``how``, in words (module docstring)."""
    from posbench.scenarios.degrade import NOISE_PARAMS

    cond = prep.gps_condition
    gps = prep.gps
    if cond in NOISE_PARAMS:  # drawn from the truth by posbench: the noise is known
        white, slow, _ = NOISE_PARAMS[cond]
        drawn = slow > 0 and prep.gps_slow_xy is not None
        return {
            "white_var_m2": white * white,
            "slow_var_m2": slow * slow,
            "slow_drawn": drawn,
            "slow_var_sd_m2": 0.0,
            "slow_samples": None,
            "latency_s": float(cfg.gps_latency_s),
            "how": f"the simulated `{cond}` profile's own noise (white {white:g} m, slow "
            f"{slow:g} m per axis"
            + ("; slow: the error drawn for this drive" if drawn else "")
            + ")",
        }
    from posbench.predictors.kalman.gnss_noise import white_share

    est = fix_white_variance(gps.t, gps.x, gps.y)
    stated = np.asarray(gps.accuracy, dtype=float) if gps.accuracy is not None else np.empty(0)
    stated = stated[np.isfinite(stated) & (stated > 0)]
    # held within [1 mm, 1e150 m]: the bound's floor on a fix's noise, and a square that
    # neither underflows to 0 (a division by it) nor overflows (ordinary statements unmoved)
    stated = np.clip(stated, math.sqrt(MIN_FIX_VAR_M2), MAX_STATED_SIGMA_M)
    how = "white: estimated from the fixes"
    white = est
    total = math.nan
    if stated.size and math.isfinite(est):
        total = float(np.median(stated * stated))
        white = total * white_share(est / total)
        how = "white: the stated accuracy's white part (split as the filters do)"
    slow = max(0.0, total - white) if math.isfinite(total) else 0.0
    truth = prep.drive.truth
    sd, samples = 0.0, None
    if truth is not None and math.isfinite(white):
        ref = truth_at(truth.t, truth.x, truth.y, gps.t)
        ex, ey = gps.x - ref[:, 0], gps.y - ref[:, 1]
        measured = fix_error_variance(ex, ey)
        if math.isfinite(measured):
            slow = max(0.0, measured - white)
            how += "; slow: the fixes' error against the truth, less the white part"
            sd, samples = _slow_sampling(gps.t, ex, ey, measured)
    elif stated.size:
        how += "; slow: the rest of the stated accuracy"
    return {
        "white_var_m2": white,
        "slow_var_m2": slow,
        "slow_drawn": False,
        "slow_var_sd_m2": sd,
        "slow_samples": samples,
        "latency_s": 0.0,
        "how": how,
    }


def _slow_sampling(
    t: np.ndarray, ex: np.ndarray, ey: np.ndarray, measured: float
) -> tuple[float, float | None]:
    """The standard deviation [m^2] of ``measured``, the fixes' mean square error per axis
    against the truth (``ex``, ``ey`` [m] at the fix times ``t`` [s]; glitches left out as
    :func:`~posbench.metrics.limit.fix_error_variance` leaves them), and the independent
    samples it rests on (drive span / correlation time); (0, None) where it cannot tell."""
    r = np.hypot(ex, ey)
    med = float(np.nanmedian(r)) if np.isfinite(r).any() else math.nan
    keep = np.isfinite(r) & (r <= OUTLIER_FACTOR * med) if med > 0 else np.isfinite(r)
    tt = np.asarray(t, dtype=float)[keep]
    tau = correlation_time_s(tt, np.asarray(ex)[keep], np.asarray(ey)[keep])
    span = float(tt[-1] - tt[0]) if tt.size > 1 else math.nan
    sd = slow_floor_sd(measured, span, tau)
    if not math.isfinite(sd):
        return 0.0, None
    return sd, max(1.0, span / tau)


def drawn_slow_offsets(prep: PreparedDrive, t_query: np.ndarray, latency_s: float) -> np.ndarray:
    """The length [m] of the slow error posbench drew for ``prep``'s fixes at each query
    time ``t_query`` [s]: the drawn error (``PreparedDrive.gps_slow_xy``, at ``gps_all``'s
    fix times, dropped fixes included) interpolated linearly, held beyond the first and last
    fix. A fix stamped ``t`` holds the truth at ``t - latency_s`` plus the error drawn at
    ``t``, so the track the fixes show at ``t_query`` carries the error at ``t_query +
    latency_s``."""
    slow = prep.gps_slow_xy
    assert slow is not None
    t = prep.gps_all.t
    tq = np.asarray(t_query, dtype=float) + latency_s
    if t.size == 0:
        return np.full(tq.shape, np.nan)
    length: np.ndarray = np.hypot(np.interp(tq, t, slow[:, 0]), np.interp(tq, t, slow[:, 1]))
    return length


#: the window [s] of the jerk PSD's profile along a drive (:func:`jerk_psd`)
Q_WINDOW_S = 2.0


def jerk_psd(prep: PreparedDrive) -> tuple[float, JerkPsd]:
    """The jerk PSD [m^2/s^5] of ``prep``'s reference on a grid of its median fix interval
    [s], less what the reference's own white noise adds
    (:func:`~posbench.metrics.jerk_psd.track_noise_variance`): the drive's one value, and its
    profile along the drive in windows of
    :data:`Q_WINDOW_S` (:func:`~posbench.metrics.jerk_psd.jerk_psd_profile`, what the bound
    takes). The reference: its truth, or without one the cubic through its fixes the
    queries are scored against (:func:`posbench.replay.reference.cubic_through_fixes`; a
    stale or jumping fix moves it far less than it moves the fixes themselves)."""
    gps = prep.gps
    dt = float(np.median(np.diff(gps.t))) if len(gps) > 1 else math.nan
    if not (math.isfinite(dt) and dt > 0):
        return math.nan, math.nan
    truth = prep.drive.truth
    if truth is not None:
        t, x, y = truth.t, truth.x, truth.y
    else:
        own = prep.drive.gps
        t = own.t[0] + dt * np.arange(int((own.t[-1] - own.t[0]) / dt) + 1)
        ref = cubic_through_fixes(own.t, own.x, own.y, t)
        x, y = ref[:, 0], ref[:, 1]
    # a measured truth's own white noise would pass for jerk at a 0.1 s grid: taken out
    noise = track_noise_variance(t, x, y, dt=dt)
    noise = noise if math.isfinite(noise) else 0.0
    q = jerk_psd_from_track(t, x, y, dt=dt, noise_var=noise)
    profile = jerk_psd_profile(t, x, y, dt=dt, window_s=Q_WINDOW_S, noise_var=noise)
    return q, (profile if profile[0].size else math.nan)


def drive_limit(
    prep: PreparedDrive, queries: pd.DataFrame, cfg: RunConfig
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The bound on ``prep``'s scored queries (``queries``: its query table, columns of
    :func:`posbench.replay.queries.query_frame`): a frame of :data:`LIMIT_COLUMNS` (kind,
    query time [s], route type, bound on the mean error [m] fixes only and with the IMU;
    NaN where it has none), and what it took (``q_m2_s5``, ``fix_white_var_m2``,
    ``slow_var_m2``: with a drawn slow error the mean square per axis of its realisation
    over the scored queries, ``slow_added``, ``slow_drawn``, ``slow_var_sd_m2``,
    ``slow_samples`` (:func:`fix_noise`), ``noise``, ``imu_var_m2_s4``, ``latency_s``,
    ``cost_s``: seconds this took)."""
    start = time.perf_counter()
    scored = ~queries["warmup"].to_numpy(dtype=bool)
    scored &= queries["x_ref"].notna().to_numpy() & queries["y_ref"].notna().to_numpy()

    def scored_column(name: str, dtype: Any = None) -> np.ndarray:
        """One column of the scored queries (the table is not copied whole)."""
        out: np.ndarray = queries[name].to_numpy(dtype=dtype)[scored]
        return out

    noise = fix_noise(prep, cfg)
    q, q_profile = jerk_psd(prep)
    truth_ref = prep.reference == TRUTH
    imu = prep.drive.imu
    t_acc, r_acc = None, None
    if imu is not None and len(imu) >= 3:
        good = np.isfinite(imu.ax) & np.isfinite(imu.ay)
        r_acc = imu_white_variance(imu.t, imu.ax, imu.ay)
        t_acc = imu.t[good] if math.isfinite(r_acc) else None
    t_query = scored_column("t_query", float)
    offsets = None
    slow_var = noise["slow_var_m2"]
    if noise["slow_drawn"]:
        offsets = drawn_slow_offsets(prep, t_query, noise["latency_s"])
        # what the drive's queries carried: the realisation's mean square per axis
        slow_var = float(np.mean(offsets * offsets) / 2.0) if offsets.size else 0.0
    bound, bound_imu = mean_error_bounds(
        prep.gps.t,
        noise["white_var_m2"],
        q_profile,
        scored_column("t_issue", float),
        t_query,
        slow_var=noise["slow_var_m2"],
        slow_offset_m=offsets,
        independent_truth=truth_ref,
        latency_s=noise["latency_s"],
        t_acc=t_acc,
        r_acc=r_acc,
    )
    frame = pd.DataFrame(
        {
            "kind": scored_column("kind"),
            "t_query": t_query,
            "label": scored_column("label"),
            "limit_m": bound,
            "limit_imu_m": bound_imu if bound_imu is not None else np.full(bound.size, np.nan),
        }
    )
    info = {
        "q_m2_s5": q,
        "fix_white_var_m2": noise["white_var_m2"],
        "slow_var_m2": slow_var,
        "slow_added": truth_ref,
        "slow_drawn": bool(noise["slow_drawn"]) and truth_ref,
        "slow_var_sd_m2": noise["slow_var_sd_m2"] if truth_ref else 0.0,
        "slow_samples": noise["slow_samples"] if truth_ref else None,
        "noise": noise["how"],
        "imu_var_m2_s4": r_acc if t_acc is not None else None,
        "latency_s": noise["latency_s"],
        "cost_s": time.perf_counter() - start,
    }
    return frame, info
