"""Each predictor's figures, step one of combining a run (:mod:`posbench.aggregation.aggregate`
puts them in place): from its scored rows, read on their own (with the baseline's for the
paired comparison), every summary and interval of results.json that concerns it, as plain
values, so that they can be computed in a child process and sent back.

Pure given its inputs: the traces (in memory or on disk) and the per-drive records in,
nested dicts of figures out."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from posbench.aggregation.combining import Combining
from posbench.aggregation.intervals import (
    Statistics,
    with_ci,
)
from posbench.aggregation.paired_sums import (
    drive_indices,
    paired_groups,
    paired_sums,
    rereader,
)
from posbench.heap import trim_heap
from posbench.metrics.accuracy import summarize
from posbench.metrics.latency import latency_summary, streamed_latency_summary
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet


def latency_of(runs: Sequence[DriveRun], call: str, name: str) -> dict[str, Any] | None:
    """The latency summary [us] of predictor ``name``'s ``call`` durations over every drive
    that has them, read one drive at a time, twice
    (:func:`~posbench.metrics.latency.streamed_latency_summary`: at 64 drive hours the
    durations joined held 180 MB); None where no drive has them."""

    seen = False

    def pieces() -> Iterator[np.ndarray]:
        nonlocal seen
        for r in runs:
            found = r.call_ns(call, name)
            if found is not None:
                seen = True
                yield found

    summary = streamed_latency_summary(pieces)
    return summary if seen else None


def empty_kinds(stats: Statistics | None = None) -> dict[str, Any]:
    empty = np.empty(0)
    return {k: with_ci(summarize(empty), empty, empty, None, stats) for k in KINDS}


def predictor_figures(c: Combining, name: str) -> dict[str, Any]:
    """Every figure of predictor ``name``: the pieces :func:`aggregate` puts in place. Its
    figure families read its rows together, one drive at a time
    (:func:`~posbench.aggregation.drive_passes.run_passes`), and hold a few numbers per drive
    and group; the paired comparison reads it beside the baseline the same way, one drive
    at a time (:mod:`posbench.aggregation.paired_sums`)."""
    from posbench.aggregation.drive_passes import run_passes
    from posbench.aggregation.error_figures import ErrorFigures
    from posbench.aggregation.excluded import ExcludedFigures
    from posbench.aggregation.sanity import REFERENCE, sanity_section
    from posbench.aggregation.track import TrackFigures, track_available
    from posbench.aggregation.uncertainty import (
        UncertaintyFigures,
        add_predictor,
        empty_section,
        uncertainty_available,
    )

    errors, excluded = ErrorFigures(c, name), ExcludedFigures(c.stats)
    track = TrackFigures() if track_available(c.ts) else None
    uncertainty = UncertaintyFigures() if uncertainty_available(c.ts) else None
    families = [f for f in (errors, excluded, track, uncertainty) if f is not None]
    run_passes(c.ts, name, families)
    out = errors.result()
    entry = out["entry"]
    none = latency_summary(np.empty(0))
    entry["latency_us"] = latency_of(c.runs, "step", name) or none
    entry["query_us"] = latency_of(c.runs, "query", name) or none
    covs = latency_of(c.runs, "cov", name)
    if covs is not None:  # the covariance_at call, timed apart from the query
        entry["covariance_us"] = covs
    out.update(paired_figures(c, name, bool(out["per_drive"])))
    warmup, no_reference = excluded.result()
    out["excluded"] = {"warmup": {name: warmup}, "no_reference": {name: no_reference}}
    out["track_errors"] = {"predictors": {}, "by_label": {}}
    if track is not None:
        kinds, labels = track.result()
        out["track_errors"] = {"predictors": {name: kinds}, "by_label": {name: labels}}
    out["uncertainty"] = empty_section()
    if uncertainty is None:
        out["uncertainty"]["none"].append(name)
    else:
        add_predictor(out["uncertainty"], name, uncertainty)
    trim_heap()
    out["losses"] = (
        sanity_section(c.ts, [REFERENCE, name], c.datasets, c.stats)["losses"]
        if c.sanity and name != REFERENCE
        else []
    )
    return out


def paired_figures(c: Combining, name: str, scored: bool) -> dict[str, Any]:
    """``paired`` (and ``paired_held``) of predictor ``name`` (``scored``: whether it has
    scored rows) against the baseline, from both predictors' per-drive sums
    (:mod:`posbench.aggregation.paired_sums`: neither's rows held); none for the baseline
    itself, or without one."""
    stats = c.stats
    if not stats.baseline or name == stats.baseline or not scored:
        return {}
    sums = paired_sums(c.ts, name, stats.baseline)
    again = rereader(c.ts, name, stats.baseline, sums)
    out = {"paired": paired_groups(sums, drive_indices(sums), c.datasets, again, stats)}
    if c.held_all or c.held_ds:  # the same comparison without the training drives
        keep = drive_indices(sums, without=c.trained_on)
        out["paired_held"] = paired_groups(sums, keep, c.held_ds, again, stats)
    return out


def limit_figures(
    runs: Sequence[DriveRun],
    res: dict[str, Any],
    stats: Statistics,
    readers: Mapping[str, bool | None],
) -> tuple[dict[str, Any] | None, list[dict[str, Any] | None]]:
    """:func:`~posbench.aggregation.limit.limit_section` and the ``limit`` entry it gives
    each drive of ``res["drives"]`` (None: none), as values: it may run in a child process."""
    from posbench.aggregation.limit import limit_section

    section = limit_section(runs, res, stats, readers)
    return section, [d.get("limit") for d in res["drives"]]


def scored_drives(ts: TraceSet, name: str) -> tuple[list[tuple[str, str]], bool]:
    """The (dataset, drive) pairs with scored rows of predictor ``name``, and whether any
    of them fell in an outage: read one part at a time."""
    found: dict[tuple[str, str], None] = {}
    outages = False
    for rows in ts.pieces(name, ["dataset", "drive", "outage"], plain=True):
        pairs = rows[["dataset", "drive"]].drop_duplicates()
        found.update(
            dict.fromkeys(
                zip(pairs["dataset"].astype(str), pairs["drive"].astype(str), strict=True)
            )
        )
        outages = outages or bool((rows["outage"].to_numpy() >= 0).any())
    return list(found), outages
