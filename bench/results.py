"""Combine per-drive runs into the figures of ``results.json`` (per drive first, then combined)."""

from __future__ import annotations

import hashlib
import platform
import subprocess
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from bench.config import RunConfig
from bench.prepare import LABELS
from bench.runner import DriveRun
from metrics.accuracy import speed_bin_labels, speed_bin_order, summarize, summarize_groups
from metrics.latency import latency_summary
from metrics.outages import error_vs_since_fix, outage_scores

KINDS = ("future", "now")
#: the trace columns aggregation reads (positions are not needed once errors exist)
AGGREGATED = ("dataset", "drive", "predictor", "kind", "t_query", "error_m", "label", "speed_mps",
              "since_fix_s", "outage")
VERSIONED = ("posbench", "numpy", "scipy", "pandas", "filterpy", "onnxruntime", "rosbags", "pymap3d")


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def data_provenance(paths: Sequence[str | Path] | None, seed: int) -> list[dict[str, Any]]:
    """The ``data`` block of results.json: :func:`tree_hash` of each data path, or the built-in
    synthetic drives' generator seed when there is none."""
    if paths:
        return [tree_hash(p) for p in paths]
    return [{"path": "built-in synthetic drives", "files": 0, "bytes": 0,
             "sha256": f"generator seed {seed}"}]


def git_commit() -> str | None:
    """The commit of the posbench checkout, with ``-dirty`` if it has changes; None outside git."""
    root = Path(__file__).resolve().parents[1]
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True,
                             timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def tree_hash(path: str | Path) -> dict[str, Any]:
    """sha256 over the sorted relative paths and contents of every file at or under ``path``."""
    p = Path(path)
    files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file())
    h = hashlib.sha256()
    size = 0
    for f in files:
        h.update(str(f.relative_to(p) if f != p else f.name).encode())
        with open(f, "rb") as fh:
            while chunk := fh.read(1 << 20):
                h.update(chunk)
                size += len(chunk)
    return {"path": str(path), "files": len(files), "bytes": size, "sha256": h.hexdigest()}


def learned_models(cfg: RunConfig) -> dict[str, dict[str, Any]]:
    """Per predictor of the run that declares a learned model (``lstm``, ``lstm@mine``,
    ``lstm-authors``, ...; :meth:`~predictors.base.Predictor.model_description`): the model
    file it uses, whether that is the bundled one, and the drive names the model was
    trained on (:meth:`~predictors.base.Predictor.training_drives`), so results on those
    drives can be told apart. Each predictor is created with the run's options for it."""
    from predictors.base import Predictor
    from predictors.registry import create, predictor_class

    out: dict[str, dict[str, Any]] = {}
    for name in cfg.predictors:
        cls = predictor_class(name)
        if (cls.model_description is Predictor.model_description
                and cls.training_drives is Predictor.training_drives):
            continue  # no learned model: not worth building (an ONNX session, ...)
        pred = create(name, None, **cfg.predictor_options.get(name, {}))
        desc = pred.model_description()
        drives = list(pred.training_drives())
        if desc is None and not drives:
            continue
        desc = desc or {}
        out[name] = {"model": str(desc.get("model", "")), "bundled": bool(desc.get("bundled")),
                     "train_drives": drives}
    return out


def scored_mask(traces: pd.DataFrame) -> np.ndarray:
    """Rows that count in the headline figures: past the warm-up (see
    :func:`bench.scoring.warmup_end_s`) and with a known reference position."""
    if traces.empty:
        return np.zeros(0, dtype=bool)
    m = traces["x_ref"].notna().to_numpy() & traces["y_ref"].notna().to_numpy()
    if "warmup" in traces:
        m &= ~traces["warmup"].to_numpy(dtype=bool)
    return m


