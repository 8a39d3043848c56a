"""How the figures read the traces: from a :class:`~posbench.scoring.trace_set.TraceSet`, one
predictor's parts one at a time (:meth:`~posbench.scoring.trace_set.TraceSet.pieces`,
each reduced to what the figure draws before the next is read) or one drive's rows, and only
the columns a figure draws, so that a figure of a long run never holds the whole traces, nor
one predictor's columns over every drive.

The figures draw what they drew from the whole frame: the same rows in the same order, the
predictors in the order they first appear among the rows drawn (:func:`first_seen`), the
most-turning drive picked as before (:func:`most_turning`)."""

from __future__ import annotations

from collections.abc import Mapping

from posbench.scoring.trace_set import TraceSet


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
