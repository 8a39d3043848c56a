"""Saved runs side by side: one figure of every run aligned by predictor, data set, route
type (label) and drive (:func:`aligned`), the figure named (:class:`Metric`), short labels
for the runs, and the configuration items on which they disagree
(:func:`config_differences`).

Everything here reads :class:`posbench.saved_run.run.Run` objects and returns numeric frames
or plain records; :mod:`posbench.comparison.views` renders them. A figure missing in one run
is NaN there, never dropped. The paired difference of two runs is
:mod:`posbench.comparison.paired`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from posbench.errors import UsageError
from posbench.saved_run.run import Run
from posbench.scoring.schema import KINDS

STATS = ("mean_m", "median_m", "rmse_m", "p95_m", "max_m")
#: config keys that make two runs' figures incomparable when they differ
CONFIG_KEYS = (
    "horizon_s",
    "now_step_s",
    "gps_profile",
    "gps_latency_s",
    "intervals",
    "dropouts",
    "seed",
    "seeds",
    "exclude_poor_truth",
    "use_tuned",
    "gate",
)


@dataclass(frozen=True)
class Metric:
    """A figure of a saved run: ``kind`` (future, now) and ``stat`` (mean_m, median_m, ...)."""

    kind: str
    stat: str

    @classmethod
    def parse(cls, text: str, option: str = "--metric") -> Metric:
        """``future.mean_m`` -> Metric; a :class:`UsageError` naming the choices otherwise."""
        kind, _, stat = text.strip().partition(".")
        if kind not in KINDS or stat not in STATS:
            raise UsageError(
                f"{option}: {text!r} is not a metric; use KIND.STAT with KIND one of "
                f"{', '.join(KINDS)} and STAT one of {', '.join(STATS)} "
                f"(e.g. future.mean_m)"
            )
        return cls(kind, stat)

    def __str__(self) -> str:
        return f"{self.kind}.{self.stat}"


# ------------------------------------------------------------------ run labels and config
def run_labels(runs: Sequence[Run]) -> list[str]:
    """Short unique names for runs: their folder names, with parents added until unique."""
    paths = [
        Path(r.folder).resolve() if r.folder is not None else Path(f"run{i}")
        for i, r in enumerate(runs)
    ]
    depth = 1
    while True:
        labels = [Path(*p.parts[-depth:]).as_posix() for p in paths]
        if len(set(labels)) == len(labels) or depth >= max(len(p.parts) for p in paths):
            break
        depth += 1
    seen: dict[str, int] = {}
    out = []
    for lab in labels:  # the same folder given twice
        seen[lab] = seen.get(lab, 0) + 1
        out.append(lab if seen[lab] == 1 else f"{lab} ({seen[lab]})")
    return out


def _data_hashes(run: Run) -> dict[str, str]:
    return {str(d.get("path", "")): str(d.get("sha256", "")) for d in run.results.get("data") or []}


def _data_text(hashes: Mapping[str, str]) -> str:
    """A run's data as ``file:hash`` pairs (hash cut to 8 characters), by path; ``synthetic``
    when it has none."""
    return ", ".join(f"{Path(p).name}:{s[:8]}" for p, s in sorted(hashes.items())) or "synthetic"


def config_differences(runs: Sequence[Run], labels: Sequence[str]) -> list[str]:
    """One line per configuration item on which the runs disagree (empty: comparable).

    Checked: :data:`CONFIG_KEYS`, per-predictor options of predictors the runs share, and
    the data (paths and content hashes)."""
    lines = []
    configs = [r.config for r in runs]
    for key in CONFIG_KEYS:
        values = [c.get(key) for c in configs]
        if any(v != values[0] for v in values[1:]):
            lines.append(
                f"{key}: "
                + ", ".join(f"{v!r} ({lab})" for v, lab in zip(values, labels, strict=True))
            )
    shared = set.intersection(*(set(r.predictors) for r in runs)) if runs else set()
    for name in sorted(shared):
        opts = [c.get("predictor_options", {}).get(name, {}) for c in configs]
        if any(o != opts[0] for o in opts[1:]):
            lines.append(
                f"options of {name}: "
                + ", ".join(f"{o!r} ({lab})" for o, lab in zip(opts, labels, strict=True))
            )
    hashes = [_data_hashes(r) for r in runs]
    if any(h != hashes[0] for h in hashes[1:]):
        lines.append(
            "data: "
            + ", ".join(f"{_data_text(h)} ({lab})" for h, lab in zip(hashes, labels, strict=True))
        )
    return lines


# ------------------------------------------------------------------ aligned figures
def _ci(summary: Mapping[str, Any], stat: str) -> tuple[float, float]:
    ci = (summary.get("ci95") or {}).get(stat)
    if not ci or ci[0] is None or ci[1] is None:
        return math.nan, math.nan
    return float(ci[0]), float(ci[1])


def _value(summary: Mapping[str, Any] | None, stat: str) -> tuple[float, float, float, int]:
    if not summary:
        return math.nan, math.nan, math.nan, 0
    v = summary.get(stat)
    lo, hi = _ci(summary, stat)
    return (math.nan if v is None else float(v)), lo, hi, int(summary.get("count") or 0)


def _scoped_summaries(run: Run, kind: str) -> list[tuple[str, str, str, str, Mapping[str, Any]]]:
    """(scope, dataset, group, predictor, summary) for every figure of ``run``: the run as a
    whole, each data set, each route type of each data set and each drive."""
    res = run.results
    out = []
    for p, s in res["predictors"].items():
        out.append(("all", "", "", p, s.get(kind)))
    for ds, preds in res.get("by_dataset", {}).items():
        for p, s in preds.items():
            out.append(("dataset", ds, "", p, s.get(kind)))
    for ds, preds in res.get("by_label", {}).items():
        for p, kinds in preds.items():
            for label, s in (kinds.get(kind) or {}).items():
                out.append(("route type", ds, label, p, s))
    for d in res.get("drives", []):
        if d.get("skipped"):
            continue
        for p, s in (d.get("predictors") or {}).items():
            out.append(("drive", d["dataset"], d["name"], p, s.get(kind)))
    return out


def aligned(runs: Sequence[Run], labels: Sequence[str], metric: Metric) -> pd.DataFrame:
    """The ``metric`` of every run, aligned: one row per (scope, dataset, group, predictor)
    and, per run label ``L``, columns ``L`` (value [m]), ``L lo``, ``L hi`` (95 % CI, NaN
    when the run has none) and ``L n`` (queries). Rows keep the first run's order; rows
    only some runs have come after, NaN in the others."""
    keys: dict[tuple[str, str, str, str], dict[str, Any]] = {}
    for run, lab in zip(runs, labels, strict=True):
        for scope, ds, group, pred, summary in _scoped_summaries(run, metric.kind):
            v, lo, hi, n = _value(summary, metric.stat)
            row = keys.setdefault((scope, ds, group, pred), {})
            row.update({lab: v, f"{lab} lo": lo, f"{lab} hi": hi, f"{lab} n": n})
    cols = ["scope", "dataset", "group", "predictor"]
    for lab in labels:
        cols += [lab, f"{lab} lo", f"{lab} hi", f"{lab} n"]
    rows = [
        {"scope": k[0], "dataset": k[1], "group": k[2], "predictor": k[3], **v}
        for k, v in keys.items()
    ]
    frame = pd.DataFrame(rows, columns=cols)
    for lab in labels:
        frame[f"{lab} n"] = frame[f"{lab} n"].fillna(0).astype(int)
    order = {"all": 0, "dataset": 1, "route type": 2, "drive": 3}
    frame["_o"] = frame["scope"].map(order)
    return frame.sort_values(["_o"], kind="stable").drop(columns="_o").reset_index(drop=True)
