"""What every predictor's figures need, settled before any is computed (step one of
combining a run: :mod:`posbench.aggregation.predictor_figures`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from posbench.aggregation.intervals import Statistics
from posbench.scoring.records import DriveRun
from posbench.scoring.trace_set import TraceSet


@dataclass(frozen=True)
class Combining:
    """What every predictor's figures need, settled before any is computed."""

    ts: TraceSet
    runs: Sequence[DriveRun]
    stats: Statistics
    datasets: list[str]
    with_outages: bool
    trained_on: set[str]
    held_ds: list[str]
    held_all: bool
    #: whether the predictors are checked against cv (:mod:`posbench.aggregation.sanity`)
    sanity: bool
