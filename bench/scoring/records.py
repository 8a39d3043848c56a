"""A drive's outcome as one record: :class:`DriveRun` (its traces, call durations, fixes and
notes), what a replay, a Ray task or scored answers produce and aggregation, the report and
the rerun recording read; and the traces of many records as one frame."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.scoring.part_writer import write_part
from posbench.scoring.trace_parts import read_file
from posbench.scoring.trace_set import TraceSet


@dataclass
class DriveRun:
    """One drive's outcome: per-query traces and per-predictor call durations [ns]."""

    name: str
    dataset: str
    reference: str
    notes: list[str]
    warnings: list[str]
    traces: pd.DataFrame
    step_ns: dict[str, np.ndarray] = field(default_factory=dict)
    query_ns: dict[str, np.ndarray] = field(default_factory=dict)
    outages: list[tuple[float, float]] = field(default_factory=list)
    skipped: str | None = None
    gps_count: int = 0
    duration_s: float = 0.0
    fixes: pd.DataFrame | None = None  # t, x, y, received (False = removed by dropouts)
    track: pd.DataFrame | None = None  # t, x, y of the reference (truth or fix cubic), 10 Hz
    rejected: dict[str, int] = field(default_factory=dict)  # fixes the outlier gate dropped
    sensor_frames: dict[str, Any] = field(default_factory=dict)  # see sensor_frames()
    #: covariance_at durations [ns] of the predictors that report one (timed apart)
    cov_ns: dict[str, np.ndarray] = field(default_factory=dict)
    #: the GPS condition its fixes were fed under (``native``: the recording's own receiver;
    #: a profile: drawn from the truth); "" for a skipped drive
    gps_condition: str = ""
    #: what its truth is, in words, where the drive is scored against one
    #: (:func:`posbench.replay.reference.truth_source`); "" for none or not known
    truth_source: str = ""
    #: the bound on its scored queries, one row each (kind, t_query, label, limit_m,
    #: limit_imu_m: :data:`posbench.replay.limit.LIMIT_COLUMNS`); None: not computed
    limit: pd.DataFrame | None = None
    #: what the bound took (q, the fixes' white noise, the slow floor, the IMU's noise, ...:
    #: :func:`posbench.replay.limit.drive_limit`); empty without a bound
    limit_info: dict[str, Any] = field(default_factory=dict)
    #: why part of its truth's span has no reference position (its samples farther apart
    #: than the reference interpolates across:
    #: :func:`posbench.scenarios.truth_gaps.truth_gap_note`, also among its ``warnings``);
    #: "" where none
    reference_gaps: str = ""
    #: where its traces are when the worker wrote them to disk
    #: (:func:`posbench.scoring.part_writer.write_part`, one part per task, in predictor
    #: order): ``traces`` is then empty and these hold its ``trace_rows`` rows
    trace_parts: list[str] = field(default_factory=list)
    trace_rows: int = 0
    #: where its call durations are when spilled (``.npz`` per task: ``step/NAME``,
    #: ``query/NAME``, ``cov/NAME`` [ns]); the dicts above then hold none
    timing_parts: list[str] = field(default_factory=list)
    #: where its bound's rows are when spilled (Parquet); ``limit`` is then None
    limit_part: str = ""
    #: where its fixes and reference track are when spilled (``.npz``: ``fixes/COLUMN``,
    #: ``track/COLUMN``); ``fixes`` and ``track`` are then None
    #: (:meth:`with_fixes_and_track` reads them back)
    track_part: str = ""
    #: the moment the paper's figures show, recorded while its ``lstm`` was replayed
    #: (:func:`posbench.replay.paper_moment.moment_probe`: ``turns``, and where lstm stepped
    #: on the moment's fix ``t_fix``, ``grid``, ``pred``, ``now_t``, ``now_xy``); empty
    #: without lstm
    paper_moment: dict[str, Any] = field(default_factory=dict)

    @property
    def has_traces(self) -> bool:
        """Whether any query of the drive was traced (in memory or in its parts)."""
        return not self.traces.empty or self.trace_rows > 0

    def load_traces(self, columns: Sequence[str] | None = None) -> pd.DataFrame:
        """Its traces (only ``columns``, given them), from memory or from its parts."""
        if self.trace_parts and self.traces.empty:
            return TraceSet(parts=self.trace_parts).frame(columns)
        if columns is None or self.traces.empty:
            return self.traces
        return self.traces[[c for c in columns if c in self.traces.columns]]

    def call_ns(self, call: str, name: str) -> np.ndarray | None:
        """Predictor ``name``'s ``call`` durations [ns] (``step``, ``query`` or ``cov``), from
        memory or from its spilled timings; None where it has none."""
        held: dict[str, np.ndarray] = getattr(self, f"{call}_ns")
        if name in held:
            return held[name]
        key = f"{call}/{name}"
        for path in self.timing_parts:
            with np.load(path) as z:
                if key in z.files:
                    return np.asarray(z[key])
        return None

    @property
    def has_limit(self) -> bool:
        """Whether its bound was computed (held or spilled)."""
        return self.limit is not None or bool(self.limit_part)

    def load_limit(self) -> pd.DataFrame | None:
        """Its bound's rows (:data:`posbench.replay.limit.LIMIT_COLUMNS`), from memory or
        disk; None when not computed."""
        if self.limit is None and self.limit_part:
            return read_file(self.limit_part)
        return self.limit

    def with_fixes_and_track(self) -> DriveRun:
        """This record with its fixes and reference track in memory (read back from
        ``track_part`` when spilled; itself when not)."""
        if not self.track_part:
            return self
        with np.load(self.track_part) as z:
            frames = {
                kind: pd.DataFrame(
                    {k.split("/", 1)[1]: z[k] for k in z.files if k.startswith(f"{kind}/")}
                )
                for kind in {k.split("/", 1)[0] for k in z.files}
            }
        return replace(self, fixes=frames.get("fixes"), track=frames.get("track"), track_part="")

    def spill(self, folder: Path, name: str) -> DriveRun:
        """This record with what grows with the drive's span - its traces
        (:func:`~posbench.scoring.part_writer.write_part`), call durations, bound's rows,
        fixes and reference track - written to ``folder`` under ``name`` and dropped from
        memory: what remains is small and the same for a drive of any length, but for its
        notes."""
        folder.mkdir(parents=True, exist_ok=True)
        changes: dict[str, Any] = {}
        if not self.traces.empty:
            path = write_part(folder, self.traces, name)
            changes |= {
                "traces": self.traces.iloc[:0],
                "trace_parts": [str(path)],
                "trace_rows": len(self.traces),
            }
        timings = {
            f"{call}/{n}": a
            for call in ("step", "query", "cov")
            for n, a in getattr(self, f"{call}_ns").items()
        }
        if timings:
            path = folder / f"{name}.ns.npz"
            np.savez(path, **timings)
            changes |= {"step_ns": {}, "query_ns": {}, "cov_ns": {}, "timing_parts": [str(path)]}
        if self.limit is not None:
            path = folder / f"{name}.limit.parquet"
            self.limit.to_parquet(path, index=False)
            changes |= {"limit": None, "limit_part": str(path)}
        frames = {
            f"{kind}/{column}": frame[column].to_numpy()
            for kind in ("fixes", "track")
            if (frame := getattr(self, kind)) is not None
            for column in frame.columns
        }
        if frames:
            path = folder / f"{name}.track.npz"
            np.savez(path, **frames)
            changes |= {"fixes": None, "track": None, "track_part": str(path)}
        return replace(self, **changes)


