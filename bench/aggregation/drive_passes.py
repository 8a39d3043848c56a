"""A predictor's figure families computed from its rows one drive at a time, in two passes
over the traces that every family shares (TrackEval's per-sequence step, then combine).

A family (:class:`Family`) names the columns it reads and whether it reads the scored rows or
every row; :func:`run_passes` reads the union of the families' columns one drive at a time and
hands each family its rows (:meth:`Family.first`); between the passes each family settles what
it needs of the second (:meth:`Family.between`), and only if one wants it are the drives read
again (:meth:`Family.second`). What a family holds is its own business: a few numbers per drive
and group (:mod:`posbench.aggregation.error_figures` and its siblings), never a predictor's rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import pandas as pd

from posbench.scoring.schema import SCORED_BY, scored_mask
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
    pass two for the families that want it."""
    if traces.empty or not families:
        return
    wanted = {c for f in families for c in f.columns} | set(SCORED_BY)
    cols = [c for c in traces.columns if c in wanted]

    def visit(todo: Sequence[Family], second: bool) -> None:
        for rows in traces.drive_pieces(name, cols, scored=False):
            scored = None
            for f in todo:
                if f.scored and scored is None:
                    mask = scored_mask(rows)
                    scored = rows if mask.all() else rows[mask]
                mine = scored if f.scored else rows
                assert mine is not None
                if mine.empty:
                    continue
                if second:
                    f.second(mine)
                else:
                    f.first(mine)

    visit(families, second=False)
    again = [f for f in families if f.between()]
    if again:
        visit(again, second=True)
