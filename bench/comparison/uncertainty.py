"""The uncertainty figures of saved runs side by side (``bench compare --uncertainty``).

Reads each run's ``uncertainty`` block of results.json (schema 1.4, built by
:mod:`posbench.aggregation.uncertainty`): per predictor that reports covariance and kind
(future, now), the mean NEES with its cluster-bootstrap 95 % CI as stored (whole run only;
the other rows have none), the coverage of the 95 % ellipse, the sharpness (median 95 % ellipse
area [m^2]), the log-likelihood of the reference [nats], the verdict and the query count.

Rows: the whole run (``all``), each data set (``dataset``), each route type over all data
sets (``route type``: results.json keeps the uncertainty by label, not by data set and
label) and each time-since-last-fix bin (``since fix``). A cell says what a run has:

- the figures, when the predictor reports covariance there;
- ``no uncertainty`` (verdict column, numbers ``-``) when the run scored it and it
  reports none (results.json ``uncertainty.none``): never a made-up figure;
- ``pre-1.4 run`` when the run has no ``uncertainty`` block at all (written before
  schema 1.4): :func:`missing_notes` says so in words;
- ``-`` when the run lacks that predictor or row.

No difference column: a NEES is best at 2, not at its smallest, and results.json keeps no
per-drive calibration figures to pair on; read the CIs and verdicts side by side.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import pandas as pd

from posbench.saved_run.run import Run
from posbench.scoring.schema import KINDS
from posbench.tables.table import Table, as_float

#: row scope -> the block of results.json ``uncertainty`` holding it
SCOPE_BLOCKS = {
    "all": "predictors",
    "dataset": "by_dataset",
    "route type": "by_label",
    "since fix": "by_since_fix",
}
#: the figures per run: frame column suffix -> header text
FIGURES = {
    "nees": "NEES",
    "cov95": "cov 95 %",
    "area": "95 % area [m^2]",
    "loglik": "log-lik",
    "verdict": "verdict",
    "n": "n",
}
NO_UNCERTAINTY = "no uncertainty"
PRE_SCHEMA = "pre-1.4 run"


def has_uncertainty(run: Run) -> bool:
    """Whether ``run``'s results.json carries the ``uncertainty`` block (schema >= 1.4)."""
    return isinstance(run.results.get("uncertainty"), Mapping)


def missing_notes(runs: Sequence[Run], labels: Sequence[str]) -> list[str]:
    """One line per run without uncertainty figures (written before schema 1.4)."""
    return [
        f"{lab} has no uncertainty figures (results.json schema "
        f"{run.results.get('schema_version', '?')}, written before schema 1.4 added "
        f"them): its cells read '{PRE_SCHEMA}'; re-run it with this posbench to compare them"
        for run, lab in zip(runs, labels, strict=True)
        if not has_uncertainty(run)
    ]


def _summaries(
    block: Mapping[str, Any], scope: str
) -> list[tuple[str, str, str, str, Mapping[str, Any]]]:
    """(dataset, group, predictor, kind, summary) of one scope of an ``uncertainty`` block."""
    src = block.get(SCOPE_BLOCKS[scope]) or {}
    out = []
    for pred, kinds in src.items():
        for k in KINDS:
            entry = (kinds or {}).get(k)
            if not entry:
                continue
            if scope == "all":
                out.append(("", "", pred, k, entry))
            else:
                for g, s in entry.items():
                    ds, group = (g, "") if scope == "dataset" else ("", g)
                    out.append((ds, group, pred, k, s))
    return out


def _figures(s: Mapping[str, Any]) -> dict[str, Any]:
    ci = s.get("nees_ci95") or [None, None]
    cov = s.get("coverage") or {}
    num = as_float
    return {
        "nees": num(s.get("nees")),
        "nees lo": num(ci[0]),
        "nees hi": num(ci[1]),
        "cov95": num(cov.get("95")),
        "area": num(s.get("sharpness_m2")),
        "loglik": num(s.get("loglik")),
        "verdict": s.get("verdict") or "-",
        "n": int(s.get("count") or 0),
    }


_EMPTY = {
    "nees": float("nan"),
    "nees lo": float("nan"),
    "nees hi": float("nan"),
    "cov95": float("nan"),
    "area": float("nan"),
    "loglik": float("nan"),
    "n": 0,
}
#: the per-run columns of the aligned frame, in order
COLUMNS = ("nees", "nees lo", "nees hi", "cov95", "area", "loglik", "verdict", "n")


