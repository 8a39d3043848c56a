"""One prepared drive's queries as a table: every query with the reference it is scored
against (the query columns of the traces, :data:`posbench.scoring.schema.QUERY_COLUMNS`),
and where its warm-up ends."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

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


def query_frame(
    prep: PreparedDrive,
    kind: str,
    rows: slice = slice(None),
    columns: Sequence[str] | None = None,
) -> pd.DataFrame:
    """One drive's queries of one kind (``future`` or ``now``) with what they are scored
    against: the :data:`QUERY_COLUMNS` of the traces (``columns`` only, given them), of the
    queries ``rows`` (a slice of that kind's queries, in time order; default all)."""
    q: Queries = prep.future if kind == "future" else prep.now
    t_issue, t_query = q.t_issue[rows], q.t_query[rows]
    n = t_query.size
    make: dict[str, Callable[[], Any]] = {
        "dataset": lambda: prep.dataset,
        "drive": lambda: prep.drive.name,
        "kind": lambda: kind,
        "t_issue": lambda: t_issue,
        "t_query": lambda: t_query,
        "x_ref": lambda: q.ref_xy[rows, 0],
        "y_ref": lambda: q.ref_xy[rows, 1],
        "label": lambda: pd.Categorical(q.label[rows], categories=LABEL_CATEGORIES),
        "speed_mps": lambda: q.speed_mps[rows],
        "since_fix_s": lambda: q.since_fix_s[rows],
        "outage": lambda: outage_ids(t_query, prep.outages),
        "warmup": lambda: t_issue < warmup_end_s(prep),
        "heading_ref": lambda: _or_nan(None if q.heading_rad is None else q.heading_rad[rows], n),
        "yaw_rate_ref": lambda: _or_nan(None if q.yaw_rate is None else q.yaw_rate[rows], n),
    }
    wanted = list(make) if columns is None else list(columns)
    frame = pd.DataFrame({c: make[c]() for c in wanted}, index=pd.RangeIndex(n))
    return frame.astype({"kind": KIND_DTYPE}) if "kind" in frame else frame


def _or_nan(values: np.ndarray | None, n: int) -> np.ndarray:
    return np.full(n, np.nan) if values is None else np.asarray(values, dtype=float)
