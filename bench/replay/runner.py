"""Run predictors over drives: prepare, replay, score. Drives run in parallel
processes; results are merged in drive order, so they are identical for any
number of workers."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import as_completed
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.config import RunConfig
from posbench.replay.gps_outliers import GatedPredictor
from posbench.replay.loop import replay
from posbench.replay.paper_moment import PAPER_PREDICTOR, moment_probe
from posbench.replay.predictor_setup import build_predictor
from posbench.replay.prepare import PreparedDrive, prepare_drive
from posbench.replay.queries import query_frame
from posbench.replay.reference import truth_source
from posbench.scenarios.child_processes import WorkerPool
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import DriveInfo, StoredDrive, as_drive
from posbench.scenarios.truth_gaps import truth_gap_note
from posbench.scoring.part_writer import PartWriter
from posbench.scoring.records import DriveRun, merge_predictor_runs
from posbench.scoring.score import score_many


def _fixes_frame(prep: PreparedDrive) -> pd.DataFrame:
    received = np.isin(prep.gps_all.t, prep.gps.t)
    return pd.DataFrame(
        {"t": prep.gps_all.t, "x": prep.gps_all.x, "y": prep.gps_all.y, "received": received}
    )


def _track_frame(prep: PreparedDrive) -> pd.DataFrame:
    d = prep.drive
    if d.truth is not None:
        tr = d.truth
        step = max(1, int(round(0.1 / np.median(np.diff(tr.t))))) if len(tr) > 1 else 1
        return pd.DataFrame({"t": tr.t[::step], "x": tr.x[::step], "y": tr.y[::step]})
    from posbench.replay.reference import cubic_through_fixes

    t = np.arange(d.gps.t[0], d.gps.t[-1], 0.1)
    xy = cubic_through_fixes(d.gps.t, d.gps.x, d.gps.y, t)
    return pd.DataFrame({"t": t, "x": xy[:, 0], "y": xy[:, 1]})


#: ``meta.extra`` keys a loader sets about sensor frames and truth (see scenarios.loaders.rosbag)
SENSOR_FRAME_KEYS = ("imu_frame", "truth_kind", "truth_alignment")


def sensor_frames(drive: Drive | DriveInfo) -> dict[str, Any]:
    """What the loader did about sensor frames and truth: the IMU path (levelled by its
    orientation, mount from tf, estimated, as-is), what the drive is scored against, and
    the alignment of a named truth (rotation, translation, residual RMS [m])."""
    return {k: drive.meta.extra[k] for k in SENSOR_FRAME_KEYS if k in drive.meta.extra}


def skip_reason(drive: Drive | DriveInfo, cfg: RunConfig) -> str | None:
    """Why ``drive`` is not scored under ``cfg`` (None: it is)."""
    if cfg.exclude_poor_truth and drive.meta.extra.get("truth_poor"):
        return "poor truth accuracy (median > 1 m)"
    return None


def skipped_run(drive: Drive | DriveInfo, reason: str) -> DriveRun:
    """The record of a drive that is not scored, with the reason."""
    return DriveRun(
        drive.name,
        drive.meta.format,
        "",
        [],
        list(drive.meta.warnings),
        pd.DataFrame(),
        skipped=reason,
        sensor_frames=sensor_frames(drive),
    )


def refuse_far_answers(
    name: str, drive: str, prep: PreparedDrive, future_xy: np.ndarray, now_xy: np.ndarray
) -> None:
    """A predictor's answers must be positions: one farther than
    :data:`~posbench.scenarios.drive.MAX_POSITION_M` from the drive's origin (farther than any
    point on Earth) is a broken predictor, refused in one line naming it, the drive and the
    query time, as ``bench score`` refuses such an answer (the figures would overflow).

    Raises:
        DataError: the first such answer (future queries first, then now queries).
    """
    from posbench.scenarios.drive import MAX_POSITION_M
    from posbench.scenarios.errors import DataError

    for kind, xy, q in (("future", future_xy, prep.future), ("now", now_xy, prep.now)):
        with np.errstate(invalid="ignore"):
            far = np.abs(xy) > MAX_POSITION_M
        rows = np.flatnonzero(far.any(axis=1)) if xy.size else np.empty(0, dtype=int)
        if rows.size:
            i = int(rows[0])
            raise DataError(
                None,
                f"predictor {name} answered ({xy[i, 0]:g}, {xy[i, 1]:g}) m for the {kind} "
                f"query at t={float(q.t_query[i]):.3f} s of drive {drive}: no position (more than "
                f"{MAX_POSITION_M:g} m from the drive's origin, farther than any point on "
                f"Earth); {rows.size} such {kind} answers on this drive",
            )


def part_name(index: int, predictor: int | None = None) -> str:
    """The name of the traces part of drive ``index`` (of its ``predictor``-th predictor's
    task, when the drive is replayed one predictor per task): names sort in drive, then
    predictor order."""
    return f"drive-{index:06d}" + ("" if predictor is None else f"-{predictor:03d}")


#: query rows scored at a time, per predictor: what a worker holds of a drive's
#: traces, whatever the drive's span
TRACE_CHUNK_ROWS = 1 << 16


def run_drive(
    drive: Drive | StoredDrive,
    cfg: RunConfig,
    limit: bool = False,
    parts: Path | None = None,
    part: str = "drive",
) -> DriveRun:
    """Prepare one drive and replay it through every configured predictor; with ``limit``,
    also compute the bound on its scored queries (:func:`posbench.replay.limit.drive_limit`;
    ``bench run`` asks for it, once per drive). Given a folder ``parts``, its traces are
    written there as part ``part`` while they are scored, :data:`TRACE_CHUNK_ROWS` queries at
    a time, and the record names the file instead of holding them
    (:meth:`~posbench.scoring.records.DriveRun.spill`): what returns to the caller is small.
    A stored drive is read here (:func:`~posbench.scenarios.stored_drive.as_drive`), unless
    it is not scored."""
    described = drive.info if isinstance(drive, StoredDrive) else drive  # its meta: enough
    reason = skip_reason(described, cfg)
    if reason:
        record = skipped_run(described, reason)
        return record.spill(parts, part) if parts is not None else record
    if parts is None:
        return _run_drive(as_drive(drive), cfg, limit, None)
    with PartWriter(parts, part) as writer:
        record = _run_drive(as_drive(drive), cfg, limit, writer)
        if writer.rows:
            record = replace(record, trace_parts=[str(writer.close())], trace_rows=writer.rows)
    return record.spill(parts, part)


def _query_chunks(prep: PreparedDrive) -> list[tuple[slice, slice]]:
    """The queries of ``prep`` (future then now) cut into pieces of at most
    :data:`TRACE_CHUNK_ROWS`: per piece, its future rows and its now rows (at least one
    piece, of no rows when the drive has no query)."""
    n_future, total = prep.future.t_query.size, prep.future.t_query.size + prep.now.t_query.size
    out = []
    for lo in range(0, max(total, 1), TRACE_CHUNK_ROWS):
        hi = min(lo + TRACE_CHUNK_ROWS, total)
        out.append(
            (
                slice(min(lo, n_future), min(hi, n_future)),
                slice(max(lo - n_future, 0), max(hi - n_future, 0)),
            )
        )
    return out


def _chunk_queries(prep: PreparedDrive, future: slice, now: slice) -> pd.DataFrame:
    """The query table of one piece: its future rows, then its now rows."""
    frames = [query_frame(prep, "future", future), query_frame(prep, "now", now)]
    return pd.concat(frames, ignore_index=True)


def _run_drive(drive: Drive, cfg: RunConfig, limit: bool, writer: PartWriter | None) -> DriveRun:
    """``drive`` through every predictor of ``cfg``: each predictor's traces scored as soon as
    it is replayed and given to ``writer`` piece by piece (None: kept in the record)."""
    prep = prepare_drive(drive, cfg)
    step_ns, query_ns, cov_ns, rejected = {}, {}, {}, {}
    bound: pd.DataFrame | None = None
    bound_info: dict[str, Any] = {}
    chunks = _query_chunks(prep)
    # a drive of one piece (most): its query table made once for every predictor
    held = _chunk_queries(prep, *chunks[0]) if len(chunks) == 1 else None
    if limit:
        from posbench.replay.limit import LIMIT_QUERY_COLUMNS, drive_limit

        queries = held
        if queries is None:  # a long drive: the columns the bound reads, no more
            queries = pd.concat(
                [query_frame(prep, k, columns=LIMIT_QUERY_COLUMNS) for k in ("future", "now")],
                ignore_index=True,
            )
        bound, bound_info = drive_limit(prep, queries, cfg)
        del queries
    pieces: list[pd.DataFrame] = []
    keep = pieces.append if writer is None else writer.write
    # a drive of one piece: every predictor's answers scored together once all are replayed
    # (one table, as small as the drive); a longer one: each predictor's as soon as it is
    answers: list[tuple[str, np.ndarray, np.ndarray | None]] = []
    paper_moment: dict[str, Any] = {}
    for name in cfg.predictors:
        pred = build_predictor(cfg, name, prep.gps_condition)
        pred.warm_up()  # one-time start-up work (compiled kernels) off the clock
        gated = GatedPredictor(pred) if cfg.gate else None
        probe = None
        if name == PAPER_PREDICTOR:  # its step at the paper figures' moment, recorded
            probe, paper_moment = moment_probe(pred, prep.future, cfg.horizon_s)
        res = replay(pred if gated is None else gated, prep, cfg.horizon_s, probe)
        refuse_far_answers(name, drive.name, prep, res.future_xy, res.now_xy)
        if gated is not None:
            rejected[name] = gated.rejected
        step_ns[name] = res.step_ns
        query_ns[name] = res.query_ns
        if res.cov_ns is not None:
            cov_ns[name] = res.cov_ns
        xy = np.concatenate([res.future_xy, res.now_xy])
        if held is not None:
            answers.append((name, xy, res.cov))
            continue
        lo = 0
        for future, now in chunks:  # each piece scored and handed on: future, then now rows
            queries = _chunk_queries(prep, future, now)
            hi = lo + len(queries)
            cov = None if res.cov is None else res.cov[lo:hi]
            keep(score_many(queries, [(name, xy[lo:hi], cov)]))
            lo = hi
        del res, xy
    if held is not None and answers:
        scored = score_many(held, answers)
        del answers
        if writer is None:
            pieces.append(scored)
        else:
            writer.write_by_predictor(scored)
        del scored
    if writer is None:
        if len(pieces) == 1:
            traces = pieces[0]
        else:
            traces = pd.concat(pieces, ignore_index=True) if pieces else pd.DataFrame()
    else:
        traces = writer.empty if writer.empty is not None else pd.DataFrame()
    del pieces
    gaps = truth_gap_note(drive.truth.t) if drive.truth is not None else ""
    return DriveRun(
        drive.name,
        prep.dataset,
        prep.reference,
        prep.notes,
        list(drive.meta.warnings) + ([gaps] if gaps else []),
        traces,
        step_ns,
        query_ns,
        prep.outages,
        gps_count=len(prep.gps),
        duration_s=drive.duration_s,
        fixes=_fixes_frame(prep),
        track=_track_frame(prep),
        sensor_frames=sensor_frames(drive),
        rejected=rejected,
        cov_ns=cov_ns,
        gps_condition=prep.gps_condition,
        truth_source=truth_source(drive),
        limit=bound,
        limit_info=bound_info,
        reference_gaps=gaps,
        paper_moment=paper_moment,
    )


def _init_worker() -> None:
    """One thread per worker process: onnxruntime / BLAS must not oversubscribe the cores."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"


