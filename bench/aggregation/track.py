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

from posbench.metrics.track_errors import inward_cross, track_summary
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet

NEEDED = ("predictor", "kind", "label", "error_m", "along_m", "cross_m", "yaw_rate_ref")


def track_section(traces: TraceSet, predictors: Sequence[str]) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_label": {name: {kind: {label: summary}}}}``
    over the scored rows (the headline figures') of ``traces``, one predictor at a time;
    empty dicts when the traces have no along/cross-track columns (answers scored before
    they existed)."""
    out: dict[str, Any] = {"predictors": {}, "by_label": {}}
    if traces.empty or any(c not in traces for c in NEEDED):
        return out
    for name, rows in traces.per_predictor(predictors, NEEDED):
        kind = text_values(rows["kind"])
        label = text_values(rows["label"], as_str=True)
        cols = np.column_stack(
            [
                rows["along_m"].to_numpy(float),
                rows["cross_m"].to_numpy(float),
                inward_cross(rows["cross_m"].to_numpy(float), rows["yaw_rate_ref"].to_numpy(float)),
                rows["error_m"].to_numpy(float),
            ]
        )
        del rows  # the arrays above are what the summaries read
        out["predictors"][name] = {}
        out["by_label"][name] = {}
        for k in KINDS:
            mine = kind == k
            sub, labels = cols[mine], label[mine]
            out["predictors"][name][k] = track_summary(*sub.T)
            out["by_label"][name][k] = {lab: track_summary(*sub[labels == lab].T) for lab in LABELS}
    return out
