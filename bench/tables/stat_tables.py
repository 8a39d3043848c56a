"""The tables of the statistics: each predictor against the baseline (overall, per data set,
per route type) and the spread of a run repeated over seeds. Numeric
:class:`~posbench.tables.table.Table` s like those of :mod:`posbench.tables.run_tables`,
rendered by the same code."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import pandas as pd

from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.tables.breakdown_tables import LABEL_TITLES
from posbench.tables.run_tables import TRAINED_MARK, ci_map, put_figure, trained_in_run
from posbench.tables.table import Table, as_float

#: the marker of a paired difference whose 95 % interval excludes 0
CONCLUSIVE = "*"


def _trained_in(res: Mapping[str, Any], dataset: str | None) -> set[str]:
    """Learned predictors trained on some drive of the run (of ``dataset``, if given)."""
    names = (
        {d["name"] for d in res.get("drives", []) if d["dataset"] == dataset}
        if dataset is not None
        else None
    )
    return {p for p, drives in trained_in_run(res).items() if names is None or names & set(drives)}


def paired_table(
    res: Mapping[str, Any], dataset: str | None = None, held_out: bool = False
) -> Table:
    """Each predictor against the baseline (``results["paired"]``), overall or in one data
    set: difference of mean error [m] (predictor - baseline, queries both answered) with its
    95 % interval, ``*`` where the interval excludes 0, and the drives it wins. A learned
    predictor trained on some of the drives compared is marked ``*`` after its name;
    ``held_out``: over the drives no predictor trained or tuned on
    (``results["paired"]["held_out"]``)."""
    paired = res.get("paired") or {}
    if held_out:
        paired = {**(paired.get("held_out") or {}), "baseline": paired.get("baseline")}
    src = (
        paired.get("overall") if dataset is None else paired.get("by_dataset", {}).get(dataset)
    ) or {}
    trained = set() if held_out else _trained_in(res, dataset)
    rows = []
    for name, kinds in src.items():
        row: dict[str, Any] = {"predictor": name + (TRAINED_MARK if name in trained else "")}
        for k in KINDS:
            e = kinds.get(k) or {}
            ci = e.get("ci95") or [None, None]
            row.update(
                {
                    f"{k}_diff": as_float(e.get("diff_m")),
                    f"{k}_diff_lo": as_float(ci[0]),
                    f"{k}_diff_hi": as_float(ci[1]),
                    f"{k}_mark": CONCLUSIVE if e.get("conclusive") else "",
                    f"{k}_wins": f"{e.get('wins', 0)}/{e.get('drives', 0)}",
                    f"{k}_wins_n": e.get("wins", 0),
                    f"{k}_drives": e.get("drives", 0),
                    f"{k}_queries": e.get("queries", 0),
                }
            )
        rows.append(row)
    base = paired.get("baseline")
    labels = {f"{k}_diff": f"{k} Δ mean vs {base} [m]" for k in KINDS}
    labels.update({f"{k}_wins": "drives won" for k in KINDS})
    labels.update({f"{k}_queries": "queries" for k in KINDS})
    cols = ["predictor"] + [
        c
        for k in KINDS
        for c in (
            f"{k}_diff",
            f"{k}_diff_lo",
            f"{k}_diff_hi",
            f"{k}_mark",
            f"{k}_wins",
            f"{k}_wins_n",
            f"{k}_drives",
            f"{k}_queries",
        )
    ]
    stem = "paired" + ("" if dataset is None else f"-{dataset}") + ("-held-out" if held_out else "")
    return Table(
        pd.DataFrame(rows, columns=cols),
        stem,
        labels,
        ci=ci_map([f"{k}_diff" for k in KINDS]),
        marks={f"{k}_diff": f"{k}_mark" for k in KINDS},
        hidden=[c for k in KINDS for c in (f"{k}_wins_n", f"{k}_drives")],
    )


def paired_label_table(res: Mapping[str, Any], dataset: str, kind: str = "future") -> Table:
    """Route type x predictor: difference of mean error against the baseline [cm] with its
    95 % interval, ``*`` where it excludes 0, (queries both answered)."""
    by_label = (res.get("paired") or {}).get("by_label", {}).get(dataset, {})
    preds = list(by_label)
    rows = []
    for lab in LABELS:
        row: dict[str, Any] = {"route type": LABEL_TITLES[lab]}
        for p in preds:
            e = by_label[p].get(kind, {}).get(lab) or {}
            ci = e.get("ci95") or [None, None]
            row.update(
                {
                    f"{p} [cm]": 100 * as_float(e.get("diff_m")),
                    f"{p} [cm]_lo": 100 * as_float(ci[0]),
                    f"{p} [cm]_hi": 100 * as_float(ci[1]),
                    f"{p} mark": CONCLUSIVE if e.get("conclusive") else "",
                    f"{p} n": int(e.get("queries", 0)),
                }
            )
        rows.append(row)
    cols = ["route type"] + [
        c
        for p in preds
        for c in (f"{p} [cm]", f"{p} [cm]_lo", f"{p} [cm]_hi", f"{p} mark", f"{p} n")
    ]
    base = (res.get("paired") or {}).get("baseline")
    return Table(
        pd.DataFrame(rows, columns=cols),
        f"paired-route-type-{dataset}-{kind}",
        {f"{p} [cm]": f"{p} Δ vs {base} [cm] (n)" for p in preds},
        {f"{p} [cm]": 1 for p in preds},
        {f"{p} [cm]": f"{p} n" for p in preds},
        ci=ci_map([f"{p} [cm]" for p in preds]),
        marks={f"{p} [cm]": f"{p} mark" for p in preds},
    )


def block_lengths(summaries: Iterable[Mapping[str, Any]]) -> list[int]:
    """The block lengths [queries] of the summaries whose interval came from the block
    bootstrap of a single drive (sorted, distinct)."""
    return sorted(
        {
            int(s["ci95"]["block_len"])
            for s in summaries
            if (s or {}).get("ci95") and s["ci95"].get("block_len")
        }
    )


def seeds_table(res: Mapping[str, Any]) -> Table:
    """Per predictor and kind: the mean error [m] of the first seed with its 95 % interval,
    beside its mean, sd, min and max across the seeds (``results["seeds"]``)."""
    seeds = res["seeds"]
    first = seeds["traces_seed"]
    rows = []
    for name, kinds in seeds["spread"].items():
        row: dict[str, Any] = {"predictor": name}
        for k in KINDS:
            put_figure(row, f"{k}_mean", res["predictors"][name][k], "mean_m")
            sp = kinds[k]["mean_m"]
            row.update(
                {
                    f"{k}_seeds_mean": as_float(sp["mean"]),
                    f"{k}_sd": as_float(sp["sd"]),
                    f"{k}_min": as_float(sp["min"]),
                    f"{k}_max": as_float(sp["max"]),
                }
            )
            d = kinds[k].get("diff_m")
            row[f"{k}_diff_sd"] = as_float(d["sd"]) if d else float("nan")
        rows.append(row)
    labels = {}
    for k in KINDS:
        labels.update(
            {
                f"{k}_mean": f"{k} mean [m], seed {first}",
                f"{k}_seeds_mean": f"{k} mean over seeds",
                f"{k}_sd": "sd",
                f"{k}_min": "min",
                f"{k}_max": "max",
                f"{k}_diff_sd": f"sd of Δ vs {res.get('paired', {}).get('baseline')}",
            }
        )
    cols = ["predictor"] + [
        c
        for k in KINDS
        for c in (
            f"{k}_mean",
            f"{k}_mean_lo",
            f"{k}_mean_hi",
            f"{k}_seeds_mean",
            f"{k}_sd",
            f"{k}_min",
            f"{k}_max",
            f"{k}_diff_sd",
        )
    ]
    if not (res.get("paired") or {}).get("baseline"):
        cols = [c for c in cols if not c.endswith("_diff_sd")]
    spread_cols = ("_seeds_mean", "_sd", "_min", "_max")
    return Table(
        pd.DataFrame(rows, columns=cols),
        "seeds",
        labels,
        {c: 4 for c in cols if c.endswith(spread_cols)},
        ci=ci_map([f"{k}_mean" for k in KINDS]),
    )
