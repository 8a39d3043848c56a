"""Combine per-drive runs into the figures of ``results.json`` (per drive first, then combined).

Pure given its inputs: traces and per-drive records in, a nested dict of figures out. What
the run was (command, config, versions, data hashes) is added by
:func:`posbench.pipeline.results.build_results`; which learned models stand behind the
predictors is an input (:func:`posbench.replay.predictor_setup.learned_models`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import (
    Statistics,
    add_group_cis,
    drive_codes,
    one_drive_cis,
    outage_cis,
    paired_results,
    with_ci,
)
from posbench.config import RunConfig, default_baseline
from posbench.metrics.accuracy import speed_bin_labels, speed_bin_order, summarize, summarize_groups
from posbench.metrics.latency import latency_summary
from posbench.metrics.outages import (
    error_vs_since_fix,
    outage_keys,
    outage_scores,
    since_fix_checkpoint,
)
from posbench.scenarios.labels import LABELS
from posbench.scoring.records import DriveRun, trace_set
from posbench.scoring.reference import dataset_references
from posbench.scoring.schema import KINDS
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
        out["warmup"][name] = _kind_summaries(_with_codes(df[warm & ~no_ref]), stats)
        kind = df["kind"].to_numpy()
        out["no_reference"][name] = {k: int((no_ref & (kind == k)).sum()) for k in KINDS}
    return out


def _with_codes(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with column ``code``: its drive as an integer (the bootstrap's cluster)."""
    return df.assign(code=drive_codes(df))


