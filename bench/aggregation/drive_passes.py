"""A predictor's figure families computed from its rows one drive at a time, in two passes
over the traces that every family shares (TrackEval's per-sequence step, then combine).

A family (:class:`Family`) names the columns it reads and whether it reads the scored rows or
every row; :func:`run_passes` reads, one drive at a time, the union of the columns of the
families of scored rows (the rows chosen as they are read), then that of the families of every
row, and hands each family its rows (:meth:`Family.first`); between the passes each family
settles what it needs of the second (:meth:`Family.between`), and only if one wants it are the
drives read again (:meth:`Family.second`). What a family holds is its own business: a few
numbers per drive and group (:mod:`posbench.aggregation.error_figures` and its siblings),
never a predictor's rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import pandas as pd

from posbench.scoring.trace_set import TraceSet


class Family(Protocol):
    """One figure family's steps over a predictor's rows."""

    #: the trace columns it reads
    columns: tuple[str, ...]
    #: True: the scored rows (:func:`~posbench.scoring.schema.scored_mask`); False: every row
    scored: bool

    def first(self, rows: pd.DataFrame) -> None:
        """Pass one: one drive's rows (in their order)."""

    def between(self) -> bool:
        """After pass one: what pass two must keep; whether the family needs pass two."""
        ...

    def second(self, rows: pd.DataFrame) -> None:
        """Pass two: the same drive's rows."""


def run_passes(traces: TraceSet, name: str, families: Sequence[Family]) -> None:
    """Predictor ``name``'s rows through ``families``, one drive at a time: pass one, then
    pass two for the families that want it. The families of scored rows share one read of
    their columns, the rows chosen as they are read (never a drive's every row beside its
    scored copy); those of every row share another, of their columns only."""
    if traces.empty or not families:
        return
    for scored in (True, False):
        group = [f for f in families if f.scored is scored]
        if not group:
            continue
        wanted = {c for f in group for c in f.columns}
        cols = [c for c in traces.columns if c in wanted]
        _visit(traces, name, cols, scored, group, second=False)
        again = [f for f in group if f.between()]
        if again:
            _visit(traces, name, cols, scored, again, second=True)


def _visit(
    traces: TraceSet,
    name: str,
    cols: list[str],
    scored: bool,
    families: Sequence[Family],
    second: bool,
) -> None:
    """One pass of ``families`` over predictor ``name``'s rows (its scored rows only, given
    ``scored``), ``cols`` of them, one drive at a time."""
    for rows in traces.drive_pieces(name, cols, scored=scored):
        if rows.empty:
            continue
        for f in families:
            if second:
                f.second(rows)
            else:
                f.first(rows)
