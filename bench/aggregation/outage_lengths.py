"""Outage lengths side by side: results.json's ``outage_lengths`` (schema 1.10), for runs with
the ``outage-lengths`` dropout profile.

Per drive, each outage's length class, FDE, ATE and distance driven since the last fix
(:mod:`posbench.metrics.outage_lengths`); then, per predictor and length, the figures over
every drive's outages of that length with their 95 % intervals (cluster bootstrap over
drives; one drive: a block bootstrap over its outages in time order, as
:func:`posbench.aggregation.intervals.outage_cis` does).

The distance comes from the traces alone: the reference positions of the drive's now
queries (every ``now_step_s``, also before the outage) as a polyline, so answers scored by
``bench score`` get the same figures as a replay.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import Statistics
from posbench.config import RunConfig
from posbench.metrics.block_bootstrap import block_length, block_resample
from posbench.metrics.bootstrap import summary_ci
from posbench.metrics.cluster_bootstrap import cluster_weights, ratio_ci
from posbench.metrics.outage_lengths import (
    length_classes,
    length_figures,
    path_lengths,
    per_outage_ate,
)
from posbench.scenarios.dropouts import FIELD_OUTAGE_LENGTHS_S, FIELD_OUTAGES
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import scored_mask

#: per outage: drive index, length class [s], FDE [m], ATE [m], distance [m], last query [s]
_FIELDS = ("drive", "length_s", "fde_m", "ate_m", "distance_m", "t_end")


def length_key(length_s: float) -> str:
    """The key of one length in ``outage_lengths`` (``"1s"``, ``"60s"``)."""
    return f"{length_s:g}s"


def _reference_track(tr: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The drive's reference as (t [s], x, y [m]): the now queries' reference positions of
    one predictor (every predictor is asked the same queries), in time order."""
    now = tr[(tr["kind"] == "now").to_numpy()]
    if now.empty:
        return np.empty(0), np.empty(0), np.empty(0)
    now = now[(now["predictor"] == now["predictor"].iloc[0]).to_numpy()]
    t = now["t_query"].to_numpy(dtype=float)
    x = now["x_ref"].to_numpy(dtype=float)
    y = now["y_ref"].to_numpy(dtype=float)
    ok = np.isfinite(t) & np.isfinite(x) & np.isfinite(y)
    t, x, y = t[ok], x[ok], y[ok]
    order = np.argsort(t, kind="stable")
    t, x, y = t[order], x[order], y[order]
    first = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, dtype=bool)
    return t[first], x[first], y[first]


def drive_outages(
    run: DriveRun, index: int, preds: Sequence[str], lengths_s: Sequence[float]
) -> dict[str, pd.DataFrame]:
    """Per predictor, one row per outage of ``run`` with a scored query: the columns of
    :data:`_FIELDS` (``drive`` = ``index``, the bootstrap's cluster)."""
    if not run.has_traces or not run.outages:
        return {}
    tr = run.load_traces()
    if tr.empty:
        return {}
    bounds = np.asarray(run.outages, dtype=float).reshape(-1, 2)
    classes = length_classes(bounds[:, 1] - bounds[:, 0], lengths_s)
    t_ref, x_ref, y_ref = _reference_track(tr)
    rows = (tr["kind"] == "now").to_numpy() & scored_mask(tr) & (tr["outage"] >= 0).to_numpy()
    out: dict[str, pd.DataFrame] = {}
    for name in preds:
        mine = tr[rows & (tr["predictor"] == name).to_numpy()]
        uid, fde, ate, t_end = per_outage_ate(
            mine["error_m"].to_numpy(dtype=float),
            mine["t_query"].to_numpy(dtype=float),
            mine["outage"].to_numpy(),
        )
        dist = path_lengths(t_ref, x_ref, y_ref, bounds[uid, 0], t_end)
        out[name] = pd.DataFrame(
            {
                "drive": np.full(uid.size, index, dtype=np.int64),
                "length_s": classes[uid],
                "fde_m": fde,
                "ate_m": ate,
                "distance_m": dist,
                "t_end": t_end,
            }
        )
    return out


