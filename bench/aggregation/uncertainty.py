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
from posbench.aggregation.row_columns import RowColumns, extend_codes
from posbench.metrics.calibration import (
    calibration_curve,
    calibration_of,
    log_det,
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


def _kind_columns(traces: TraceSet, name: str) -> dict[str, Any] | None:
    """Predictor ``name``'s scored rows reduced to what the section needs, read one part of
    the traces at a time (never a frame of every row, nor its errors and covariances, beside
    them), grouped by query kind in a stable order (each kind's rows keep theirs): ``d2``
    (:func:`~posbench.metrics.calibration.mahalanobis_sq`) and ``ln_det``
    (:func:`~posbench.metrics.calibration.log_det`), ``code`` (the drive, numbered as
    :func:`~posbench.aggregation.intervals.drive_codes` numbers them), ``t_query`` [s],
    ``since_bin`` (:func:`~posbench.metrics.calibration.since_fix_bin`), ``dataset`` and
    ``label`` (indices into ``tables[col]``: its values in order of first appearance; -1
    where missing), and ``rows_of``: each kind of :data:`KINDS` -> its slice. About 34
    bytes a query. None when no row reports a covariance."""
    columns = RowColumns(
        {
            "d2": np.float64,
            "ln_det": np.float64,
            "kind": np.int8,
            "code": np.int32,
            "t_query": np.float64,
            "since_bin": np.int8,
            "dataset": np.int16,
            "label": np.int16,
        },
        traces.row_bound(name),
    )
    tables: dict[str, list[Any]] = {"dataset": [], "label": []}
    indices: dict[str, dict[Any, int]] = {"dataset": {}, "label": {}}
    pair_code: dict[tuple[object, object], int] = {}
    reported = False
    for rows in traces.pieces(name, NEEDED):
        cov = rows[COV].to_numpy(float)
        reported = reported or bool(np.isfinite(cov[:, 0]).any())
        kind = text_values(rows["kind"])
        # the part's drives numbered in order of appearance, then as across the parts so far
        local = drive_codes(rows)
        first = np.unique(local, return_index=True)[1]
        ds, dr = text_values(rows["dataset"]), text_values(rows["drive"])
        to_run = [pair_code.setdefault((ds[i], dr[i]), len(pair_code)) for i in first]
        columns.add(
            d2=mahalanobis_sq(_errors(rows), cov),
            ln_det=log_det(cov),
            kind=np.select([kind == k for k in KINDS], np.arange(len(KINDS)), -1),
            code=np.asarray(to_run, dtype=np.int32)[local],
            t_query=rows["t_query"].to_numpy(float),
            since_bin=since_fix_bin(rows["since_fix_s"].to_numpy(float))[0],
            dataset=extend_codes(ds, tables["dataset"], indices["dataset"]),
            label=extend_codes(text_values(rows["label"]), tables["label"], indices["label"]),
        )
    if not reported:
        return None
    order, slices = columns.group_order("kind", len(KINDS))
    out: dict[str, Any] = {"rows_of": dict(zip(KINDS, slices, strict=True)), "tables": tables}
    for col in ("d2", "ln_det", "code", "t_query", "since_bin", "dataset", "label"):
        out[col] = columns.take(col, order)  # one column at a time, in kind order
    return out


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
    for name in predictors:
        cols = _kind_columns(traces, name)
        if cols is None:
            out["none"].append(name)
            continue
        rows_of, tables = cols["rows_of"], cols["tables"]
        for block in ("predictors", "by_dataset", "by_label", "by_since_fix", "curve"):
            out[block][name] = {}
        for k in KINDS:
            m = rows_of[k]
            d2, ld = cols["d2"][m], cols["ln_det"][m]
            # the kind's drives numbered in order of appearance, as drive_codes numbers them
            clusters = pd.factorize(cols["code"][m])[0].astype(np.int64)
            out["predictors"][name][k] = calibration_of(
                d2, ld, clusters=clusters, times=cols["t_query"][m]
            )
            del clusters
            out["curve"][name][k] = [list(pq) for pq in calibration_curve(d2)]
            for block, col in (("by_dataset", "dataset"), ("by_label", "label")):
                code, groups = pd.factorize(cols[col][m])  # in order of appearance
                out[block][name][k] = {
                    str(tables[col][g]): calibration_of(d2[code == i], ld[code == i], with_ci=False)
                    for i, g in enumerate(groups)
                    if g >= 0  # a missing value: in no group
                }
            idx, names = cols["since_bin"][m], since_fix_bin(np.empty(0))[1]
            out["by_since_fix"][name][k] = {
                b: calibration_of(d2[idx == i], ld[idx == i], with_ci=False)
                for i, b in enumerate(names)
                if (idx == i).any()
            }
        del cols
    return out
