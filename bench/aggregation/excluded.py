"""What the headline figures leave out (results.json's ``excluded``), per predictor and kind:
the warm-up queries, with their error summaries and intervals, and the queries without a
reference (beyond the truth's or the fixes' span: nothing to score against).

Computed from the traces one drive at a time (:class:`~posbench.metrics.streamed_summary.
StreamedSummary`, its second pass over the warm-up queries held from the first: a drive's
first seconds), never holding a predictor's rows: per kind the warm-up queries' summary and
interval as :func:`~posbench.aggregation.intervals.ci_entry` gives them on those rows, counts,
quantiles and intervals to the bit, mean and RMSE to rounding.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import Statistics
from posbench.metrics.streamed_summary import StreamedSummary
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index
from posbench.scoring.trace_set import TraceSet, as_trace_set

COLUMNS = ("kind", "t_query", "error_m", "x_ref", "y_ref", "warmup")


def _warm_rows(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A drive's rows: whether each lacks a reference, whether each is a scored warm-up
    query (with a reference), and its kind's index in :data:`KINDS` (-1: another)."""
    no_ref = (rows["x_ref"].isna() | rows["y_ref"].isna()).to_numpy()
    warm = rows["warmup"].to_numpy(dtype=bool) if "warmup" in rows else np.zeros(len(rows), bool)
    return no_ref, warm & ~no_ref, category_index(rows["kind"], KINDS)


def _summaries(ts: TraceSet, name: str, stats: Statistics | None) -> dict[str, Any]:
    """``excluded`` of predictor ``name``: per kind its warm-up queries' summaries, and
    its queries without a reference, counted."""
    cols = [c for c in COLUMNS if c in ts]
    sums = {k: StreamedSummary(*_resampling(stats)) for k in KINDS}
    no_reference = dict.fromkeys(KINDS, 0)
    # a drive's warm-up is its first seconds: its queries are held for pass two, not read again
    held: list[tuple[str, np.ndarray, np.ndarray]] = []
    for rows in ts.drive_pieces(name, cols, scored=False):
        no_ref, warm, kind = _warm_rows(rows)
        e, t = rows["error_m"].to_numpy(dtype=float), rows["t_query"].to_numpy(dtype=float)
        for i, k in enumerate(KINDS):
            mine = kind == i
            no_reference[k] += int((no_ref & mine).sum())
            mine &= warm
            sums[k].add(e[mine])
            held.append((k, e[mine], t[mine]))
    for s in sums.values():
        s.wanted()
    for k, e, t in held:
        sums[k].keep(e, t)
    warmup = {}
    for k, s in sums.items():
        summary = s.summary()
        ci = summary.pop("ci")
        if stats is not None:
            summary["ci95"] = {
                "mean_m": ci["mean_m"],
                "median_m": ci["median_m"],
                "p95_m": ci["p95_m"],
                "drives": ci["clusters"],
                "block_len": ci["block_len"],
            }
        warmup[k] = summary
    return {"warmup": warmup, "no_reference": no_reference}


def _resampling(stats: Statistics | None) -> tuple[int, int, float]:
    """The bootstrap's resamples, seed and level (those of the default without ``stats``:
    then no interval is reported, and none is computed beyond the cheap ones)."""
    s = stats or Statistics()
    return s.resamples, s.seed, s.level


def excluded_summary(
    traces: TraceSet | pd.DataFrame, preds: Sequence[str], stats: Statistics | None = None
) -> dict[str, Any]:
    """What the headline figures leave out, per predictor and kind: warm-up queries (with
    their error summaries, and intervals given ``stats``) and queries without a reference
    (beyond the truth's or the fixes' span: nothing to score against). One predictor's
    rows at a time, one drive at a time."""
    out: dict[str, Any] = {"warmup": {}, "no_reference": {}}
    ts = as_trace_set(traces)
    if ts.empty:
        return out
    for name in preds:
        mine = _summaries(ts, name, stats)
        out["warmup"][name] = mine["warmup"]
        out["no_reference"][name] = mine["no_reference"]
    return out
