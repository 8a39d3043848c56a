"""Turn a loaded :class:`Drive` into what the runner replays: the GPS fixes a
predictor receives, the query times and the reference positions to score against.

Pure given the config: the same drive, config and seed give the same inputs on
any machine and in any worker.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posbench.config import RunConfig, drive_seed, fixes_description, gps_condition
from posbench.metrics.track_errors import HEADING_DT_S, reference_motion
from posbench.replay.reference import FIX_CUBIC, TRUTH, reference_at
from posbench.scenarios.drive import Drive, GpsStream


@dataclass
class Queries:
    """Query times [s] of one kind and what they are scored against."""

    t_issue: np.ndarray  # when the runner asks (all observations given are <= this)
    t_query: np.ndarray  # the instant whose position is asked for
    ref_xy: np.ndarray  # (N, 2) reference positions [m]; NaN = not scorable
    speed_mps: np.ndarray
    label: np.ndarray
    since_fix_s: np.ndarray  # t_query - time of the last fix received by t_issue [s]
    #: the reference's direction of travel at t_query [rad, counter-clockwise from east];
    #: NaN at standstill or unknown (:func:`posbench.metrics.track_errors.reference_motion`)
    heading_rad: np.ndarray | None = None
    #: the reference's yaw rate at t_query [rad/s], positive = turning left; NaN unknown
    yaw_rate: np.ndarray | None = None


@dataclass
class PreparedDrive:
    """One drive ready to replay."""

    drive: Drive
    dataset: str
    gps: GpsStream  # the fixes fed to predictors
    gps_all: GpsStream  # the fixes before dropouts (received + dropped)
    reference: str  # TRUTH or FIX_CUBIC
    future: Queries
    now: Queries
    outages: list[tuple[float, float]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: the GPS condition of the fixes fed (:func:`posbench.config.gps_condition`)
    gps_condition: str = "native"
    #: fixes drawn by posbench (a GPS profile): the slow error [m] it drew for each fix of
    #: ``gps_all``, (len(gps_all), 2) east, north (:class:`posbench.scenarios.degrade.DrawnGps`);
    #: None for a receiver's own fixes (its slow error is not known)
    gps_slow_xy: np.ndarray | None = None


def _input_gps(
    drive: Drive, cfg: RunConfig, seed: int, condition: str
) -> tuple[GpsStream, np.ndarray | None, list[str]]:
    """The fixes fed under GPS ``condition``: the drive's own, or drawn from its truth
    (then with the slow error drawn for each fix [m], (n, 2); else None)."""
    if condition != "native":
        from posbench.scenarios.degrade import draw_gps

        assert drive.truth is not None  # gps_condition gives a profile only with a truth
        drawn = draw_gps(
            drive.truth,
            profile=condition,
            seed=seed,
            latency_s=cfg.gps_latency_s,
            intervals=cfg.intervals,
        )
        return (
            drawn.gps,
            drawn.slow_xy,
            [
                f"GPS: {fixes_description(condition)}: intervals {cfg.intervals}, "
                f"latency {cfg.gps_latency_s:g} s, seed {seed}"
            ],
        )
    return drive.gps, None, [f"GPS: {fixes_description(condition)}"]


def _interp(tq: np.ndarray, t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` sampled at times ``t`` [s], interpolated linearly at ``tq`` [s] (NaN outside)."""
    at_tq: np.ndarray = np.interp(tq, t, v, left=np.nan, right=np.nan)
    return at_tq


def _speed_at(drive: Drive, tq: np.ndarray, ref_t: np.ndarray, ref_xy: np.ndarray) -> np.ndarray:
    if drive.truth is not None and drive.truth.v is not None:
        return _interp(tq, drive.truth.t, drive.truth.v)
    if drive.speed is not None and len(drive.speed) > 1:
        return _interp(tq, drive.speed.t, drive.speed.v)
    ok = np.all(np.isfinite(ref_xy), axis=1)
    if ok.sum() < 2:
        return np.full(tq.size, np.nan)
    t, xy = ref_t[ok], ref_xy[ok]
    v = np.hypot(np.gradient(xy[:, 0], t), np.gradient(xy[:, 1], t))
    return _interp(tq, t, v)


