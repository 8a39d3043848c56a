"""How the figures read the traces: from a :class:`~posbench.scoring.trace_set.TraceSet`, one
predictor or one drive at a time and only the columns a figure draws, so that a figure of a
long run holds one predictor's few columns (or one drive's rows), never the whole traces.

The figures draw what they drew from the whole frame: the same rows in the same order, the
predictors in the order they first appear among the rows drawn (:func:`first_seen`), the
most-turning drive picked as before (:func:`most_turning`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import pandas as pd

from posbench.figures.style import warmup_mask
from posbench.scoring.trace_set import TraceSet


def past_warmup(ts: TraceSet, predictor: str, columns: Sequence[str]) -> tuple[pd.DataFrame, bool]:
    """The rows of ``predictor`` past the warm-up (every row without a ``warmup`` column),
    ``columns`` of them (those the traces have); and whether it had any warm-up row."""
    rows = ts.frame([*dict.fromkeys([*columns, "warmup"])], predictor)
    w = warmup_mask(rows)
    return (rows[~w] if w.any() else rows), bool(w.any())


def first_seen(ts: TraceSet, firsts: Mapping[str, str]) -> list[str]:
    """The predictors of ``firsts`` (predictor -> the drive of its first row drawn, in the
    order of :meth:`TraceSet.predictors`) in the order they first appear among the rows
    drawn, as ``groupby(sort=False)`` over the whole traces gives them: by that drive, then
    in run order (the order of the predictors within every drive)."""
    names = list(firsts)
    if len(set(firsts.values())) <= 1:
        return names
    rank = {d: i for i, d in enumerate(ts.drives())}
    return sorted(names, key=lambda p: rank.get(firsts[p], len(rank)))
