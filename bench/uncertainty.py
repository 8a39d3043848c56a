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

from posbench.intervals import drive_codes
from posbench.metrics.calibration import (
    calibration_curve,
    calibration_summary,
    mahalanobis_sq,
    since_fix_bin,
)
from posbench.tables import Table

KINDS = ("future", "now")
COV = ["cov_xx", "cov_xy", "cov_yy"]
NEEDED = ("predictor", "kind", "dataset", "drive", "label", "since_fix_s", "x", "y",
          "x_ref", "y_ref", "t_query", *COV)


def _arrays(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    err = rows[["x", "y"]].to_numpy(float) - rows[["x_ref", "y_ref"]].to_numpy(float)
    return err, rows[COV].to_numpy(float)


def uncertainty_section(traces: pd.DataFrame, keep: np.ndarray, predictors: Sequence[str]
                        ) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_dataset": {name: {kind: {ds: summary}}},
    "by_label": {...}, "by_since_fix": {name: {kind: {bin: summary}}}, "curve": {name:
    {kind: [[expected, observed], ...]}}, "none": [names without covariance]}`` over the
    rows ``keep`` of ``traces``. Traces without covariance columns (older runs, answers
    without them): every predictor under ``none``."""
    out: dict[str, Any] = {"predictors": {}, "by_dataset": {}, "by_label": {},
                           "by_since_fix": {}, "curve": {}, "none": []}
    if traces.empty or any(c not in traces for c in NEEDED):
        out["none"] = list(predictors)
        return out
    has_cov = np.isfinite(traces["cov_xx"].to_numpy(float))
    for name in predictors:
        mine = keep & (traces["predictor"] == name).to_numpy()
        if not (mine & has_cov).any():
            out["none"].append(name)
            continue
        sub = traces.loc[mine, list(NEEDED)]
        for block in ("predictors", "by_dataset", "by_label", "by_since_fix", "curve"):
            out[block][name] = {}
        for k in KINDS:
            rows = sub[(sub["kind"] == k).to_numpy()]
            err, cov = _arrays(rows)
            out["predictors"][name][k] = calibration_summary(
                err, cov, clusters=drive_codes(rows), times=rows["t_query"].to_numpy(float))
            out["curve"][name][k] = [list(pq) for pq in
                                     calibration_curve(mahalanobis_sq(err, cov))]
            for block, col in (("by_dataset", "dataset"), ("by_label", "label")):
                code, groups = pd.factorize(rows[col])  # in order of appearance
                out[block][name][k] = {
                    str(g): calibration_summary(err[code == i], cov[code == i], with_ci=False)
                    for i, g in enumerate(groups)}
            idx, names = since_fix_bin(rows["since_fix_s"].to_numpy(float))
            out["by_since_fix"][name][k] = {
                b: calibration_summary(err[idx == i], cov[idx == i], with_ci=False)
                for i, b in enumerate(names) if (idx == i).any()}
    return out


#: the report's paragraph under the table
UNCERTAINTY_NOTE = (
    "Each answer's reported 2x2 covariance P (`covariance_at`, ENU, m^2) against its error e. "
    "NEES = mean e' P^-1 e, 2 when honest (above: overconfident, ellipses too small; below: "
    "underconfident), with its 95 % CI resampling drives; `cov 95 %` = share of references "
    "inside the reported 95 % ellipse (50/90/99 % in results.json); sharpness = median 95 % "
    "ellipse area; log-lik = mean log density of the reference [nats]. Verdict: `calibrated` "
    "when the 95 % coverage is within 0.95 +- max(0.02, 1.96 sqrt(0.0475 / n)) and the NEES "
    "within its chi-square 95 % interval for n queries or its CI holds 2 "
    "(metrics/calibration.py). `no uncertainty`: the predictor reports none.")


def _num(v: Any) -> float:
    return float("nan") if v is None else float(v)


def uncertainty_table(res: dict[str, Any], group: str | None = None) -> Table:
    """"Uncertainty": per predictor and kind, NEES [CI], coverage of the 50/95 % ellipses,
    sharpness [m^2], log-likelihood, verdict, queries; one row "no uncertainty" per
    predictor without covariance. ``group``: ``"by_since_fix"`` (or another by_ block) for
    a row per bin instead (no CI there)."""
    block = res.get("uncertainty", {})
    rows = []
    src = block.get("predictors", {}) if group is None else block.get(group, {})
    for name, kinds in src.items():
        for k in KINDS:
            items = [(None, kinds[k])] if group is None else list(kinds.get(k, {}).items())
            for g, s in items:
                ci = s.get("nees_ci95") or [None, None]
                row = {"predictor": name, "kind": k}
                if group is not None:
                    row["group"] = g
                rows.append({**row, "nees": _num(s["nees"]), "nees_lo": _num(ci[0]),
                             "nees_hi": _num(ci[1]), "cov50": _num(s["coverage"]["50"]),
                             "cov95": _num(s["coverage"]["95"]),
                             "sharpness_m2": _num(s["sharpness_m2"]),
                             "loglik": _num(s["loglik"]), "verdict": s["verdict"] or "-",
                             "n": s["count"]})
    if group is None:
        for name in block.get("none", []):
            rows.append({"predictor": name, "kind": "-", "verdict": "no uncertainty", "n": 0})
    labels = {"nees": "NEES (2 = honest)", "cov50": "cov 50 %", "cov95": "cov 95 %",
              "sharpness_m2": "95 % area [m^2]", "loglik": "log-lik"}
    cols = ["predictor", "kind", *(["group"] if group is not None else []), "nees", "nees_lo",
            "nees_hi", "cov50", "cov95", "sharpness_m2", "loglik", "verdict", "n"]
    frame = pd.DataFrame(rows, columns=cols)
    title = "Uncertainty" if group is None else f"Uncertainty {group.replace('_', ' ')}"
    name = "uncertainty" if group is None else f"uncertainty_{group}"
    return Table(frame, name, labels, ci={"nees": ("nees_lo", "nees_hi")}, title=title)
