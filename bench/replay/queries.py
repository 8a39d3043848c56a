"""One prepared drive's queries as a table: every query with the reference it is scored
against (the query columns of the traces, :data:`posbench.scoring.schema.QUERY_COLUMNS`),
and where its warm-up ends."""

from __future__ import annotations

import numpy as np
import pandas as pd

from posbench.metrics.outages import outage_ids
from posbench.replay.prepare import PreparedDrive, Queries
from posbench.scoring.schema import KIND_DTYPE, LABEL_CATEGORIES


def warmup_end_s(prep: PreparedDrive) -> float:
    """When a drive's warm-up ends [s]: the time of its second received fix (inf with fewer).

    Queries issued before it are warm-up: no predictor can know a velocity from one fix, so
    their errors measure the cold start, not prediction. They are kept in the traces
    (column ``warmup``) and reported apart, never in the headline figures.
    """
    return float(prep.gps.t[1]) if len(prep.gps) >= 2 else float("inf")


def query_frame(prep: PreparedDrive, kind: str) -> pd.DataFrame:
    """One drive's queries of one kind (``future`` or ``now``) with what they are scored
    against: the :data:`QUERY_COLUMNS` of the traces."""
    q: Queries = prep.future if kind == "future" else prep.now
    return pd.DataFrame(
        {
            "dataset": prep.dataset,
            "drive": prep.drive.name,
            "kind": kind,
            "t_issue": q.t_issue,
            "t_query": q.t_query,
            "x_ref": q.ref_xy[:, 0],
            "y_ref": q.ref_xy[:, 1],
            "label": pd.Categorical(q.label, categories=LABEL_CATEGORIES),
            "speed_mps": q.speed_mps,
            "since_fix_s": q.since_fix_s,
            "outage": outage_ids(q.t_query, prep.outages),
            "warmup": q.t_issue < warmup_end_s(prep),
            "heading_ref": _or_nan(q.heading_rad, q.t_query.size),
            "yaw_rate_ref": _or_nan(q.yaw_rate, q.t_query.size),
        }
    ).astype({"kind": KIND_DTYPE})


def _or_nan(values: np.ndarray | None, n: int) -> np.ndarray:
    return np.full(n, np.nan) if values is None else np.asarray(values, dtype=float)