def replay_cost(drive: Drive | StoredDrive, cfg: RunConfig) -> float:
    """A drive's replay work, in events: its samples (fixes, IMU, speed) and its "now"
    queries. Only the order matters (the runner starts the costliest drives first)."""
    info = DriveInfo.of(drive)
    return info.samples + info.duration_s / cfg.now_step_s


def plan_tasks(
    drives: Sequence[Drive | StoredDrive], cfg: RunConfig, workers: int
) -> list[tuple[int, str | None]]:
    """The local runner's tasks, costliest first: (drive index, None) replays a drive through
    every predictor; (drive index, name) through predictor ``name`` only. A drive holding
    more than 1 / (2 x workers) of the run's work (:func:`replay_cost`) is split by
    predictor, so that one long drive still keeps every worker busy."""
    costs = [replay_cost(d, cfg) for d in drives]
    limit = sum(costs) / (2 * max(workers, 1))
    tasks: list[tuple[float, int, str | None]] = []
    for i, c in enumerate(costs):
        if c > limit and len(cfg.predictors) > 1:
            tasks += [(c / len(cfg.predictors), i, name) for name in cfg.predictors]
        else:
            tasks.append((c, i, None))
    tasks.sort(key=lambda x: -x[0])  # stable: equal costs keep drive and predictor order
    return [(i, name) for _, i, name in tasks]


