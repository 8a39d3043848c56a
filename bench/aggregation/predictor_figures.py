"""Each predictor's figures, step one of combining a run (:mod:`posbench.aggregation.aggregate`
puts them in place): from its scored rows, read on their own (with the baseline's for the
paired comparison), every summary and interval of results.json that concerns it, as plain
values, so that they can be computed in a child process and sent back.

Pure given its inputs: the traces (in memory or on disk) and the per-drive records in,
nested dicts of figures out."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
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
from posbench.metrics.latency import latency_summary
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet


def durations(runs: Sequence[DriveRun], call: str, name: str) -> list[np.ndarray]:
    """Predictor ``name``'s ``call`` durations [ns] per drive that has them, in drive order."""
    found = (r.call_ns(call, name) for r in runs)
    return [a for a in found if a is not None]


def empty_kinds(stats: Statistics | None = None) -> dict[str, Any]:
    empty = np.empty(0)
    return {k: with_ci(summarize(empty), empty, empty, None, stats) for k in KINDS}


def predictor_figures(c: Combining, name: str) -> dict[str, Any]:
    """Every figure of predictor ``name``, from its scored rows (and the baseline's, for the
    paired comparison): the pieces :func:`aggregate` puts in place. Reads and holds this
    predictor's rows only (and the baseline's), one figure family at a time: each family
    reads the columns it needs and lets them go before the next reads its own."""
    from posbench.aggregation.error_figures import error_figures

    out = error_figures(c, name)
    entry = out["entry"]
    steps, queries, covs = (durations(c.runs, call, name) for call in ("step", "query", "cov"))
    entry["latency_us"] = latency_summary(np.concatenate(steps or [np.empty(0)]))
    entry["query_us"] = latency_summary(np.concatenate(queries or [np.empty(0)]))
    if covs:  # the covariance_at call, timed apart from the query
        entry["covariance_us"] = latency_summary(np.concatenate(covs))
    out.update(paired_figures(c, name, bool(out["per_drive"])))
    trim_heap()
    from posbench.aggregation.excluded import excluded_summary
    from posbench.aggregation.sanity import REFERENCE, sanity_section
    from posbench.aggregation.track import track_section
    from posbench.aggregation.uncertainty import uncertainty_section

    out["excluded"] = excluded_summary(c.ts, [name], c.stats)
    trim_heap()
    out["track_errors"] = track_section(c.ts, [name])
    trim_heap()
    out["uncertainty"] = uncertainty_section(c.ts, [name])
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
    of them fell in an outage."""
    df = ts.scored(name, ["dataset", "drive", "outage"])
    pairs = df[["dataset", "drive"]].drop_duplicates()
    found = list(zip(pairs["dataset"].astype(str), pairs["drive"].astype(str), strict=True))
    return found, bool((df["outage"].to_numpy() >= 0).any())