def _columns(df: pd.DataFrame, kind: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Errors [m], drive codes, query times [s] and the row mask of one kind's rows."""
    m = (df["kind"] == kind).to_numpy()
    return (
        df["error_m"].to_numpy(dtype=float)[m],
        df["code"].to_numpy()[m],
        df["t_query"].to_numpy(dtype=float)[m],
        m,
    )


def _kind_summaries(df: pd.DataFrame, stats: Statistics | None = None) -> dict[str, Any]:
    """Per kind, :func:`summarize` of the errors, with ``ci95`` given ``stats`` (``df`` then
    needs the ``code`` column of :func:`_with_codes`)."""
    if stats is None:
        return {k: summarize(df.loc[df["kind"] == k, "error_m"].to_numpy()) for k in KINDS}
    kind = df["kind"].to_numpy()
    out = {k: summarize(df["error_m"].to_numpy(dtype=float)[kind == k]) for k in KINDS}
    add_group_cis(
        out,
        df["error_m"].to_numpy(dtype=float),
        kind,
        df["code"].to_numpy(),
        df["t_query"].to_numpy(dtype=float),
        stats,
    )
    return out


def _label_summaries(df: pd.DataFrame, stats: Statistics | None = None) -> dict[str, Any]:
    out = {}
    for kind in KINDS:
        m = (df["kind"] == kind).to_numpy()
        e = df["error_m"].to_numpy(dtype=float)[m]
        labels = df["label"].to_numpy()[m]
        out[kind] = summarize_groups(e, labels, order=list(LABELS))
        if stats is not None:
            add_group_cis(
                out[kind],
                e,
                labels,
                df["code"].to_numpy()[m],
                df["t_query"].to_numpy(dtype=float)[m],
                stats,
            )
    return out


def _per_drive(
    df: pd.DataFrame,
    name: str,
    per_drive: dict[tuple[str, str], dict[str, Any]],
    queries: dict[tuple[str, str, str], dict[str, tuple[np.ndarray, np.ndarray]]],
) -> None:
    """Each drive's summaries of predictor ``name`` (``df``: its scored rows with ``code``)
    into ``per_drive[(dataset, drive)][name]``, and each drive's errors and query times per
    kind into ``queries[(dataset, drive, kind)][name]`` (for the intervals, drive by drive)."""
    first = df.drop_duplicates("code")
    keys = dict(
        zip(
            first["code"].to_numpy(),
            zip(first["dataset"].astype(str), first["drive"].astype(str), strict=True),
            strict=True,
        )
    )
    for key in keys.values():
        per_drive.setdefault(key, {})[name] = {k: summarize(np.empty(0)) for k in KINDS}
    for k in KINDS:
        e, codes, t, _ = _columns(df, k)
        order = np.argsort(codes, kind="stable")  # stable: each drive keeps its time order
        present, starts, counts = np.unique(codes[order], return_index=True, return_counts=True)
        for code, a, n in zip(present.tolist(), starts.tolist(), counts.tolist(), strict=True):
            ds, drive = keys[code]
            idx = order[a : a + n]
            per_drive[(ds, drive)][name][k] = summarize(e[idx])
            queries.setdefault((ds, drive, k), {})[name] = (e[idx], t[idx])


def _durations(runs: Sequence[DriveRun], call: str, name: str) -> list[np.ndarray]:
    """Predictor ``name``'s ``call`` durations [ns] per drive that has them, in drive order."""
    found = (r.call_ns(call, name) for r in runs)
    return [a for a in found if a is not None]


def _empty_kinds(stats: Statistics | None = None) -> dict[str, Any]:
    empty = np.empty(0)
    return {k: with_ci(summarize(empty), empty, empty, None, stats) for k in KINDS}


def aggregate(
    runs: Sequence[DriveRun],
    cfg: RunConfig,
    *,
    models: Mapping[str, Mapping[str, Any]],
    traces: TraceSet | pd.DataFrame | None = None,
    statistics: Statistics | None = None,
) -> dict[str, Any]:
    """The figures of ``results.json``, from its key ``predictors`` on (``traces``: the
    runs' traces, in memory or on disk, :func:`~posbench.scoring.records.trace_set` if not
    given; ``models``: the learned models behind the
    predictors, per name ``{"model", "bundled", "train_drives"}``, ``{}`` for none, e.g.
    answers scored from a file, whose models posbench cannot know).

    Headline figures use the scored rows only
    (:func:`~posbench.scoring.schema.scored_mask`); the work goes one predictor at a time
    over just the :data:`AGGREGATED` columns of its rows (the baseline's rows are kept for
    the paired comparison); traces on disk are read that way, so the process holds one
    predictor's columns (two with the baseline), never every answer of the run. Every
    summary gets its ``ci95`` and each predictor its paired comparison with the baseline
    as ``statistics`` says (default: :class:`Statistics` with baseline ``kf`` when it is
    in the run; see :mod:`posbench.aggregation.intervals`)."""
    ts = trace_set(runs) if traces is None else as_trace_set(traces)
    preds = list(cfg.predictors)
    stats = statistics or Statistics(baseline=default_baseline(preds))
    res: dict[str, Any] = {
        "predictors": {},
        "references": {},  # filled from the drives below
        "by_dataset": {},
        "by_label": {},
        "by_speed": {},
        "outages": {},
        "models": {n: dict(m) for n, m in models.items()},
        "excluded": excluded_summary(ts, preds, stats),
        "held_out": {},
        "held_out_all": {},
        "drives": [],
    }
    res["training_drives"] = {n: m["train_drives"] for n, m in res["models"].items()}
    trained_on = {n for names in res["training_drives"].values() for n in names}
    cols = [c for c in AGGREGATED if c in ts] if not ts.empty else list(AGGREGATED)
    # which drives were scored, and whether any query fell in an outage: one predictor at a time
    drives_of: dict[str, set[str]] = {}
    with_outages = False
    for _, df in ts.per_predictor(preds, ["dataset", "drive", "outage"]):
        pairs = df[["dataset", "drive"]].drop_duplicates()
        for ds, drive in zip(pairs["dataset"].astype(str), pairs["drive"].astype(str), strict=True):
            drives_of.setdefault(ds, set()).add(drive)
        with_outages = with_outages or bool((df["outage"].to_numpy() >= 0).any())
    datasets = sorted(drives_of)
    all_drives = set().union(*drives_of.values()) if drives_of else set()
    held_ds = [ds for ds in datasets if drives_of[ds] & trained_on]
    for ds in held_ds:
        res["held_out"][ds] = {
            "drives": sorted(drives_of[ds] - trained_on),
            "excluded_training_drives": sorted(drives_of[ds] & trained_on),
            "predictors": {},
            "by_label": {},
        }
    held_all = bool(all_drives & trained_on) and bool(all_drives - trained_on)
    if held_all:
        res["held_out_all"] = {"drives": sorted(all_drives - trained_on), "predictors": {}}
    per_drive: dict[tuple[str, str], dict[str, Any]] = {}
    drive_queries: dict[tuple[str, str, str], dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for ds in datasets:
        res["by_dataset"][ds] = {}
        res["by_label"][ds] = {}
    res["statistics"] = stats.to_dict()
    res["paired"] = {"baseline": stats.baseline, "overall": {}, "by_dataset": {}, "by_label": {}}

    def scored_rows(name: str) -> pd.DataFrame:
        if ts.empty:
            return pd.DataFrame(columns=[*cols, "code"])
        return _with_codes(ts.scored(name, cols))

    base_df = scored_rows(stats.baseline) if stats.baseline else None
    for name in preds:
        df = base_df if base_df is not None and name == stats.baseline else scored_rows(name)
        entry = _kind_summaries(df, stats) if not df.empty else _empty_kinds(stats)
        steps, queries, covs = (_durations(runs, c, name) for c in ("step", "query", "cov"))
        entry["latency_us"] = latency_summary(np.concatenate(steps or [np.empty(0)]))
        entry["query_us"] = latency_summary(np.concatenate(queries or [np.empty(0)]))
        if covs:  # the covariance_at call, timed apart from the query
            entry["covariance_us"] = latency_summary(np.concatenate(covs))
        res["predictors"][name] = entry
        if not df.empty:
            for kind in KINDS:
                e, codes, t, m = _columns(df, kind)
                bins = speed_bin_labels(df["speed_mps"].to_numpy()[m])
                by_speed = summarize_groups(e, bins, order=speed_bin_order() + ["unknown"])
                add_group_cis(by_speed, e, bins, codes, t, stats)
                res["by_speed"].setdefault(name, {})[kind] = by_speed
        if with_outages:
            e, codes, t, m = _columns(df, "now")
            outage = df["outage"].to_numpy()[m]
            since = df["since_fix_s"].to_numpy()[m]
            ids = outage_keys(codes, outage)
            since_fix = error_vs_since_fix(e, since)
            add_group_cis(since_fix, e, since_fix_checkpoint(since), codes, t, stats)
            scores: dict[str, Any] = outage_scores(e, t, ids)
            scores["ci95"] = outage_cis(e, t, ids, stats)
            res["outages"][name] = {"since_fix": since_fix, "scores": scores}
        if base_df is not None and name != stats.baseline and not df.empty:
            pr = paired_results(df, base_df, datasets, stats)
            res["paired"]["overall"][name] = pr["overall"]
            for ds in datasets:
                res["paired"]["by_dataset"].setdefault(ds, {})[name] = pr["by_dataset"][ds]
                res["paired"]["by_label"].setdefault(ds, {})[name] = pr["by_label"][ds]
            if held_all or held_ds:  # the same comparison without the training drives
                ph = paired_results(
                    df[~df["drive"].isin(trained_on)],
                    base_df[~base_df["drive"].isin(trained_on)],
                    held_ds,
                    stats,
                )
                held = res["paired"].setdefault(
                    "held_out",
                    {
                        "drives": sorted(all_drives - trained_on),
                        "overall": {},
                        "by_dataset": {ds: {} for ds in held_ds},
                    },
                )
                held["overall"][name] = ph["overall"]
                for ds in held_ds:
                    held["by_dataset"][ds][name] = ph["by_dataset"][ds]
        groups = {str(ds): g for ds, g in df.groupby("dataset", sort=True, observed=True)}
        for ds in datasets:
            dfp = groups.get(ds, df.iloc[:0])
            res["by_dataset"][ds][name] = _kind_summaries(dfp, stats)
            res["by_label"][ds][name] = _label_summaries(dfp, stats)
            if ds in res["held_out"]:
                held = dfp[~dfp["drive"].isin(trained_on)]
                res["held_out"][ds]["predictors"][name] = _kind_summaries(held, stats)
                res["held_out"][ds]["by_label"][name] = _label_summaries(held, stats)
        if held_all:
            res["held_out_all"]["predictors"][name] = _kind_summaries(
                df[~df["drive"].isin(trained_on)], stats
            )
        if not df.empty:
            _per_drive(df, name, per_drive, drive_queries)
            # each drive's interval (block bootstrap) depends on its own predictor's queries
            # only: taken now, so no other predictor's errors are held meanwhile
            for (ds, drive, k), by_pred in drive_queries.items():
                for n, ci in one_drive_cis(by_pred, stats).items():
                    per_drive[(ds, drive)][n][k]["ci95"] = ci
            drive_queries.clear()
        del df, groups
    del base_df
    empty_ci = _empty_kinds(stats)["future"].get("ci95")
    for kinds in (s for by_name in per_drive.values() for s in by_name.values()):
        for k in KINDS:
            if empty_ci is not None and "ci95" not in kinds[k]:  # a kind without queries
                kinds[k]["ci95"] = dict(empty_ci)
    # a summary over exactly one drive's queries is that drive's summary: the same interval
    pairs = {ds: {(ds, d) for d in drives_of[ds]} for ds in datasets}
    one_drive = [(res["predictors"], set().union(*pairs.values()) if pairs else set())]
    one_drive += [(res["by_dataset"][ds], pairs[ds]) for ds in datasets]
    one_drive += [
        (h["predictors"], {(ds, d) for d in h["drives"]}) for ds, h in res["held_out"].items()
    ]
    if held_all:
        one_drive.append(
            (
                res["held_out_all"]["predictors"],
                {p for ds in datasets for p in pairs[ds] if p[1] not in trained_on},
            )
        )
    for summaries, drives in one_drive:
        if len(drives) == 1 and next(iter(drives)) in per_drive:
            mine = per_drive[next(iter(drives))]
            for name, kinds in summaries.items():
                for k in KINDS:
                    if name in mine and "ci95" in kinds.get(k, {}):
                        kinds[k]["ci95"] = dict(mine[name][k]["ci95"])
    for r in runs:
        d: dict[str, Any] = {
            "name": r.name,
            "dataset": r.dataset,
            "reference": r.reference,
            "truth_source": r.truth_source,
            "gps_condition": r.gps_condition,
            "duration_s": r.duration_s,
            "gps_fed": r.gps_count,
            "notes": r.notes,
            "warnings": r.warnings,
            "skipped": r.skipped,
            "trained_on": [n for n, names in res["training_drives"].items() if r.name in names],
            "rejected": dict(r.rejected),
            "predictors": {},
        }
        if r.sensor_frames:
            d["sensor_frames"] = r.sensor_frames
        if r.has_traces:
            mine = per_drive.get((r.dataset, r.name), {})
            d["predictors"] = {name: mine.get(name, _empty_kinds(stats)) for name in preds}
        res["drives"].append(d)
    res["references"] = dataset_references(res["drives"])
    from posbench.aggregation.limit import imu_readers, limit_section

    # the bound beside the predictors, never one; each judged against the bound that applies
    readers = imu_readers(preds, cfg.predictor_options)
    limit = limit_section(runs, res, stats, readers)
    if limit is not None:
        res["limit"] = limit
    res["gate"] = gate_summary(runs, cfg)
    from posbench.aggregation.outage_lengths import outage_length_section

    lengths = outage_length_section(runs, cfg, stats)  # the outage-lengths profile only
    if lengths is not None:
        res["outage_lengths"] = lengths
    from posbench.aggregation.track import track_section

    res["track_errors"] = track_section(ts, preds)
    from posbench.aggregation.uncertainty import uncertainty_section

    res["uncertainty"] = uncertainty_section(ts, preds)
    from posbench.aggregation.sanity import sanity_section

    res["sanity"] = sanity_section(ts, preds, datasets, stats)
    return res


def gate_summary(runs: Sequence[DriveRun], cfg: RunConfig) -> dict[str, Any]:
    """The GPS outlier gate's totals: per predictor, fixes rejected, fixes fed and drives
    with at least one rejection (empty when the run was ungated)."""
    out: dict[str, Any] = {"enabled": bool(cfg.gate), "predictors": {}}
    if not cfg.gate:
        return out
    fed = sum(r.gps_count for r in runs if not r.skipped)
    for name in cfg.predictors:
        counts = [r.rejected.get(name, 0) for r in runs if not r.skipped]
        out["predictors"][name] = {
            "rejected": int(sum(counts)),
            "fixes_fed": int(fed),
            "drives_with_rejections": int(sum(c > 0 for c in counts)),
        }
    return out