def _pct_ci(
    fig: np.ndarray, dist: np.ndarray, drive: np.ndarray, t_end: np.ndarray, stats: Statistics
) -> list[float]:
    """95 % interval of 100 x sum(fig) / sum(dist) [%]: resampling drives (their sums), or
    with one drive blocks of its outages in time order."""
    if fig.size == 0:
        return [float("nan"), float("nan")]
    codes, clusters = np.unique(drive, return_inverse=True)
    if codes.size > 1:
        counts = cluster_weights(codes.size, stats.resamples, stats.seed)
        units = clusters.ravel()
    else:
        order = np.argsort(t_end, kind="stable")
        fig, dist = fig[order], dist[order]
        blocks = block_resample(fig.size, block_length(fig), stats.resamples, stats.seed)
        counts, units = blocks.counts, blocks.units
    n_units = counts.shape[1]
    lo, hi = ratio_ci(
        np.bincount(units, weights=fig, minlength=n_units),
        np.bincount(units, weights=dist, minlength=n_units),
        counts,
        stats.level,
    )
    return [100.0 * lo, 100.0 * hi]


def length_entry(rows: pd.DataFrame, stats: Statistics | None) -> dict[str, Any]:
    """One predictor's figures at one length (:func:`length_figures`), with ``drives`` and,
    given ``stats``, ``ci95`` (``fde_mean_m``, ``ate_mean_m`` [m], ``fde_pct``, ``ate_pct``
    [%], ``drives``, ``block_len``)."""
    ok = rows[np.isfinite(rows[["fde_m", "ate_m", "distance_m"]].to_numpy(dtype=float)).all(1)]
    fde, ate = ok["fde_m"].to_numpy(dtype=float), ok["ate_m"].to_numpy(dtype=float)
    dist, drive = ok["distance_m"].to_numpy(dtype=float), ok["drive"].to_numpy()
    t_end = ok["t_end"].to_numpy(dtype=float)
    entry: dict[str, Any] = dict(length_figures(fde, ate, dist))
    entry["drives"] = int(np.unique(drive).size)
    if stats is None:
        return entry
    f, a = (
        summary_ci(
            x,
            drive,
            t_end,
            n_resamples=stats.resamples,
            seed=stats.seed,
            level=stats.level,
            quantiles=False,
        )
        for x in (fde, ate)
    )
    entry["ci95"] = {
        "fde_mean_m": f["mean_m"],
        "ate_mean_m": a["mean_m"],
        "fde_pct": _pct_ci(fde, dist, drive, t_end, stats),
        "ate_pct": _pct_ci(ate, dist, drive, t_end, stats),
        "drives": f["clusters"],
        "block_len": f["block_len"],
    }
    return entry


def outage_length_section(
    runs: Sequence[DriveRun], cfg: RunConfig, stats: Statistics | None
) -> dict[str, Any] | None:
    """results.json's ``outage_lengths`` for a run with the ``outage-lengths`` profile (None
    for any other): ``profile``, ``lengths_s``, ``ate`` (``"rms"``), ``drives`` (drives
    scored), ``counts`` (per length: ``length_s``, ``outages``, ``drives``: the outages cut
    at that length and the drives holding one, whether or not a query in them was scored)
    and ``predictors`` (name -> length key -> :func:`length_entry`)."""
    if cfg.dropouts != FIELD_OUTAGES:
        return None
    lengths = [float(x) for x in FIELD_OUTAGE_LENGTHS_S]
    scored = [r for r in runs if not r.skipped and r.has_traces]
    per_pred: dict[str, list[pd.DataFrame]] = {name: [] for name in cfg.predictors}
    counts = {length_key(x): {"length_s": x, "outages": 0, "drives": 0} for x in lengths}
    for i, r in enumerate(scored):
        if r.outages:
            b = np.asarray(r.outages, dtype=float).reshape(-1, 2)
            classes = length_classes(b[:, 1] - b[:, 0], lengths)
            for x in lengths:
                n = int(np.sum(classes == x))
                counts[length_key(x)]["outages"] += n
                counts[length_key(x)]["drives"] += int(n > 0)
        for name, frame in drive_outages(r, i, cfg.predictors, lengths).items():
            per_pred[name].append(frame)
    predictors: dict[str, Any] = {}
    empty = pd.DataFrame({c: pd.Series(dtype=float) for c in _FIELDS})
    for name, frames in per_pred.items():
        table = pd.concat(frames, ignore_index=True) if frames else empty
        predictors[name] = {
            length_key(x): length_entry(table[table["length_s"] == x], stats) for x in lengths
        }
    return {
        "profile": FIELD_OUTAGES,
        "lengths_s": lengths,
        "ate": "rms",
        "drives": len(scored),
        "counts": counts,
        "predictors": predictors,
    }
