"""The table and the figure of ``bench compare``, from the aligned figures and paired
differences of :mod:`posbench.comparison.align`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.comparison.align import Metric, aligned
from posbench.comparison.paired import paired_difference
from posbench.saved_run.run import Run


def _cell(v: float, lo: float, hi: float, digits: int = 3) -> str:
    if not np.isfinite(v):
        return "-"
    text = f"{v:.{digits}f}"
    if np.isfinite(lo) and np.isfinite(hi):
        text += f" [{lo:.{digits}f}, {hi:.{digits}f}]"
    return text


def _delta_cell(diff: float, lo: float, hi: float, digits: int = 3) -> str:
    """``+d [lo, hi]``, with `` *`` when the interval excludes 0; ``-`` without a difference."""
    if not np.isfinite(diff):
        return "-"
    text = f"{diff:+.{digits}f}"
    if np.isfinite(lo) and np.isfinite(hi):
        text += f" [{lo:+.{digits}f}, {hi:+.{digits}f}]" + (" *" if lo > 0 or hi < 0 else "")
    return text


def comparison_table(
    runs: Sequence[Run], labels: Sequence[str], metric: Metric, scopes: Sequence[str], seed: int = 0
) -> tuple[Any, pd.DataFrame]:
    """The comparison as a display :class:`posbench.tables.table.Table` (``value [CI]`` cells, one
    column per run, then ``Δ`` columns: each later run minus the first, paired over shared
    drives, ``*`` where the CI excludes 0) and the numeric frame behind it (for CSV). The
    figure columns are text but marked as ``figures``: right-aligned in LaTeX and Markdown.

    ``scopes``: which rows, among ``all``, ``dataset``, ``route type``, ``drive``. Paired
    CIs are given for ``all`` and ``dataset`` rows; route-type and drive rows show the
    plain difference (results.json keeps no per-drive, per-route-type figures)."""
    from posbench.tables.table import Table

    frame = aligned(runs, labels, metric)
    frame = frame[frame["scope"].isin(list(scopes))].reset_index(drop=True)
    first = labels[0]
    for run, lab in zip(runs[1:], labels[1:], strict=True):
        diffs, los, his, nd = [], [], [], []
        for _, row in frame.iterrows():
            p = None
            if (
                row["scope"] in ("all", "dataset")
                and row["predictor"] in run.predictors
                and row["predictor"] in runs[0].predictors
            ):
                p = paired_difference(
                    runs[0],
                    run,
                    row["predictor"],
                    metric,
                    seed,
                    dataset=row["dataset"] if row["scope"] == "dataset" else None,
                )
            if p is None:
                d = row[lab] - row[first]
                diffs.append(d)
                los.append(math.nan)
                his.append(math.nan)
                nd.append(0)
            else:
                diffs.append(p.diff)
                los.append(p.lo)
                his.append(p.hi)
                nd.append(p.drives)
        frame[f"delta {lab}"] = diffs
        frame[f"delta {lab} lo"] = los
        frame[f"delta {lab} hi"] = his
        frame[f"delta {lab} drives"] = nd
    shown: dict[str, list[str]] = {"scope": [], "dataset": [], "group": [], "predictor": []}
    for lab in labels:
        shown[lab] = []
        shown[f"{lab} n"] = []
    for lab in labels[1:]:
        shown[f"Δ {lab}"] = []
    for _, row in frame.iterrows():
        for c in ("scope", "dataset", "group", "predictor"):
            shown[c].append(str(row[c]) or "-")
        for lab in labels:
            shown[lab].append(_cell(row[lab], row[f"{lab} lo"], row[f"{lab} hi"]))
            shown[f"{lab} n"].append(str(int(row[f"{lab} n"])))
        for lab in labels[1:]:
            shown[f"Δ {lab}"].append(
                _delta_cell(row[f"delta {lab}"], row[f"delta {lab} lo"], row[f"delta {lab} hi"])
            )
    heads = {
        "scope": "scope",
        "dataset": "data set",
        "group": "route/drive",
        "predictor": "predictor",
    }
    for lab in labels:
        heads[lab] = lab
        heads[f"{lab} n"] = "n"
    for lab in labels[1:]:
        heads[f"Δ {lab}"] = f"Δ {lab} - {first}"
    title = f"{metric} [m] [95 % CI]; Δ paired over shared drives, * CI excludes 0"
    table = pd.DataFrame(shown)
    if (table["group"] == "-").all():  # only whole-run and data-set rows: no route or drive
        table = table.drop(columns="group")
    figures = [*labels, *(f"{lab} n" for lab in labels), *(f"Δ {lab}" for lab in labels[1:])]
    return Table(table, "comparison", heads, title=title, figures=figures), frame


def comparison_figure(runs: Sequence[Run], labels: Sequence[str], metric: Metric) -> Any:
    """One bar group per predictor (the whole-run figure, whatever rows the table shows),
    one bar per run, 95 % CI whiskers where the runs have them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frame = aligned(runs, labels, metric)
    frame = frame[frame["scope"] == "all"]
    preds = list(frame["predictor"])
    fig, ax = plt.subplots(figsize=(max(6.0, 1.2 * len(preds) * max(1, len(labels)) / 2 + 2), 4.5))
    width = 0.8 / max(1, len(labels))
    x = np.arange(len(preds))
    for i, lab in enumerate(labels):
        v = frame[lab].to_numpy(dtype=float)
        lo = frame[f"{lab} lo"].to_numpy(dtype=float)
        hi = frame[f"{lab} hi"].to_numpy(dtype=float)
        # a percentile interval need not hold its point value (a skewed median): clip at 0
        err = np.vstack(
            [
                np.where(np.isfinite(lo), np.maximum(v - lo, 0.0), 0.0),
                np.where(np.isfinite(hi), np.maximum(hi - v, 0.0), 0.0),
            ]
        )
        ax.bar(
            x + (i - (len(labels) - 1) / 2) * width,
            np.nan_to_num(v),
            width,
            yerr=err,
            capsize=3,
            label=lab,
        )
    ax.set_xticks(x, preds, rotation=30, ha="right")
    ax.set_ylabel(f"{metric} [m]")
    ax.set_title(f"{metric} per predictor (whiskers: 95 % cluster-bootstrap CI)")
    ax.legend(fontsize="small")
    fig.tight_layout()
    return fig
