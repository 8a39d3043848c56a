"""The ``track_errors`` block of results.json: where the error points (schema 1.2).

Per predictor and kind (and per scenario label), :func:`posbench.metrics.track_errors.track_summary`
of the scored queries' along-track and cross-track errors (trace columns ``along_m``,
``cross_m``) and of the cross-track error signed toward the inside of the turn
(:func:`posbench.metrics.track_errors.inward_cross` of ``cross_m`` and ``yaw_rate_ref``).

Computed from the traces one part (drive) at a time, never holding a predictor's rows: pass
one adds each group's counts and sums and counts its values per bin; pass two keeps the values
of the bins that hold the p95s (:mod:`posbench.metrics.two_pass_quantiles`). The figures are
:func:`~posbench.metrics.track_errors.track_summary`'s: counts and p95s exactly, means to
rounding (summed per drive, then exactly over the drives: the same to the bit from parts on
disk as from a frame in memory).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.drive_passes import run_passes
from posbench.metrics.track_errors import inward_cross
from posbench.metrics.two_pass_quantiles import BinCounts
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index
from posbench.scoring.trace_set import TraceSet

NEEDED = ("kind", "label", "error_m", "along_m", "cross_m", "yaw_rate_ref")
#: the groups of each kind: every query of the kind, then each route type's
GROUPS = ("all", *LABELS)


class _Group:
    """One group's figures (a kind's queries, or its queries of one route type), added one
    part of the traces at a time."""

    def __init__(self) -> None:
        self.count = self.standstill = self.turning = 0
        self.sums: tuple[list[float], list[float], list[float]] = ([], [], [])
        self.along, self.cross = BinCounts((95,)), BinCounts((95,))

    def add(
        self, along: np.ndarray, cross: np.ndarray, inward: np.ndarray, error: np.ndarray
    ) -> None:
        """Pass one: a part's rows of the group (errors [m])."""
        ok = np.isfinite(along) & np.isfinite(cross)
        ok_i = np.isfinite(inward)
        self.count += int(ok.sum())
        self.standstill += int((np.isfinite(error) & ~ok).sum())
        self.turning += int(ok_i.sum())
        av, cv = along[ok], cross[ok]
        for sums, v in zip(self.sums, (av, cv, inward[ok_i]), strict=True):
            sums.append(float(v.sum()))
        self.along.add(np.abs(av))
        self.cross.add(np.abs(cv))

    def keep(self, along: np.ndarray, cross: np.ndarray) -> None:
        """Pass two: the same part's rows of the group."""
        ok = np.isfinite(along) & np.isfinite(cross)
        self.along.keep(np.abs(along[ok]))
        self.cross.keep(np.abs(cross[ok]))

    def summary(self) -> dict[str, float | int]:
        """:func:`~posbench.metrics.track_errors.track_summary` of the group."""
        a, c, i = (math.fsum(s) for s in self.sums)
        nan = float("nan")
        return {
            "count": self.count,
            "standstill": self.standstill,
            "along_mean_m": a / self.count if self.count else nan,
            "along_p95_abs_m": self.along.quantiles()[0],
            "cross_mean_m": c / self.count if self.count else nan,
            "cross_p95_abs_m": self.cross.quantiles()[0],
            "turning": self.turning,
            "inward_mean_m": i / self.turning if self.turning else nan,
        }


def _group_rows(rows: pd.DataFrame) -> Iterator[tuple[str, str, np.ndarray]]:
    """(kind, group, the rows' mask) of each group of :data:`GROUPS` with rows in ``rows``."""
    kind, label = category_index(rows["kind"], KINDS), category_index(rows["label"], LABELS)
    for i, k in enumerate(KINDS):
        mine = kind == i
        if not mine.any():
            continue
        yield k, "all", mine
        for j, lab in enumerate(LABELS):
            sel = mine & (label == j)
            if sel.any():
                yield k, lab, sel


class TrackFigures:
    """Predictor's track-error groups: a :class:`~posbench.aggregation.drive_passes.Family`
    of the scored rows."""

    columns: tuple[str, ...] = NEEDED
    scored: bool = True

    def __init__(self) -> None:
        self.groups = {(k, g): _Group() for k in KINDS for g in GROUPS}

    def first(self, rows: pd.DataFrame) -> None:
        cross = rows["cross_m"].to_numpy(float)
        cols = (
            rows["along_m"].to_numpy(float),
            cross,
            inward_cross(cross, rows["yaw_rate_ref"].to_numpy(float)),
            rows["error_m"].to_numpy(float),
        )
        for k, g, sel in _group_rows(rows):
            self.groups[k, g].add(*(c[sel] for c in cols))

    def between(self) -> bool:
        return any(g.count for g in self.groups.values())

    def second(self, rows: pd.DataFrame) -> None:
        along, cross = rows["along_m"].to_numpy(float), rows["cross_m"].to_numpy(float)
        for k, g, sel in _group_rows(rows):
            self.groups[k, g].keep(along[sel], cross[sel])

    def result(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """Per kind the summary, and per kind and route type."""
        groups = self.groups
        return (
            {k: groups[k, "all"].summary() for k in KINDS},
            {k: {lab: groups[k, lab].summary() for lab in LABELS} for k in KINDS},
        )


def track_available(traces: TraceSet) -> bool:
    """Whether the traces have the along/cross-track columns (answers scored before they
    existed have not)."""
    return not traces.empty and all(c in traces for c in NEEDED)


def track_section(traces: TraceSet, predictors: Sequence[str]) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_label": {name: {kind: {label: summary}}}}``
    over the scored rows (the headline figures') of ``traces``, one predictor at a time;
    empty dicts when the traces have no along/cross-track columns (answers scored before
    they existed)."""
    out: dict[str, Any] = {"predictors": {}, "by_label": {}}
    if not track_available(traces):
        return out
    for name in predictors:
        figures = TrackFigures()
        run_passes(traces, name, [figures])
        out["predictors"][name], out["by_label"][name] = figures.result()
    return out