def uncertainty_aligned(
    runs: Sequence[Run], labels: Sequence[str], scopes: Sequence[str]
) -> pd.DataFrame:
    """The uncertainty figures of every run, aligned: one row per (scope, dataset, group,
    predictor, kind) among ``scopes`` (keys of :data:`SCOPE_BLOCKS`), in that scope order
    and the runs' order, and, per run label ``L``, columns ``L nees``, ``L nees lo``,
    ``L nees hi`` (its 95 % CI as stored, NaN outside the whole-run rows), ``L cov95``,
    ``L area`` [m^2], ``L loglik`` [nats], ``L verdict`` (or ``no uncertainty`` /
    ``pre-1.4 run`` / ``-``, numbers NaN) and ``L n`` (queries).

    A predictor that reports covariance in no run gets one whole-run row, kind ``-``."""
    keys: dict[tuple[str, str, str, str, str], dict[str, Any]] = {}
    for scope in SCOPE_BLOCKS:
        if scope not in scopes:
            continue
        for run, lab in zip(runs, labels, strict=True):
            if has_uncertainty(run):
                for ds, group, pred, k, s in _summaries(run.results["uncertainty"], scope):
                    keys.setdefault((scope, ds, group, pred, k), {})[lab] = _figures(s)
        if scope == "all":  # predictors without covariance in every run: one row saying so
            for run in runs:
                for pred in (run.results.get("uncertainty") or {}).get("none") or []:
                    if not any(key[3] == pred for key in keys):
                        keys[("all", "", "", pred, "-")] = {}
    rows = []
    for (scope, ds, group, pred, k), figs in keys.items():
        row: dict[str, Any] = {
            "scope": scope,
            "dataset": ds,
            "group": group,
            "predictor": pred,
            "kind": k,
        }
        for run, lab in zip(runs, labels, strict=True):
            mine = figs.get(lab)
            if mine is None:
                mine = {**_EMPTY, "verdict": _status(run, pred)}
            row.update({f"{lab} {c}": v for c, v in mine.items()})
        rows.append(row)
    cols = ["scope", "dataset", "group", "predictor", "kind"]
    for lab in labels:
        cols += [f"{lab} {c}" for c in COLUMNS]
    frame = pd.DataFrame(rows, columns=cols)
    for lab in labels:
        frame[f"{lab} n"] = frame[f"{lab} n"].fillna(0).astype(int)
    return frame


def _status(run: Run, predictor: str) -> str:
    """What a run's cell says where it has no figure for ``predictor``."""
    if predictor not in run.predictors:
        return "-"
    if not has_uncertainty(run):
        return PRE_SCHEMA
    if predictor in (run.results["uncertainty"].get("none") or []):
        return NO_UNCERTAINTY
    return "-"


def uncertainty_comparison(
    runs: Sequence[Run], labels: Sequence[str], scopes: Sequence[str]
) -> tuple[Table, pd.DataFrame]:
    """The comparison as a display :class:`posbench.tables.table.Table` (per run: NEES [95 % CI],
    95 % coverage, 95 % ellipse area [m^2], log-likelihood, verdict, n) and the numeric
    frame behind it (:func:`uncertainty_aligned`, for CSV)."""
    frame = uncertainty_aligned(runs, labels, scopes)
    shown = frame.copy()
    for c in ("scope", "dataset", "group", "predictor", "kind"):
        shown[c] = shown[c].astype(str).replace("", "-")
    heads = {
        "scope": "scope",
        "dataset": "data set",
        "group": "route/since fix",
        "predictor": "predictor",
        "kind": "kind",
    }
    ci, digits = {}, {}
    for lab in labels:
        for c, h in FIGURES.items():
            heads[f"{lab} {c}"] = f"{lab} {h}"
        ci[f"{lab} nees"] = (f"{lab} nees lo", f"{lab} nees hi")
        digits[f"{lab} area"] = 4
    if (shown["group"] == "-").all():  # no route-type or since-fix rows
        shown = shown.drop(columns="group")
    title = (
        "Uncertainty [NEES 2 = honest, 95 % CI over drives where stored]; "
        "no uncertainty: the predictor reports none"
    )
    return Table(shown, "uncertainty_comparison", heads, digits=digits, ci=ci, title=title), frame
