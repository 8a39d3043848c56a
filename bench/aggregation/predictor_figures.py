"""Each predictor's figures, step one of combining a run (:mod:`posbench.aggregation.aggregate`
puts them in place): from its scored rows, read on their own (with the baseline's for the
paired comparison), every summary and interval of results.json that concerns it, as plain
values, so that they can be computed in a child process and sent back.

Pure given its inputs: the traces (in memory or on disk) and the per-drive records in,
nested dicts of figures out."""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import (
    Statistics,
    add_group_cis,
    ci_entry,
    drive_codes,
    one_drive_cis,
    outage_cis,
    with_ci,
)
from posbench.aggregation.paired_sums import (
    drive_indices,
    paired_groups,
    paired_sums,
    rereader,
)
from posbench.heap import trim_heap
from posbench.metrics.accuracy import speed_bin_index, speed_bin_order, summarize
from posbench.metrics.latency import latency_summary
from posbench.metrics.outages import (
    SINCE_FIX_CHECKPOINTS_S,
    SINCE_FIX_TOLERANCE_S,
    error_vs_since_fix,
    outage_keys,
    outage_scores,
    since_fix_checkpoint,
)
from posbench.scenarios.labels import LABELS
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index, text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

#: the trace columns aggregation reads (positions are not needed once errors exist)
AGGREGATED = (
    "dataset",
    "drive",
    "predictor",
    "kind",
    "t_query",
    "error_m",
    "label",
    "speed_mps",
    "since_fix_s",
    "outage",
)


def excluded_summary(
    traces: TraceSet | pd.DataFrame, preds: Sequence[str], stats: Statistics | None = None
) -> dict[str, Any]:
    """What the headline figures leave out, per predictor and kind: warm-up queries (with
    their error summaries, and intervals given ``stats``) and queries without a reference
    (beyond the truth's or the fixes' span: nothing to score against). One predictor's
    rows at a time."""
    out: dict[str, Any] = {"warmup": {}, "no_reference": {}}
    ts = as_trace_set(traces)
    if ts.empty:
        return out
    cols = ["dataset", "drive", "kind", "t_query", "error_m", "x_ref", "y_ref", "warmup"]
    for name, df in ts.per_predictor(preds, cols, scored=False):
        no_ref = (df["x_ref"].isna() | df["y_ref"].isna()).to_numpy()
        warm = df["warmup"].to_numpy(dtype=bool) if "warmup" in df else np.zeros(len(df), bool)
        out["warmup"][name] = kind_summaries(with_codes(df[warm & ~no_ref]), stats)
        kind = text_values(df["kind"])
        out["no_reference"][name] = {k: int((no_ref & (kind == k)).sum()) for k in KINDS}
    return out


