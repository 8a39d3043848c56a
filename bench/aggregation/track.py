"""The ``track_errors`` block of results.json: where the error points (schema 1.2).

Per predictor and kind (and per scenario label), :func:`posbench.metrics.track_errors.track_summary`
of the scored queries' along-track and cross-track errors (trace columns ``along_m``,
``cross_m``) and of the cross-track error signed toward the inside of the turn
(:func:`posbench.metrics.track_errors.inward_cross` of ``cross_m`` and ``yaw_rate_ref``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.row_columns import RowColumns
from posbench.metrics.track_errors import inward_cross, track_summary
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet

NEEDED = ("predictor", "kind", "label", "error_m", "along_m", "cross_m", "yaw_rate_ref")


def _track_columns(traces: TraceSet, name: str) -> tuple[dict[str, np.ndarray], dict[str, slice]]:
    """Predictor ``name``'s scored rows as the four errors the summaries read (along, cross,
    inward, Euclidean [m]) and the route type (index into :data:`LABELS`; -1: another),
    read one part of the traces at a time and put in kind order (each kind's rows keep
    theirs), with each kind of :data:`KINDS` -> its slice. About 33 bytes a query."""
    columns = RowColumns(
        {
            "along": np.float64,
            "cross": np.float64,
            "inward": np.float64,
            "error": np.float64,
            "kind": np.int8,
            "label": np.int8,
        },
        traces.row_bound(name),
    )
    kinds, labels = pd.Index(KINDS), pd.Index(LABELS)
    for rows in traces.pieces(name, NEEDED):
        cross = rows["cross_m"].to_numpy(float)
        columns.add(
            along=rows["along_m"].to_numpy(float),
            cross=cross,
            inward=inward_cross(cross, rows["yaw_rate_ref"].to_numpy(float)),
            error=rows["error_m"].to_numpy(float),
            kind=kinds.get_indexer(text_values(rows["kind"])),
            label=labels.get_indexer(text_values(rows["label"], as_str=True)),
        )
    order, slices = columns.group_order("kind", len(KINDS))
    rows_of = dict(zip(KINDS, slices, strict=True))
    cols = {c: columns.take(c, order) for c in ("along", "cross", "inward", "error", "label")}
    return cols, rows_of


def track_section(traces: TraceSet, predictors: Sequence[str]) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_label": {name: {kind: {label: summary}}}}``
    over the scored rows (the headline figures') of ``traces``, one predictor at a time;
    empty dicts when the traces have no along/cross-track columns (answers scored before
    they existed)."""
    out: dict[str, Any] = {"predictors": {}, "by_label": {}}
    if traces.empty or any(c not in traces for c in NEEDED):
        return out
    for name in predictors:
        cols, rows_of = _track_columns(traces, name)
        out["predictors"][name] = {}
        out["by_label"][name] = {}
        for k in KINDS:
            mine = rows_of[k]  # a slice: the kind's rows are together
            sub = [cols[c][mine] for c in ("along", "cross", "inward", "error")]
            labels = cols["label"][mine]
            out["predictors"][name][k] = track_summary(*sub)
            out["by_label"][name][k] = {
                lab: track_summary(*(v[labels == i] for v in sub)) for i, lab in enumerate(LABELS)
            }
        del cols
    return out
