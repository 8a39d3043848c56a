"""The "uncertainty" table: is each predictor's reported covariance honest (results.json
``uncertainty``, :mod:`posbench.aggregation.uncertainty`), with the report's note."""

from __future__ import annotations

from typing import Any

import pandas as pd

from posbench.scoring.schema import KINDS
from posbench.tables.table import Table, as_float

#: the report's paragraph under the table
UNCERTAINTY_NOTE = (
    "Each answer's reported 2x2 covariance P (`covariance_at`, ENU, m^2) against its error e. "
    "NEES = mean e' P^-1 e, 2 when honest (above: overconfident, ellipses too small; below: "
    "underconfident), with its 95 % CI resampling drives; `cov 95 %` = share of references "
    "inside the reported 95 % ellipse (50/90/99 % in results.json); sharpness = median 95 % "
    "ellipse area; log-lik = mean log density of the reference [nats]. Verdict: `calibrated` "
    "when the 95 % coverage is within 0.95 +- max(0.02, 1.96 sqrt(0.0475 / n)) and the NEES "
    "within its chi-square 95 % interval for n queries or its CI holds 2 "
    "(metrics/calibration.py). `no uncertainty`: the predictor reports none."
)


def uncertainty_table(res: dict[str, Any], group: str | None = None) -> Table:
    """ "Uncertainty": per predictor and kind, NEES [CI], coverage of the 50/95 % ellipses,
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
                rows.append(
                    {
                        **row,
                        "nees": as_float(s["nees"]),
                        "nees_lo": as_float(ci[0]),
                        "nees_hi": as_float(ci[1]),
                        "cov50": as_float(s["coverage"]["50"]),
                        "cov95": as_float(s["coverage"]["95"]),
                        "sharpness_m2": as_float(s["sharpness_m2"]),
                        "loglik": as_float(s["loglik"]),
                        "verdict": s["verdict"] or "-",
                        "n": s["count"],
                    }
                )
    if group is None:
        for name in block.get("none", []):
            rows.append({"predictor": name, "kind": "-", "verdict": "no uncertainty", "n": 0})
    labels = {
        "nees": "NEES (2 = honest)",
        "cov50": "cov 50 %",
        "cov95": "cov 95 %",
        "sharpness_m2": "95 % area [m^2]",
        "loglik": "log-lik",
    }
    cols = [
        "predictor",
        "kind",
        *(["group"] if group is not None else []),
        "nees",
        "nees_lo",
        "nees_hi",
        "cov50",
        "cov95",
        "sharpness_m2",
        "loglik",
        "verdict",
        "n",
    ]
    frame = pd.DataFrame(rows, columns=cols)
    title = "Uncertainty" if group is None else f"Uncertainty {group.replace('_', ' ')}"
    name = "uncertainty" if group is None else f"uncertainty_{group}"
    return Table(frame, name, labels, ci={"nees": ("nees_lo", "nees_hi")}, title=title)