def with_codes(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with column ``code``: its drive as an integer (the bootstrap's cluster)."""
    return df.assign(code=drive_codes(df))


def kind_summaries(df: pd.DataFrame, stats: Statistics | None = None) -> dict[str, Any]:
    """Per kind, :func:`summarize` of the errors, with ``ci95`` given ``stats`` (``df`` then
    needs the ``code`` column of :func:`with_codes`)."""
    every = _kind_groups(df, np.zeros(len(df), dtype=np.int8), ["all"], stats)
    return {k: every[k]["all"] for k in KINDS}


def _kind_groups(
    df: pd.DataFrame,
    groups: np.ndarray,
    names: Sequence[str],
    stats: Statistics | None,
) -> dict[str, dict[str, Any]]:
    """Per kind, per name of ``names``, :func:`summarize` of the errors of the rows whose
    ``groups`` value is that name's index (-1: in none), with ``ci95`` given ``stats``:
    what :func:`summarize_groups` and :func:`add_group_cis` give each kind's rows, one
    group's rows at a time instead of a copy of each kind's columns."""
    e = df["error_m"].to_numpy(dtype=float)
    kind = category_index(df["kind"], KINDS)
    key = np.where((kind >= 0) & (groups >= 0), kind * len(names) + groups, -1)
    del kind
    codes, t = np.empty(0, dtype=np.int64), np.empty(0)
    if stats is not None:
        codes, t = df["code"].to_numpy(), df["t_query"].to_numpy(dtype=float)
    out: dict[str, dict[str, Any]] = {}
    for i, k in enumerate(KINDS):
        out[k] = {}
        for j, name in enumerate(names):
            rows = np.flatnonzero(key == i * len(names) + j)  # in their (time) order
            mine = e[rows]
            out[k][str(name)] = summarize(mine)
            if stats is not None:
                clusters = codes[rows]
                # query times order a single drive's queries only: no copy for several
                drives = clusters[np.isfinite(mine)]
                one = drives.size > 0 and drives.min() == drives.max()
                del drives
                times = t[rows] if one else None
                out[k][str(name)]["ci95"] = ci_entry(mine, clusters, times, stats)
                del clusters, times
            del rows, mine
    return out


def label_summaries(df: pd.DataFrame, stats: Statistics | None = None) -> dict[str, Any]:
    """Per kind, per route type of :data:`LABELS`, :func:`summarize` of the errors (with
    ``ci95`` given ``stats``; ``df`` then needs the ``code`` column of :func:`with_codes`)."""
    return _kind_groups(df, category_index(df["label"], LABELS), LABELS, stats)


def per_drive_summaries(
    df: pd.DataFrame, name: str, stats: Statistics
) -> dict[tuple[str, str], dict[str, Any]]:
    """Each drive's figures of predictor ``name`` (``df``: its scored rows with ``code``):
    ``{(dataset, drive): {kind: summary with ci95}}``, the interval a block bootstrap of
    the drive's queries (:func:`one_drive_cis`). One drive and kind at a time: nothing is
    kept of a drive's queries once its figures are drawn."""
    first = df.drop_duplicates("code")
    keys = dict(
        zip(
            first["code"].to_numpy(),
            zip(first["dataset"].astype(str), first["drive"].astype(str), strict=True),
            strict=True,
        )
    )
    out = {key: {k: summarize(np.empty(0)) for k in KINDS} for key in keys.values()}
    e, t = df["error_m"].to_numpy(dtype=float), df["t_query"].to_numpy(dtype=float)
    codes, kind = df["code"].to_numpy(), category_index(df["kind"], KINDS)
    for i, k in enumerate(KINDS):
        rows = np.flatnonzero(kind == i)
        mine = codes[rows]
        order = np.argsort(mine, kind="stable")  # stable: each drive keeps its time order
        present, starts, counts = np.unique(mine[order], return_index=True, return_counts=True)
        del mine
        for code, a, n in zip(present.tolist(), starts.tolist(), counts.tolist(), strict=True):
            idx = rows[order[a : a + n]]
            errors = e[idx]
            figures: dict[str, Any] = dict(summarize(errors))
            # the interval depends on this predictor's queries of the drive only
            figures["ci95"] = one_drive_cis({name: (errors, t[idx])}, stats)[name]
            out[keys[code]][k] = figures
        del rows, order
    return out


def durations(runs: Sequence[DriveRun], call: str, name: str) -> list[np.ndarray]:
    """Predictor ``name``'s ``call`` durations [ns] per drive that has them, in drive order."""
    found = (r.call_ns(call, name) for r in runs)
    return [a for a in found if a is not None]


def empty_kinds(stats: Statistics | None = None) -> dict[str, Any]:
    empty = np.empty(0)
    return {k: with_ci(summarize(empty), empty, empty, None, stats) for k in KINDS}


@dataclass(frozen=True)
class Combining:
    """What every predictor's figures need, settled before any is computed."""

    ts: TraceSet
    runs: Sequence[DriveRun]
    cols: list[str]
    stats: Statistics
    datasets: list[str]
    with_outages: bool
    trained_on: set[str]
    held_ds: list[str]
    held_all: bool
    #: whether the predictors are checked against cv (:mod:`posbench.aggregation.sanity`)
    sanity: bool

    def scored_rows(self, name: str) -> pd.DataFrame:
        """``name``'s scored rows of :data:`AGGREGATED`, with the drive code."""
        if self.ts.empty:
            return pd.DataFrame(columns=[*self.cols, "code"])
        return with_codes(self.ts.scored(name, self.cols))


def predictor_figures(c: Combining, name: str) -> dict[str, Any]:
    """Every figure of predictor ``name``, from its scored rows (and the baseline's, for the
    paired comparison): the pieces :func:`aggregate` puts in place. Reads and holds this
    predictor's rows only (and the baseline's), one figure family at a time: each family
    reads the columns it needs and lets them go before the next reads its own."""
    out = error_figures(c, name)
    trim_heap()
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


def _paired_figures(c: Combining, name: str, df: pd.DataFrame) -> dict[str, Any]:
    """``paired`` (and ``paired_held``) of predictor ``name`` (its scored rows ``df``)
    against the baseline, from both predictors' per-drive sums (:mod:`posbench.aggregation.
    paired_sums`: neither's rows held); none for the baseline itself, or without one."""
    stats = c.stats
    if not stats.baseline or name == stats.baseline or df.empty:
        return {}
    sums = paired_sums(c.ts, name, stats.baseline)
    again = rereader(c.ts, name, stats.baseline, sums)
    out = {"paired": paired_groups(sums, drive_indices(sums), c.datasets, again, stats)}
    if c.held_all or c.held_ds:  # the same comparison without the training drives
        keep = drive_indices(sums, without=c.trained_on)
        out["paired_held"] = paired_groups(sums, keep, c.held_ds, again, stats)
    return out


def _by_speed(df: pd.DataFrame, stats: Statistics) -> dict[str, Any]:
    """``by_speed``: per kind, the errors' summary and interval per speed bin."""
    bins = speed_bin_index(df["speed_mps"].to_numpy(dtype=float))
    return _kind_groups(df, bins, [*speed_bin_order(), "unknown"], stats)


def _outage_figures(df: pd.DataFrame, stats: Statistics) -> dict[str, Any]:
    """``outages``: the now-queries' error by time since the last fix, and the outage
    scores with their intervals. Each reads only the now-queries it counts (near a
    checkpoint; in an outage), never a copy of every now-query's columns."""
    now = category_index(df["kind"], KINDS) == KINDS.index("now")
    since = df["since_fix_s"].to_numpy(dtype=float)
    near = np.zeros(len(df), dtype=bool)
    for c in SINCE_FIX_CHECKPOINTS_S:
        near |= np.abs(since - c) <= SINCE_FIX_TOLERANCE_S
    e, codes = df["error_m"].to_numpy(dtype=float), df["code"].to_numpy()
    t = df["t_query"].to_numpy(dtype=float)
    rows = np.flatnonzero(now & near)  # in their order
    del near
    since_fix = error_vs_since_fix(e[rows], since[rows])
    add_group_cis(
        since_fix, e[rows], since_fix_checkpoint(since[rows]), codes[rows], t[rows], stats
    )
    outage = df["outage"].to_numpy()
    rows = np.flatnonzero(now & (outage >= 0))  # the scores read outage queries only
    ids = outage_keys(codes[rows], outage[rows])
    scores: dict[str, Any] = outage_scores(e[rows], t[rows], ids)
    scores["ci95"] = outage_cis(e[rows], t[rows], ids, stats)
    return {"since_fix": since_fix, "scores": scores}


def error_figures(c: Combining, name: str) -> dict[str, Any]:
    """Predictor ``name``'s figures of the error column: the headline entry with latency,
    by speed, outages, the paired comparison with the baseline, by data set and route type,
    held out, per drive. Its own function so that every array it makes is gone when it
    returns (a local of :func:`predictor_figures` would live on through the sections)."""
    stats, datasets, trained_on = c.stats, c.datasets, c.trained_on
    df = c.scored_rows(name)
    out: dict[str, Any] = {}
    entry = kind_summaries(df, stats) if not df.empty else empty_kinds(stats)
    steps, queries, covs = (durations(c.runs, call, name) for call in ("step", "query", "cov"))
    entry["latency_us"] = latency_summary(np.concatenate(steps or [np.empty(0)]))
    entry["query_us"] = latency_summary(np.concatenate(queries or [np.empty(0)]))
    if covs:  # the covariance_at call, timed apart from the query
        entry["covariance_us"] = latency_summary(np.concatenate(covs))
    out["entry"] = entry
    # the paired comparison first, so that the baseline's rows are gone before the rest
    paired = _paired_figures(c, name, df)
    trim_heap()
    if not df.empty:
        out["by_speed"] = _by_speed(df, stats)
    if c.with_outages:
        out["outages"] = _outage_figures(df, stats)
    out.update(paired)
    del paired
    out["by_dataset"], out["by_label"], out["held_out"] = {}, {}, {}
    ds_index = category_index(df["dataset"], [str(ds) for ds in datasets])
    present = set(np.unique(ds_index).tolist())
    for j, ds in enumerate(datasets):
        if present == {j}:  # every row is this data set's: its rows are df, its figures entry's
            dfp = df
            out["by_dataset"][ds] = {k: copy.deepcopy(entry[k]) for k in KINDS}
        else:  # one data set's rows at a time
            dfp = df[ds_index == j]
            out["by_dataset"][ds] = kind_summaries(dfp, stats)
        out["by_label"][ds] = label_summaries(dfp, stats)
        if ds in c.held_ds:
            held = dfp[~dfp["drive"].isin(trained_on)]
            out["held_out"][ds] = (kind_summaries(held, stats), label_summaries(held, stats))
            del held
        del dfp
    del ds_index
    if c.held_all:
        out["held_out_all"] = kind_summaries(df[~df["drive"].isin(trained_on)], stats)
    out["per_drive"] = per_drive_summaries(df, name, stats) if not df.empty else {}
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
