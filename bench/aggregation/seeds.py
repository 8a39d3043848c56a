"""A run repeated over GPS-noise and dropout seeds (``bench run --seeds``).

Every seed replays the same drives with the same predictors; only the random draws of the
simulated GPS (noise, fix times) and of the dropouts change. The first seed is the run: its
traces, figures, intervals and plots are the report's. Each seed contributes its headline
figures (:func:`seed_figures`), and :func:`seeds_section` adds their spread across seeds
(``results["seeds"]``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from itertools import zip_longest
from typing import Any

import numpy as np
import pandas as pd

from posbench.metrics.seeds import spread
from posbench.metrics.streamed_summary import StreamedSummary
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index, text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

#: the figures whose spread across seeds is reported
SPREAD_FIGURES = ("mean_m", "median_m", "rmse_m", "p95_m")


def seed_figures(
    traces: TraceSet | pd.DataFrame, predictors: Sequence[str], baseline: str | None, seed: int
) -> dict[str, Any]:
    """One seed's headline figures from its traces, read one predictor and one drive at a
    time: per predictor and kind the summary of the scored queries (as
    ``results["predictors"]``, without latency and intervals), the same per data set, and
    each predictor's paired difference of mean error against the baseline on the queries
    both answered [m] (:func:`paired_difference`). Counts, medians, p95s and maxima as on
    the rows joined; means to rounding (summed per drive)."""
    out: dict[str, Any] = {"seed": int(seed), "predictors": {}, "by_dataset": {}, "paired": {}}
    ts = as_trace_set(traces)
    if ts.empty:
        return out
    for name in predictors:
        sums = _summaries(ts, name)
        none = StreamedSummary(intervals="none")
        out["predictors"][name] = {k: sums.get((None, k), none).summary() for k in KINDS}
        for ds in sorted({key for key, _ in sums if key is not None}):
            out["by_dataset"].setdefault(ds, {})[name] = {k: sums[(ds, k)].summary() for k in KINDS}
    if baseline is not None and baseline in predictors:
        for name in predictors:
            if name != baseline:
                out["paired"][name] = paired_difference(ts, baseline, name)
    return out


def _summaries(ts: TraceSet, name: str) -> dict[tuple[str | None, str], StreamedSummary]:
    """Predictor ``name``'s scored errors per group of :func:`_slices`, summed one drive at
    a time, twice (no interval)."""
    sums: dict[tuple[str | None, str], StreamedSummary] = {}
    for rows in ts.drive_pieces(name, ["dataset", "kind", "error_m"]):
        for key, e in _slices(rows):
            sums.setdefault(key, StreamedSummary(intervals="none")).add(e)
    for summary in sums.values():
        summary.wanted()
    for rows in ts.drive_pieces(name, ["dataset", "kind", "error_m"]):
        for key, e in _slices(rows):
            sums[key].keep(e)
    return sums


def _slices(rows: pd.DataFrame) -> Iterator[tuple[tuple[str | None, str], np.ndarray]]:
    """One drive's scored rows cut into the seed figures' groups: ((None: every data set, or
    the data set; kind), errors [m])."""
    kind = category_index(rows["kind"], KINDS)
    e = rows["error_m"].to_numpy(dtype=float)
    datasets = text_values(rows["dataset"], as_str=True)
    for i, k in enumerate(KINDS):
        mine = kind == i
        yield (None, k), e[mine]
        for ds in dict.fromkeys(datasets.tolist()):
            yield (str(ds), k), e[mine & (datasets == ds)]


def paired_difference(ts: TraceSet, baseline: str, name: str) -> dict[str, float]:
    """Per kind, predictor ``name``'s mean error minus ``baseline``'s over the scored queries
    both answered (finite in both) [m], the two read drive by drive side by side (the same
    queries in the same order); NaN per kind where their drives or queries differ, or none
    was answered by both (:func:`~posbench.metrics.seeds.paired_mean_difference` on the rows
    joined, to rounding)."""
    cols = ["kind", "error_m"]
    count = dict.fromkeys(KINDS, 0)
    base_sums: dict[str, list[float]] = {k: [] for k in KINDS}  # per drive, in order
    name_sums: dict[str, list[float]] = {k: [] for k in KINDS}
    differ = dict.fromkeys(KINDS, False)
    pairs = zip_longest(ts.drive_pieces(baseline, cols), ts.drive_pieces(name, cols))
    for base, mine in pairs:
        if base is None or mine is None or base["drive"].iloc[0] != mine["drive"].iloc[0]:
            return dict.fromkeys(KINDS, float("nan"))
        kb, km = category_index(base["kind"], KINDS), category_index(mine["kind"], KINDS)
        eb, em = base["error_m"].to_numpy(dtype=float), mine["error_m"].to_numpy(dtype=float)
        for i, k in enumerate(KINDS):
            a, b = eb[kb == i], em[km == i]
            if a.size != b.size:
                differ[k] = True
                continue
            both = np.isfinite(a) & np.isfinite(b)
            count[k] += int(both.sum())
            base_sums[k].append(float(a[both].sum()))
            name_sums[k].append(float(b[both].sum()))
    out = {}
    for k in KINDS:
        n = count[k]
        ok = n > 0 and not differ[k]
        diff = math.fsum(name_sums[k]) / n - math.fsum(base_sums[k]) / n if ok else math.nan
        out[k] = diff
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
