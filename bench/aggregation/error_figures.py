"""A predictor's figures of the error column, one drive at a time: the headline entry, by
speed, by data set and route type, held out, per drive, and the outage figures.

Each figure is a :class:`~posbench.metrics.streamed_summary.StreamedSummary` of a group of
queries (a kind's, of one route type, speed bin or time since the last fix) over a set of
drives (every drive, one data set's, the held-out ones). Pass one
(:mod:`posbench.aggregation.drive_passes`) hands over the predictor's scored rows one drive
at a time, whose errors go to the groups the drive belongs to (and make the drive's own
figures, and its outages'); pass two keeps the few errors that the quantiles and their
intervals read. Nothing the size of a predictor's
rows is held: per drive and group a few numbers and bin counts. The figures are those of the
groups' rows taken whole (:func:`~posbench.metrics.accuracy.summarize` and
:func:`~posbench.aggregation.intervals.ci_entry`): counts, quantiles, maxima and intervals to
the bit, means and RMSE summed per drive and then exactly (to rounding).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.combining import Combining
from posbench.aggregation.drive_passes import run_passes
from posbench.aggregation.intervals import Statistics, ci95_of, one_drive_cis, outage_cis_of
from posbench.metrics.accuracy import speed_bin_index, speed_bin_order, summarize
from posbench.metrics.outages import (
    SINCE_FIX_CHECKPOINTS_S,
    SINCE_FIX_TOLERANCE_S,
    outage_figures_of,
    per_outage,
)
from posbench.metrics.streamed_summary import StreamedSummary
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index

COLUMNS = (
    "dataset",
    "drive",
    "kind",
    "t_query",
    "error_m",
    "label",
    "speed_mps",
    "since_fix_s",
    "outage",
)
SPEEDS = (*speed_bin_order(), "unknown")
SINCE = tuple(f"{c:g}s" for c in SINCE_FIX_CHECKPOINTS_S)
#: a group: (drives: "all" | ("ds", name) | ("held", name) | "held_all", kind, family, index)
Key = tuple[Any, str, str, int]


def _entry(summary: dict[str, Any]) -> dict[str, Any]:
    """A :class:`StreamedSummary`'s summary as results.json has it: its interval as
    ``ci95``."""
    out = dict(summary)
    out["ci95"] = ci95_of(out.pop("ci"))
    return out


class ErrorFigures:
    """Every group of one predictor's error figures, and the drives' own figures: a
    :class:`~posbench.aggregation.drive_passes.Family` of the scored rows."""

    columns: tuple[str, ...] = COLUMNS
    scored: bool = True

    def __init__(self, c: Combining, name: str) -> None:
        self.c, self.name = c, name
        self.sums: dict[Key, StreamedSummary] = {}
        #: with one data set, its drives are every drive: its groups over all its queries
        #: are those over every drive's (summed once, given twice)
        self.same: dict[Key, Key] = {}
        if len(c.datasets) == 1:
            one = ("ds", c.datasets[0])
            self.same = {(one, k, "all", 0): ("all", k, "all", 0) for k in KINDS}
        drive_sets: list[Any] = ["all", *(("ds", ds) for ds in c.datasets)]
        drive_sets += [("held", ds) for ds in c.held_ds]
        if c.held_all:
            drive_sets.append("held_all")
        for sets in drive_sets:
            for k in KINDS:
                self._new((sets, k, "all", 0))
                if sets != "all" and sets != "held_all":
                    for j in range(len(LABELS)):
                        self._new((sets, k, "label", j))
        for k in KINDS:
            for j in range(len(SPEEDS)):
                self._new(("all", k, "speed", j))
        for j in range(len(SINCE)):
            self._new(("all", "now", "since", j))
        self._done: dict[Key, dict[str, Any]] | None = None
        self.per_drive: dict[tuple[str, str], dict[str, Any]] = {}
        self.outages: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        self.drives = 0

    def _new(self, key: Key) -> None:
        if key in self.same:
            return
        s = self.c.stats
        self.sums[key] = StreamedSummary(s.resamples, s.seed, s.level)

    def slices(self, rows: pd.DataFrame) -> Iterator[tuple[Key, np.ndarray, np.ndarray]]:
        """One drive's rows cut into the groups they count in: (group, errors [m], query
        times [s]), in the same order at every pass."""
        c = self.c
        ds, drive = str(rows["dataset"].iloc[0]), str(rows["drive"].iloc[0])
        held = drive not in c.trained_on
        sets: list[Any] = ["all", ("ds", ds)]
        if held and ds in c.held_ds:
            sets.append(("held", ds))
        if held and c.held_all:
            sets.append("held_all")
        kind = category_index(rows["kind"], KINDS)
        label = category_index(rows["label"], LABELS)
        speed = speed_bin_index(rows["speed_mps"].to_numpy(dtype=float))
        since = rows["since_fix_s"].to_numpy(dtype=float)
        e, t = rows["error_m"].to_numpy(dtype=float), rows["t_query"].to_numpy(dtype=float)
        for i, k in enumerate(KINDS):
            mine = kind == i
            if not mine.any():
                continue
            ek, tk = e[mine], t[mine]
            for s in sets:
                if (s, k, "all", 0) not in self.same:
                    yield (s, k, "all", 0), ek, tk
            lk = label[mine]
            for j in range(len(LABELS)):
                sel = lk == j
                if sel.any():
                    for s in sets:
                        if s != "all" and s != "held_all":
                            yield (s, k, "label", j), ek[sel], tk[sel]
            sk = speed[mine]
            for j in range(len(SPEEDS)):
                sel = sk == j
                if sel.any():
                    yield ("all", k, "speed", j), ek[sel], tk[sel]
            if k == "now" and c.with_outages:
                sk = since[mine]
                for j, cp in enumerate(SINCE_FIX_CHECKPOINTS_S):
                    sel = np.abs(sk - cp) <= SINCE_FIX_TOLERANCE_S
                    if sel.any():
                        yield ("all", k, "since", j), ek[sel], tk[sel]

    def first(self, rows: pd.DataFrame) -> None:
        """Pass one over one drive's rows: the groups' counts, the drive's own figures, its
        outages'."""
        for key, e, _ in self.slices(rows):
            self.sums[key].add(e)
        ds, drive = str(rows["dataset"].iloc[0]), str(rows["drive"].iloc[0])
        kind = category_index(rows["kind"], KINDS)
        e, t = rows["error_m"].to_numpy(dtype=float), rows["t_query"].to_numpy(dtype=float)
        mine: dict[str, Any] = {}
        for i, k in enumerate(KINDS):
            sel = kind == i
            mine[k] = summarize(e[sel])
            if sel.any():  # the interval depends on this predictor's queries of the drive only
                one = one_drive_cis({self.name: (e[sel], t[sel])}, self.c.stats)
                mine[k]["ci95"] = one[self.name]
        self.per_drive[(ds, drive)] = mine
        if self.c.with_outages:
            now = kind == KINDS.index("now")
            outage = rows["outage"].to_numpy()
            sel = now & (outage >= 0)
            _, ade, fde, t_end = per_outage(e[sel], t[sel], outage[sel])
            if ade.size:
                self.outages.append((self.drives, ade, fde, t_end))
        self.drives += 1

    def between(self) -> bool:
        """Each group's bins that pass two keeps; pass two is wanted when a drive was seen.
        Groups of as many drives in a row: they share the resamples (a few are cached)."""
        for s in sorted(self.sums.values(), key=lambda s: len(s.counts)):
            s.wanted()
        return self.drives > 0

    def second(self, rows: pd.DataFrame) -> None:
        """Pass two over the same drive's rows: the errors the quantiles read."""
        for key, e, t in self.slices(rows):
            self.sums[key].keep(e, t)

    def summaries(
        self, sets: Any, family: str, names: Sequence[str], kinds: Sequence[str] = KINDS
    ) -> dict[str, Any]:
        """Per kind, per name of the family's groups, the summary with its interval."""
        if self._done is None:  # groups of as many drives in a row (see between)
            by_drives = sorted(self.sums.items(), key=lambda kv: len(kv[1].counts))
            self._done = {key: _entry(s.summary()) for key, s in by_drives}
        done, same = self._done, self.same

        def entry(key: Key) -> dict[str, Any]:
            return copy.deepcopy(done[same[key]]) if key in same else done[key]

        return {
            k: {str(n): entry((sets, k, family, j)) for j, n in enumerate(names)} for k in kinds
        }

    def kinds(self, sets: Any) -> dict[str, Any]:
        """Per kind, the summary of its queries over ``sets``' drives."""
        return {k: v["all"] for k, v in self.summaries(sets, "all", ["all"]).items()}

    def result(self) -> dict[str, Any]:
        """The figures: ``entry`` (per kind), ``by_speed``, ``outages``, ``by_dataset``,
        ``by_label``, ``held_out`` (and ``held_out_all``) and ``per_drive`` (empty: no
        scored row)."""
        c = self.c
        out: dict[str, Any] = {"entry": self.kinds("all")}
        if self.drives:
            out["by_speed"] = self.summaries("all", "speed", SPEEDS)
        if c.with_outages:
            since = self.summaries("all", "since", SINCE, ["now"])["now"]
            out["outages"] = {"since_fix": since, "scores": _outage_scores(self, c.stats)}
        out["by_dataset"], out["by_label"], out["held_out"] = {}, {}, {}
        for ds in c.datasets:
            out["by_dataset"][ds] = self.kinds(("ds", ds))
            out["by_label"][ds] = self.summaries(("ds", ds), "label", LABELS)
            if ds in c.held_ds:
                held = ("held", ds)
                out["held_out"][ds] = (self.kinds(held), self.summaries(held, "label", LABELS))
        if c.held_all:
            out["held_out_all"] = self.kinds("held_all")
        out["per_drive"] = self.per_drive
        return out


def error_figures(c: Combining, name: str) -> dict[str, Any]:
    """:meth:`ErrorFigures.result` of predictor ``name``, its rows read for it alone."""
    figures = ErrorFigures(c, name)
    run_passes(c.ts, name, [figures])
    return figures.result()


def _outage_scores(groups: ErrorFigures, stats: Statistics) -> dict[str, Any]:
    """The outage scores with their intervals, from each drive's outages' ADE, FDE and end
    times (the drives numbered as they came)."""
    found = groups.outages
    drive = np.concatenate(
        [np.full(a.size, i, dtype=np.int64) for i, a, _, _ in found] or [np.empty(0, np.int64)]
    )
    ade, fde, t_end = (
        np.concatenate([f[j] for f in found]) if found else np.empty(0) for j in (1, 2, 3)
    )
    scores: dict[str, Any] = outage_figures_of(ade, fde)
    scores["ci95"] = outage_cis_of(ade, fde, t_end, drive, stats)
    return scores
