"""A run repeated over GPS-noise and dropout seeds (``bench run --seeds``).

Every seed replays the same drives with the same predictors; only the random draws of the
simulated GPS (noise, fix times) and of the dropouts change. The first seed is the run: its
traces, figures, intervals and plots are the report's. Each seed contributes its headline
figures (:func:`seed_figures`), and :func:`seeds_section` adds their spread across seeds
(``results["seeds"]``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.metrics.accuracy import summarize
from posbench.metrics.seeds import paired_mean_difference, spread
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet, as_trace_set

#: the figures whose spread across seeds is reported
SPREAD_FIGURES = ("mean_m", "median_m", "rmse_m", "p95_m")


def seed_figures(
    traces: TraceSet | pd.DataFrame, predictors: Sequence[str], baseline: str | None, seed: int
) -> dict[str, Any]:
    """One seed's headline figures from its traces (read one predictor at a time): per
    predictor and kind the summary of the scored queries (as ``results["predictors"]``,
    without latency and intervals), the same per data set, and each predictor's paired
    difference of mean error against the baseline on the queries both answered [m]."""
    out: dict[str, Any] = {"seed": int(seed), "predictors": {}, "by_dataset": {}, "paired": {}}
    ts = as_trace_set(traces)
    if ts.empty:
        return out
    errors: dict[tuple[str, str], np.ndarray] = {}
    for name, mine in ts.per_predictor(predictors, ["dataset", "kind", "error_m"]):
        out["predictors"][name] = {}
        for k in KINDS:
            e = mine.loc[mine["kind"] == k, "error_m"].to_numpy(dtype=float)
            errors[(name, k)] = e
            out["predictors"][name][k] = summarize(e)
        for ds, g in mine.groupby("dataset", sort=True, observed=True):
            out["by_dataset"].setdefault(str(ds), {})[name] = {
                k: summarize(g.loc[g["kind"] == k, "error_m"].to_numpy()) for k in KINDS
            }
    if baseline is not None and baseline in predictors:
        for name in predictors:
            if name == baseline:
                continue
            out["paired"][name] = {}
            for k in KINDS:
                out["paired"][name][k] = paired_mean_difference(
                    errors[(baseline, k)], errors[(name, k)]
                )
    return out


def seeds_section(seeds: Sequence[int], figures: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """``results["seeds"]``: the seeds, which one the traces and every other figure come
    from (the first), each seed's figures, and per predictor, kind and figure the spread
    across seeds (:func:`posbench.metrics.seeds.spread`: mean, sd, min, max, n), also of the paired
    difference (figure ``diff_m``)."""
    out: dict[str, Any] = {
        "seeds": [int(s) for s in seeds],
        "traces_seed": int(seeds[0]),
        "runs": list(figures),
        "spread": {},
    }
    if not figures:
        return out
    for name in figures[0]["predictors"]:
        out["spread"][name] = {}
        for k in KINDS:
            # a figure a seed lacks (None) is NaN: spread leaves it out
            fig = {
                f: spread(np.array([r["predictors"][name][k].get(f) for r in figures], dtype=float))
                for f in SPREAD_FIGURES
            }
            if name in figures[0].get("paired", {}):
                fig["diff_m"] = spread(
                    np.array([r["paired"].get(name, {}).get(k) for r in figures], dtype=float)
                )
            out["spread"][name][k] = fig
    return out
