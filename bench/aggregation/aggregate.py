"""Combine per-drive runs into the figures of ``results.json`` (per drive first, then combined).

Pure given its inputs: traces and per-drive records in, a nested dict of figures out. What
the run was (command, config, versions, data hashes) is added by
:func:`posbench.pipeline.results.build_results`; which learned models stand behind the
predictors is an input (:func:`posbench.replay.predictor_setup.learned_models`).

Two steps: each predictor's figures
(:func:`posbench.aggregation.predictor_figures.predictor_figures`, in a child process each
given ``workers``), then put in place and combined over predictors and drives here."""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from typing import Any

import pandas as pd

from posbench.aggregation.combining import Combining
from posbench.aggregation.intervals import Statistics
from posbench.aggregation.predictor_figures import (
    empty_kinds,
    limit_figures,
    predictor_figures,
    scored_drives,
)
from posbench.config import RunConfig, default_baseline
from posbench.scoring.records import DriveRun, trace_set
from posbench.scoring.reference import dataset_references
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet, as_trace_set


def _merge_sections(res: dict[str, Any], name: str, f: dict[str, Any]) -> None:
    """Predictor ``name``'s excluded queries, track errors, uncertainty and sanity losses
    (``f``: :func:`predictor_figures`) into ``res``, after the predictors before it."""
    for key in ("warmup", "no_reference"):
        res["excluded"][key].update(f["excluded"][key])
    for block, value in f["track_errors"].items():
        res["track_errors"].setdefault(block, {}).update(value)
    for block, value in f["uncertainty"].items():
        if block == "none":
            res["uncertainty"]["none"].extend(value)
        else:
            res["uncertainty"].setdefault(block, {}).update(value)
    res["sanity"]["losses"].extend(f["losses"])


def aggregate(
    runs: Sequence[DriveRun],
    cfg: RunConfig,
    *,
    models: Mapping[str, Mapping[str, Any]],
    traces: TraceSet | pd.DataFrame | None = None,
    statistics: Statistics | None = None,
    workers: int = 1,
) -> dict[str, Any]:
    """The figures of ``results.json``, from its key ``predictors`` on (``traces``: the
    runs' traces, in memory or on disk, :func:`~posbench.scoring.records.trace_set` if not
    given; ``models``: the learned models behind the
    predictors, per name ``{"model", "bundled", "train_drives"}``, ``{}`` for none, e.g.
    answers scored from a file, whose models posbench cannot know).

    Headline figures use the scored rows only
    (:func:`~posbench.scoring.schema.scored_mask`); the work goes one predictor at a time,
    each figure family reading its rows one drive at a time and keeping per drive a few
    numbers (:mod:`posbench.aggregation.error_figures` and its siblings), so a process
    holds no predictor's rows, let alone every answer of the run. With
    ``workers`` > 1 each predictor's figures are computed in a forked child process
    (:func:`~posbench.scenarios.forked.forked_map`, that many at a time): this process never
    reads a predictor's rows, and what a predictor's figures allocated is returned to the
    system when its child ends; the figures are the same, to the bit. Every summary gets
    its ``ci95`` and each predictor its paired comparison with the baseline as
    ``statistics`` says (default: :class:`Statistics` with baseline ``kf`` when it is in
    the run; see :mod:`posbench.aggregation.intervals`)."""
    from posbench.aggregation.sanity import REFERENCE
    from posbench.scenarios.forked import Job, forked_map

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
        "excluded": {"warmup": {}, "no_reference": {}},  # filled per predictor below
        "held_out": {},
        "held_out_all": {},
        "drives": [],
    }
    res["training_drives"] = {n: m["train_drives"] for n, m in res["models"].items()}
    trained_on = {n for names in res["training_drives"].values() for n in names}
    # which drives were scored, and whether any query fell in an outage: one predictor at a
    # time (each in a child process given workers)
    drives_of: dict[str, set[str]] = {}
    with_outages = False
    for found, outages in forked_map(functools.partial(scored_drives, ts), preds, workers):
        for ds, drive in found:
            drives_of.setdefault(ds, set()).add(drive)
        with_outages = with_outages or outages
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
    for ds in datasets:
        res["by_dataset"][ds] = {}
        res["by_label"][ds] = {}
    res["statistics"] = stats.to_dict()
    res["paired"] = {"baseline": stats.baseline, "overall": {}, "by_dataset": {}, "by_label": {}}
    res["track_errors"] = {"predictors": {}, "by_label": {}}
    res["uncertainty"] = {"none": []}
    checked = REFERENCE in preds and not ts.empty
    res["sanity"] = {"reference": REFERENCE, "checked": checked, "losses": []}
    combining = Combining(
        ts, runs, stats, datasets, with_outages, trained_on, held_ds, held_all, checked
    )
    figures = forked_map(functools.partial(predictor_figures, combining), preds, workers)
    for name, f in zip(preds, figures, strict=True):
        res["predictors"][name] = f["entry"]
        if "by_speed" in f:
            res["by_speed"][name] = f["by_speed"]
        if "outages" in f:
            res["outages"][name] = f["outages"]
        if "paired" in f:
            pr = f["paired"]
            res["paired"]["overall"][name] = pr["overall"]
            for ds in datasets:
                res["paired"]["by_dataset"].setdefault(ds, {})[name] = pr["by_dataset"][ds]
                res["paired"]["by_label"].setdefault(ds, {})[name] = pr["by_label"][ds]
        if "paired_held" in f:
            ph = f["paired_held"]
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
        for ds in datasets:
            res["by_dataset"][ds][name] = f["by_dataset"][ds]
            res["by_label"][ds][name] = f["by_label"][ds]
            if ds in res["held_out"]:
                kinds, labels = f["held_out"][ds]
                res["held_out"][ds]["predictors"][name] = kinds
                res["held_out"][ds]["by_label"][name] = labels
        if held_all:
            res["held_out_all"]["predictors"][name] = f["held_out_all"]
        for key, kinds in f["per_drive"].items():
            per_drive.setdefault(key, {})[name] = kinds
        _merge_sections(res, name, f)
    _uncertainty_in_order(res)
    empty_ci = empty_kinds(stats)["future"].get("ci95")
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
            d["predictors"] = {name: mine.get(name, empty_kinds(stats)) for name in preds}
        res["drives"].append(d)
    res["references"] = dataset_references(res["drives"])
    from posbench.aggregation.limit import imu_readers

    # the bound beside the predictors, never one; each judged against the bound that applies
    readers = imu_readers(preds, cfg.predictor_options)
    limit, per_drive_limits = Job(
        limit_figures, runs, res, stats, readers, background=workers > 1, nice=0
    ).result()
    for d, entry in zip(res["drives"], per_drive_limits, strict=True):
        if entry is not None:
            d["limit"] = entry
    if limit is not None:
        res["limit"] = limit
    res["gate"] = gate_summary(runs, cfg)
    from posbench.aggregation.outage_lengths import outage_length_section

    lengths = outage_length_section(runs, cfg, stats)  # the outage-lengths profile only
    if lengths is not None:
        res["outage_lengths"] = lengths
    for key in ("track_errors", "uncertainty", "sanity"):  # after the others, as before
        res[key] = res.pop(key)
    return res


def _uncertainty_in_order(res: dict[str, Any]) -> None:
    """The uncertainty block's keys in :func:`uncertainty_section`'s order."""
    u = res["uncertainty"]
    order = ("predictors", "by_dataset", "by_label", "by_since_fix", "curve", "none")
    res["uncertainty"] = {k: u.get(k, {}) for k in order}


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