def excluded_summary(traces: pd.DataFrame, preds: Sequence[str]) -> dict[str, Any]:
    """What the headline figures leave out, per predictor and kind: warm-up queries (with
    their error summaries) and queries without a reference (beyond the truth's or the
    fixes' span: nothing to score against)."""
    out: dict[str, Any] = {"warmup": {}, "no_reference": {}}
    if traces.empty:
        return out
    no_ref = traces["x_ref"].isna() | traces["y_ref"].isna()
    warm = traces["warmup"] if "warmup" in traces else pd.Series(False, index=traces.index)
    for name in preds:
        mine = traces["predictor"] == name
        out["warmup"][name] = _kind_summaries(traces[mine & warm & ~no_ref])
        out["no_reference"][name] = {k: int((mine & no_ref & (traces["kind"] == k)).sum())
                                     for k in KINDS}
    return out


def all_traces(runs: Sequence[DriveRun]) -> pd.DataFrame:
    """Every run's per-query traces in one frame (a single run's frame is returned as is)."""
    frames = [r.traces for r in runs if not r.traces.empty]
    if len(frames) == 1:
        return frames[0]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _kind_summaries(df: pd.DataFrame) -> dict[str, Any]:
    return {k: summarize(df.loc[df["kind"] == k, "error_m"].to_numpy()) for k in KINDS}


def _label_summaries(df: pd.DataFrame) -> dict[str, Any]:
    return {kind: summarize_groups(df.loc[df["kind"] == kind, "error_m"].to_numpy(),
                                   df.loc[df["kind"] == kind, "label"].to_numpy(),
                                   order=list(LABELS))
            for kind in KINDS}


def _empty_kinds() -> dict[str, Any]:
    return {k: summarize(np.empty(0)) for k in KINDS}


