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

from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import Statistics, ci95_of
from posbench.metrics.streamed_summary import StreamedSummary
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index

COLUMNS = ("kind", "t_query", "error_m", "x_ref", "y_ref", "warmup")


def _warm_rows(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A drive's rows: whether each lacks a reference, whether each is a scored warm-up
    query (with a reference), and its kind's index in :data:`KINDS` (-1: another)."""
    no_ref = (rows["x_ref"].isna() | rows["y_ref"].isna()).to_numpy()
    warm = rows["warmup"].to_numpy(dtype=bool) if "warmup" in rows else np.zeros(len(rows), bool)
    return no_ref, warm & ~no_ref, category_index(rows["kind"], KINDS)


class ExcludedFigures:
    """A predictor's warm-up summaries and queries without a reference, per kind: a
    :class:`~posbench.aggregation.drive_passes.Family` of every row."""

    columns: tuple[str, ...] = COLUMNS
    scored: bool = False

    def __init__(self, stats: Statistics | None) -> None:
        self.stats = stats
        self.sums = {k: StreamedSummary(*_resampling(stats)) for k in KINDS}
        self.no_reference = dict.fromkeys(KINDS, 0)
        # a drive's warm-up is its first seconds: its queries are held for the second
        # pass, not read again
        self.held: list[tuple[str, np.ndarray, np.ndarray]] = []

    def first(self, rows: pd.DataFrame) -> None:
        no_ref, warm, kind = _warm_rows(rows)
        e, t = rows["error_m"].to_numpy(dtype=float), rows["t_query"].to_numpy(dtype=float)
        for i, k in enumerate(KINDS):
            mine = kind == i
            self.no_reference[k] += int((no_ref & mine).sum())
            mine &= warm
            self.sums[k].add(e[mine])
            self.held.append((k, e[mine], t[mine]))

    def between(self) -> bool:
        for s in self.sums.values():
            s.wanted()
        for k, e, t in self.held:
            self.sums[k].keep(e, t)
        self.held = []
        return False

    def second(self, rows: pd.DataFrame) -> None:
        raise AssertionError("the warm-up figures need no second read")

    def result(self) -> tuple[dict[str, Any], dict[str, int]]:
        """Per kind the warm-up summary (with ``ci95`` given statistics), and the count of
        queries without a reference."""
        warmup = {}
        for k, s in self.sums.items():
            summary = s.summary()
            ci = summary.pop("ci")
            if self.stats is not None:
                summary["ci95"] = ci95_of(ci)
            warmup[k] = summary
        return warmup, self.no_reference


def _resampling(stats: Statistics | None) -> tuple[int, int, float]:
    """The bootstrap's resamples, seed and level (the default's without ``stats``, whose
    intervals are then not reported)."""
    s = stats or Statistics()
    return s.resamples, s.seed, s.level
