"""A drive's outcome as one record: :class:`DriveRun` (its traces, call durations, fixes and
notes), what a replay, a Ray task or scored answers produce and aggregation, the report and
the rerun recording read; and the traces of many records as one frame."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
import pandas as pd


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
    }
    for f in fields(DriveRun):
        if isinstance(getattr(first, f.name), dict):
            merged[f.name] = {k: v for p in parts for k, v in getattr(p, f.name).items()}
    return replace(first, **merged)


def all_traces(runs: Sequence[DriveRun]) -> pd.DataFrame:
    """Every run's per-query traces in one frame (a single run's frame is returned as is)."""
    frames = [r.traces for r in runs if not r.traces.empty]
    if len(frames) == 1:
        return frames[0]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


#: text columns of the traces that aggregation and figures filter and group by, again and again
TEXT_COLUMNS = ("dataset", "drive", "predictor")


def lean_traces(traces: pd.DataFrame) -> pd.DataFrame:
    """``traces`` with its :data:`TEXT_COLUMNS` as categoricals (the same values), for
    :func:`aggregate` and the figures: every row filter then copies small integer codes
    instead of strings (on the shared data ~0.5-0.9 CPU-s less aggregation and ~0.2-0.3 less
    per figure process; results and files the same to the bit). Saved traces keep their
    text columns."""
    cols = {
        c: "category"
        for c in TEXT_COLUMNS
        if c in traces.columns and not isinstance(traces[c].dtype, pd.CategoricalDtype)
    }
    return traces.astype(cols) if cols else traces