def aggregate(runs: Sequence[DriveRun], cfg: RunConfig, data_manifest: list[dict[str, Any]],
              command: str, traces: pd.DataFrame | None = None,
              models: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The content of ``results.json`` (``traces``: :func:`all_traces` if already made;
    ``models``: the learned models behind the predictors, :func:`learned_models` of ``cfg``
    if None; ``{}`` for answers scored from a file, whose models posbench cannot know).

    Headline figures use the scored rows only (:func:`scored_mask`); the work goes one
    predictor at a time over just the :data:`AGGREGATED` columns of its rows, so a long run
    never holds a second full copy of its traces."""
    if traces is None:
        traces = all_traces(runs)
    preds = list(cfg.predictors)
    res: dict[str, Any] = {
        "command": command,
        "config": cfg.to_dict(),
        "versions": package_versions(),
        "git_commit": git_commit(),
        "data": data_manifest,
        "predictors": {},
        "by_dataset": {},
        "by_label": {},
        "by_speed": {},
        "outages": {},
        "models": learned_models(cfg) if models is None else models,
        "excluded": excluded_summary(traces, preds),
        "held_out": {},
        "held_out_all": {},
        "drives": [],
    }
    res["training_drives"] = {n: m["train_drives"] for n, m in res["models"].items()}
    trained_on = {n for names in res["training_drives"].values() for n in names}
    keep = scored_mask(traces)
    cols = [c for c in AGGREGATED if c in traces.columns] if not traces.empty else list(AGGREGATED)
    scored_pairs = (traces.loc[keep, ["dataset", "drive"]].drop_duplicates() if not traces.empty
                    else pd.DataFrame(columns=["dataset", "drive"]))
    datasets = sorted(set(scored_pairs["dataset"].astype(str)))
    drives_of = {ds: set(scored_pairs.loc[scored_pairs["dataset"].astype(str) == ds, "drive"]
                         .astype(str)) for ds in datasets}
    all_drives = set().union(*drives_of.values()) if drives_of else set()
    with_outages = not traces.empty and bool((traces.loc[keep, "outage"] >= 0).any())
    held_ds = [ds for ds in datasets if drives_of[ds] & trained_on]
    for ds in held_ds:
        res["held_out"][ds] = {"drives": sorted(drives_of[ds] - trained_on),
                               "excluded_training_drives": sorted(drives_of[ds] & trained_on),
                               "predictors": {}, "by_label": {}}
    held_all = bool(all_drives & trained_on) and bool(all_drives - trained_on)
    if held_all:
        res["held_out_all"] = {"drives": sorted(all_drives - trained_on), "predictors": {}}
    per_drive: dict[tuple[str, str], dict[str, Any]] = {}
    for ds in datasets:
        res["by_dataset"][ds] = {}
        res["by_label"][ds] = {}
    for name in preds:
        df = (traces.loc[keep & (traces["predictor"] == name).to_numpy(), cols]
              if not traces.empty else pd.DataFrame(columns=cols))
        entry = _kind_summaries(df) if not df.empty else _empty_kinds()
        steps = np.concatenate([r.step_ns[name] for r in runs if name in r.step_ns] or [np.empty(0)])
        queries = np.concatenate([r.query_ns[name] for r in runs if name in r.query_ns] or [np.empty(0)])
        entry["latency_us"] = latency_summary(steps)
        entry["query_us"] = latency_summary(queries)
        res["predictors"][name] = entry
        if not df.empty:
            for kind in KINDS:
                dk = df[df["kind"] == kind]
                bins = speed_bin_labels(dk["speed_mps"].to_numpy())
                res["by_speed"].setdefault(name, {})[kind] = summarize_groups(
                    dk["error_m"].to_numpy(), bins, order=speed_bin_order() + ["unknown"])
        if with_outages:
            dn = df[df["kind"] == "now"]
            code = pd.factorize(dn["drive"])[0].astype(np.int64)
            ids = np.where(dn["outage"].to_numpy() >= 0, code * 1_000_000 + dn["outage"].to_numpy(), -1)
            res["outages"][name] = {
                "since_fix": error_vs_since_fix(dn["error_m"].to_numpy(), dn["since_fix_s"].to_numpy()),
                "scores": outage_scores(dn["error_m"].to_numpy(), dn["t_query"].to_numpy(), ids),
            }
        groups = {str(ds): g for ds, g in df.groupby("dataset", sort=True, observed=True)}
        for ds in datasets:
            dfp = groups.get(ds, df.iloc[:0])
            res["by_dataset"][ds][name] = _kind_summaries(dfp)
            res["by_label"][ds][name] = _label_summaries(dfp)
            if ds in res["held_out"]:
                held = dfp[~dfp["drive"].isin(trained_on)]
                res["held_out"][ds]["predictors"][name] = _kind_summaries(held)
                res["held_out"][ds]["by_label"][name] = _label_summaries(held)
        if held_all:
            res["held_out_all"]["predictors"][name] = _kind_summaries(
                df[~df["drive"].isin(trained_on)])
        for (ds, drive), g in df.groupby(["dataset", "drive"], sort=False, observed=True):
            per_drive.setdefault((str(ds), str(drive)), {})[name] = _kind_summaries(g)
        del df, groups
    for r in runs:
        d: dict[str, Any] = {"name": r.name, "dataset": r.dataset, "reference": r.reference,
                             "duration_s": r.duration_s, "gps_fed": r.gps_count,
                             "notes": r.notes, "warnings": r.warnings, "skipped": r.skipped,
                             "trained_on": [n for n, names in res["training_drives"].items()
                                            if r.name in names],
                             "rejected": dict(r.rejected),
                             "predictors": {}}
        if not r.traces.empty:
            mine = per_drive.get((r.dataset, r.name), {})
            d["predictors"] = {name: mine.get(name, _empty_kinds()) for name in preds}
        res["drives"].append(d)
    res["gate"] = gate_summary(runs, cfg)
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
        out["predictors"][name] = {"rejected": int(sum(counts)), "fixes_fed": int(fed),
                                   "drives_with_rejections": int(sum(c > 0 for c in counts))}
    return out
