"""The ``uncertainty`` block of results.json (schema 1.4): is each predictor's reported
covariance honest?

Per predictor that reports covariance (trace columns ``cov_xx``, ``cov_xy``, ``cov_yy``)
and kind, :func:`posbench.metrics.calibration.calibration_summary` of the scored queries (the
headline rows: past warm-up, reference known) with the NEES's cluster-bootstrap CI
(drives resampled), and without CI by data set, by route type (scenario label) and by
time since the last fix (:data:`posbench.metrics.calibration.SINCE_FIX_EDGES_S`), plus the
calibration curve. A predictor without any covariance is listed under ``none``: the
report says "no uncertainty" for it, never a made-up figure.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import drive_codes
from posbench.metrics.calibration import (
    calibration_curve,
    calibration_summary,
    mahalanobis_sq,
    since_fix_bin,
)
from posbench.scoring.schema import COV_COLUMNS, KINDS
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet

COV = list(COV_COLUMNS)
NEEDED = (
    "predictor",
    "kind",
    "dataset",
    "drive",
    "label",
    "since_fix_s",
    "x",
    "y",
    "x_ref",
    "y_ref",
    "t_query",
    *COV,
)


def _errors(rows: pd.DataFrame) -> np.ndarray:
    """(N, 2) answer minus reference [m, ENU]."""
    err: np.ndarray = rows[["x", "y"]].to_numpy(float) - rows[["x_ref", "y_ref"]].to_numpy(float)
    return err


def uncertainty_section(traces: TraceSet, predictors: Sequence[str]) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_dataset": {name: {kind: {ds: summary}}},
    "by_label": {...}, "by_since_fix": {name: {kind: {bin: summary}}}, "curve": {name:
    {kind: [[expected, observed], ...]}}, "none": [names without covariance]}`` over the
    scored rows of ``traces`` (one predictor at a time). Traces without covariance columns
    (older runs, answers without them): every predictor under ``none``."""
    out: dict[str, Any] = {
        "predictors": {},
        "by_dataset": {},
        "by_label": {},
        "by_since_fix": {},
        "curve": {},
        "none": [],
    }
    if traces.empty or any(c not in traces for c in NEEDED):
        out["none"] = list(predictors)
        return out
    for name, sub in traces.per_predictor(predictors, NEEDED):
        cov_all = sub[COV].to_numpy(float)
        if not np.isfinite(cov_all[:, 0]).any():
            out["none"].append(name)
            continue
        # the columns as arrays once, rows grouped by kind (a stable order: each kind's rows
        # keep theirs), the frame let go: each kind's rows are a slice of these, not a copy
        kind_code, kind_names = pd.factorize(sub["kind"])
        order = np.argsort(kind_code, kind="stable")
        bounds = np.searchsorted(kind_code[order], np.arange(len(kind_names) + 1))
        rows_of = {
            str(k): slice(a, b) for k, a, b in zip(kind_names, bounds[:-1], bounds[1:], strict=True)
        }
        cov_all = cov_all[order]
        err_all = _errors(sub)[order]
        codes_all = drive_codes(sub)[order]
        times = sub["t_query"].to_numpy(float)[order]
        since = sub["since_fix_s"].to_numpy(float)[order]
        text = {col: text_values(sub[col])[order] for col in ("dataset", "label")}
        del sub, order, kind_code
        for block in ("predictors", "by_dataset", "by_label", "by_since_fix", "curve"):
            out[block][name] = {}
        for k in KINDS:
            m = rows_of.get(k, slice(0, 0))
            err, cov = err_all[m], cov_all[m]
            # the kind's drives numbered in order of appearance, as drive_codes numbers them
            clusters = pd.factorize(codes_all[m])[0].astype(np.int64)
            out["predictors"][name][k] = calibration_summary(
                err, cov, clusters=clusters, times=times[m]
            )
            out["curve"][name][k] = [list(pq) for pq in calibration_curve(mahalanobis_sq(err, cov))]
            for block, col in (("by_dataset", "dataset"), ("by_label", "label")):
                code, groups = pd.factorize(text[col][m])  # in order of appearance
                out[block][name][k] = {
                    str(g): calibration_summary(err[code == i], cov[code == i], with_ci=False)
                    for i, g in enumerate(groups)
                }
            idx, names = since_fix_bin(since[m])
            out["by_since_fix"][name][k] = {
                b: calibration_summary(err[idx == i], cov[idx == i], with_ci=False)
                for i, b in enumerate(names)
                if (idx == i).any()
            }
    return out
