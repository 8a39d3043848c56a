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


def _kind_columns(traces: TraceSet, name: str) -> dict[str, Any] | None:
    """Predictor ``name``'s scored rows as arrays, read one part of the traces at a time
    (never a frame of every row beside them), grouped by query kind in a stable order (each
    kind's rows keep theirs): ``err`` (N, 2) [m], ``cov`` (N, 3) [m^2], ``code`` (the drive,
    numbered as :func:`~posbench.aggregation.intervals.drive_codes` numbers them),
    ``t_query`` and ``since_fix_s`` [s], ``dataset`` and ``label`` (text), and ``rows_of``:
    each kind of :data:`KINDS` -> its slice. None when no row reports a covariance."""
    pieces: dict[str, list[np.ndarray]] = {
        c: [] for c in ("err", "cov", "kind", "code", "t_query", "since_fix_s", "dataset", "label")
    }
    pair_code: dict[tuple[object, object], int] = {}
    for rows in traces.pieces(name, NEEDED):
        pieces["err"].append(_errors(rows))
        pieces["cov"].append(rows[COV].to_numpy(float))
        kind = text_values(rows["kind"])
        pieces["kind"].append(
            np.select([kind == k for k in KINDS], np.arange(len(KINDS)), -1).astype(np.int8)
        )
        # the part's drives numbered in order of appearance, then as across the parts so far
        local = drive_codes(rows)
        first = np.unique(local, return_index=True)[1]
        ds, dr = text_values(rows["dataset"]), text_values(rows["drive"])
        to_run = [pair_code.setdefault((ds[i], dr[i]), len(pair_code)) for i in first]
        pieces["code"].append(np.asarray(to_run, dtype=np.int64)[local])
        for col in ("t_query", "since_fix_s"):
            pieces[col].append(rows[col].to_numpy(float))
        pieces["dataset"].append(ds)
        pieces["label"].append(text_values(rows["label"]))
    if not pieces["cov"] or not any(np.isfinite(c[:, 0]).any() for c in pieces["cov"]):
        return None
    kind = np.concatenate(pieces.pop("kind"))
    order = np.argsort(kind, kind="stable")
    bounds = np.searchsorted(kind[order], np.arange(len(KINDS) + 1))
    out: dict[str, Any] = {
        "rows_of": {k: slice(int(bounds[i]), int(bounds[i + 1])) for i, k in enumerate(KINDS)}
    }
    del kind
    for col in list(pieces):  # one column at a time: joined, put in kind order, parts let go
        out[col] = np.concatenate(pieces.pop(col))[order]
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
        err_all, cov_all, codes_all = cols["err"], cols["cov"], cols["code"]
        times, since = cols["t_query"], cols["since_fix_s"]
        text = {col: cols[col] for col in ("dataset", "label")}
        rows_of = cols["rows_of"]
        del cols
        for block in ("predictors", "by_dataset", "by_label", "by_since_fix", "curve"):
            out[block][name] = {}
        for k in KINDS:
            m = rows_of[k]
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
