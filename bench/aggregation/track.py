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

from posbench.metrics.track_errors import inward_cross, track_summary
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS

NEEDED = ("predictor", "kind", "label", "error_m", "along_m", "cross_m", "yaw_rate_ref")


def track_section(
    traces: pd.DataFrame, keep: np.ndarray, predictors: Sequence[str]
) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_label": {name: {kind: {label: summary}}}}``
    over the rows ``keep`` (the headline figures' scored rows) of ``traces``; empty dicts
    when the traces have no along/cross-track columns (answers scored before they existed)."""
    out: dict[str, Any] = {"predictors": {}, "by_label": {}}
    if traces.empty or any(c not in traces for c in NEEDED):
        return out
    # codes only meet the names through the *_of maps: no text copy of the columns needed
    pred_codes, pred_names = pd.factorize(traces["predictor"])
    kind_codes, kind_names = pd.factorize(traces["kind"])
    label_codes, label_names = pd.factorize(traces["label"])
    cols = np.column_stack(
        [
            traces["along_m"].to_numpy(float),
            traces["cross_m"].to_numpy(float),
            np.zeros(len(traces)),
            traces["error_m"].to_numpy(float),
        ]
    )
    cols[:, 2] = inward_cross(cols[:, 1], traces["yaw_rate_ref"].to_numpy(float))
    pred_of = {str(n): i for i, n in enumerate(pred_names)}
    kind_of = {str(n): i for i, n in enumerate(kind_names)}
    label_of = {str(n): i for i, n in enumerate(label_names)}
    for name in predictors:
        mine = keep & (pred_codes == pred_of.get(name, -1))
        out["predictors"][name] = {}
        out["by_label"][name] = {}
        for k in KINDS:
            rows = np.flatnonzero(mine & (kind_codes == kind_of.get(k, -1)))
            sub, labels = cols[rows], label_codes[rows]
            out["predictors"][name][k] = track_summary(*sub.T)
            out["by_label"][name][k] = {
                lab: track_summary(*sub[labels == label_of.get(lab, -1)].T) for lab in LABELS
            }
    return out