def run(
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    workers: int = 1,
    on_done: Callable[[DriveRun], None] | None = None,
    limit: bool = False,
    parts: Path | None = None,
) -> list[DriveRun]:
    """Run all drives; ``on_done`` is called as each finishes (for a progress bar); with
    ``limit``, each drive's bound is computed too (:func:`run_drive`; by one task of a drive
    split by predictor, the first predictor's). Given a folder ``parts``, each task writes
    its traces there (:func:`run_drive`, :func:`part_name`) and returns a small record.
    The returned list is in the order of ``drives`` whatever ``workers`` is. With several
    workers the costliest drives start first, and a drive long enough to hold a worker
    alone is replayed one predictor per task (:func:`plan_tasks`); its parts are merged as
    :func:`run_drive` would have made it (:func:`merge_predictor_runs`). The workers end
    with this process and leave Ctrl-C to it; an error or Ctrl-C here ends them at once
    (:class:`~posbench.scenarios.child_processes.WorkerPool`)."""
    out: list[DriveRun | None] = [None] * len(drives)
    if workers <= 1 or not drives or (len(drives) == 1 and len(cfg.predictors) <= 1):
        for i, d in enumerate(drives):
            out[i] = drive_run = run_drive(d, cfg, limit, parts, part_name(i))
            if on_done:
                on_done(drive_run)
        return [r for r in out if r is not None]
    tasks = plan_tasks(drives, cfg, workers)
    pieces: dict[int, dict[str, DriveRun]] = {}
    n_parts = {i: sum(1 for j, _ in tasks if j == i) for i in range(len(drives))}
    with WorkerPool(min(workers, len(tasks)), initializer=_init_worker) as pool:
        futures = {
            pool.submit(
                run_drive,
                drives[i],
                cfg if name is None else replace(cfg, predictors=(name,)),
                limit and (name is None or name == cfg.predictors[0]),  # once per drive
                parts,
                part_name(i, None if name is None else cfg.predictors.index(name)),
            ): (i, name)
            for i, name in tasks
        }
        for fut in as_completed(futures):
            i, name = futures[fut]
            if name is None:
                drive_run = fut.result()
            else:
                pieces.setdefault(i, {})[name] = fut.result()
                if len(pieces[i]) < n_parts[i]:
                    continue
                mine = pieces.pop(i)
                drive_run = merge_predictor_runs([mine[n] for n in cfg.predictors])
            out[i] = drive_run
            if on_done:
                on_done(drive_run)
    return [r for r in out if r is not None]