def _labels(drive: Drive, tq: np.ndarray, grid_t: np.ndarray, grid_xy: np.ndarray) -> np.ndarray:
    """Scenario labels at query times from the reference track (truth or fitted fixes)."""
    try:
        from posbench.scenarios.labels import label_times
    except ImportError:  # labelling not available: everything is unlabelled
        return np.full(tq.size, "unlabelled")
    ok = np.all(np.isfinite(grid_xy), axis=1)
    if ok.sum() < 8:
        return np.full(tq.size, "unlabelled")
    st = drive.speed.t if drive.speed is not None else None
    sv = drive.speed.v if drive.speed is not None else None
    return np.asarray(
        label_times(tq, grid_t[ok], grid_xy[ok, 0], grid_xy[ok, 1], speed_t=st, speed_v=sv)
    )


def prepare_drive(drive: Drive, cfg: RunConfig) -> PreparedDrive:
    """Draw the input GPS, apply dropouts, place the queries and their references."""
    seed = drive_seed(cfg.seed, drive.name)
    condition = gps_condition(cfg, drive)
    gps, slow_xy, notes = _input_gps(drive, cfg, seed, condition)
    gps_all = gps
    outages: list[tuple[float, float]] = []
    if cfg.dropouts != "none":
        from posbench.scenarios.dropouts import apply_dropouts

        gps, outages = apply_dropouts(gps, cfg.dropouts, seed=seed + 1)
        notes.append(f"dropouts {cfg.dropouts}: {len(outages)} outages")
    reference = TRUTH if drive.truth is not None else FIX_CUBIC

    # future queries: issued at each received fix, asking for fix time + horizon
    f_issue = gps.t.copy()
    f_query = gps.t + cfg.horizon_s
    # now queries: every now_step_s between the first and last received fix
    if len(gps) >= 2:
        n_now = int(np.floor((gps.t[-1] - gps.t[0]) / cfg.now_step_s)) + 1
        n_query = gps.t[0] + cfg.now_step_s * np.arange(n_now)
    else:
        n_query = np.empty(0)

    # a fine reference grid for labels and speed
    t0 = min(gps.t[0], drive.truth.t[0]) if drive.truth is not None and len(gps) else gps.t[0]
    t1 = max(gps.t[-1], drive.truth.t[-1]) if drive.truth is not None and len(gps) else gps.t[-1]
    grid_t = np.arange(t0, t1 + 1e-9, 0.1)
    # one reference evaluation (one truth spline) for the grid and both query kinds, at the
    # query times and HEADING_DT_S before and after them (the reference's direction of travel)
    tq_all = np.concatenate([f_query, n_query])
    dt = HEADING_DT_S
    all_ref = reference_at(drive, np.concatenate([grid_t, tq_all, tq_all - dt, tq_all + dt]))
    grid_xy = all_ref[: grid_t.size]
    at, before, after = np.split(all_ref[grid_t.size :], 3)
    heading, _, yaw_rate = reference_motion(before, at, after, dt)
    nf = f_query.size
    refs = {
        "future": (at[:nf], heading[:nf], yaw_rate[:nf]),
        "now": (at[nf:], heading[nf:], yaw_rate[nf:]),
    }
    del all_ref, before, after

    def queries(kind: str, t_issue: np.ndarray, t_query: np.ndarray) -> Queries:
        ref, heading, yaw_rate = refs[kind]
        last_fix = np.searchsorted(gps.t, t_issue, side="right") - 1
        since = t_query - gps.t[np.clip(last_fix, 0, None)]
        return Queries(
            t_issue,
            t_query,
            ref,
            _speed_at(drive, t_query, grid_t, grid_xy),
            _labels(drive, t_query, grid_t, grid_xy),
            since,
            heading,
            yaw_rate,
        )

    future = queries("future", f_issue, f_query)
    now = queries("now", n_query, n_query)
    return PreparedDrive(
        drive,
        drive.meta.format,
        gps,
        gps_all,
        reference,
        future,
        now,
        outages,
        notes,
        condition,
        slow_xy,
    )