def merge_predictor_runs(parts: Sequence[DriveRun]) -> DriveRun:
    """One drive's per-predictor runs (in predictor order) as one run, exactly as
    :func:`run_drive` would have made it with all predictors: traces are concatenated (per
    predictor: future, then now) with a fresh index, and every per-predictor dict (step_ns,
    query_ns, ...) is joined in predictor order. The rest (prepared-drive figures: notes,
    outages, fixes, ...) is the same in every part; the bound (``limit``) is computed by
    one part only and taken from it."""
    first = parts[0]
    frames = [p.traces for p in parts if not p.traces.empty]
    merged: dict[str, Any] = {
        "traces": pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(),
        "limit": next((p.limit for p in parts if p.limit is not None), None),
        "trace_parts": [f for p in parts for f in p.trace_parts],
        "trace_rows": sum(p.trace_rows for p in parts),
        "timing_parts": [f for p in parts for f in p.timing_parts],
        "limit_part": next((p.limit_part for p in parts if p.limit_part), ""),
    }
    for f in fields(DriveRun):
        if isinstance(getattr(first, f.name), dict):
            merged[f.name] = {k: v for p in parts for k, v in getattr(p, f.name).items()}
    return replace(first, **merged)


def all_traces(runs: Sequence[DriveRun]) -> pd.DataFrame:
    """Every run's per-query traces in one frame (a single run's frame is returned as is;
    traces written to parts are read back: for small runs, see :func:`trace_set`)."""
    frames = [r.load_traces() for r in runs if r.has_traces]
    if len(frames) == 1:
        return frames[0]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def trace_set(runs: Sequence[DriveRun]) -> TraceSet:
    """The runs' traces as a :class:`~posbench.scoring.trace_set.TraceSet`: their parts on
    disk when the workers wrote them there, else the frame of :func:`all_traces`."""
    if any(r.trace_parts for r in runs):
        if any(not r.traces.empty for r in runs):
            raise ValueError("runs with traces both in memory and on disk")
        return TraceSet(parts=[f for r in runs for f in r.trace_parts])
    return TraceSet(all_traces(runs))
