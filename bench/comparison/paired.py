"""NEW - OLD of one figure of two saved runs, paired over the drives both scored.

The per-drive figures come from results.json (counts, means, RMSEs, maxima) or, for the
quantiles, from the runs' traces; the statistics are :mod:`posbench.metrics.paired`: a
cluster bootstrap over the shared drives, each resample recomputing both runs on the same
drives.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from posbench.comparison.align import Metric
from posbench.metrics.cluster_bootstrap import DEFAULT_RESAMPLES, resample_counts
from posbench.metrics.paired import (
    QUANTILE_STATS,
    paired_interval,
    pooled_max_by_resample,
    pooled_mean_by_resample,
    pooled_quantile_by_resample,
    pooled_rmse_by_resample,
)
from posbench.saved_run.run import Run

#: fewest shared drives for a paired CI: with one drive, resampling drives says nothing
#: about the spread (the CI is then NaN and no gate can fail on it)
MIN_DRIVES = 2


@dataclass(frozen=True)
class PairedDifference:
    """NEW - OLD of one statistic over the drives both runs scored (positive: NEW worse),
    [m], with its 95 % CI (NaN with fewer than :data:`MIN_DRIVES` drives)."""

    old: float
    new: float
    diff: float
    lo: float
    hi: float
    drives: int

    @property
    def conclusive(self) -> bool:
        """The 95 % CI excludes 0 (False when there is no CI)."""
        return bool(self.lo > 0 or self.hi < 0)


def drive_summaries(
    run: Run, predictor: str, kind: str, dataset: str | None = None
) -> dict[tuple[str, str], Mapping[str, Any]]:
    """``(dataset, drive) -> summary`` of ``predictor``'s ``kind`` queries in every scored
    drive of ``run`` (of ``dataset`` only, if given) that has any."""
    out = {}
    for d in run.results.get("drives", []):
        if dataset is not None and str(d["dataset"]) != dataset:
            continue
        s = (d.get("predictors") or {}).get(predictor, {}).get(kind)
        if not d.get("skipped") and s and s.get("count"):
            out[(str(d["dataset"]), str(d["name"]))] = s
    return out


def drive_errors(
    run: Run, predictor: str, kind: str, drives: Sequence[tuple[str, str]]
) -> list[np.ndarray]:
    """The scored errors [m] of ``predictor`` per drive, in ``drives`` order (from traces:
    that predictor's columns only, :attr:`~posbench.saved_run.run.Run.trace_set`)."""
    tr = run.trace_set.scored(predictor, ["dataset", "drive", "kind", "error_m"])
    tr = tr[(tr["kind"] == kind).to_numpy()]
    groups = {
        (str(ds), str(dr)): g["error_m"].to_numpy(dtype=float)
        for (ds, dr), g in tr.groupby(["dataset", "drive"], observed=True, sort=False)
    }
    out = []
    for k in drives:
        e = groups.get(k, np.empty(0))
        out.append(e[np.isfinite(e)])
    return out


def _pooled(
    run: Run,
    summaries: Sequence[Mapping[str, Any]],
    predictor: str,
    metric: Metric,
    drives: Sequence[tuple[str, str]],
    weights: np.ndarray,
) -> tuple[float, np.ndarray]:
    """``metric`` of one run pooled over ``drives`` and under each resample."""
    stat = metric.stat
    if stat in QUANTILE_STATS:
        return pooled_quantile_by_resample(
            drive_errors(run, predictor, metric.kind, drives), QUANTILE_STATS[stat], weights
        )
    column = {"mean_m": "mean_m", "rmse_m": "rmse_m", "max_m": "max_m"}[stat]
    values = np.array([float(s[column]) for s in summaries])
    if stat == "max_m":
        return pooled_max_by_resample(values, weights)
    counts = np.array([float(s["count"]) for s in summaries])
    pooled = pooled_mean_by_resample if stat == "mean_m" else pooled_rmse_by_resample
    return pooled(counts, values, weights)


def paired_difference(
    old: Run,
    new: Run,
    predictor: str,
    metric: Metric,
    seed: int = 0,
    resamples: int = DEFAULT_RESAMPLES,
    dataset: str | None = None,
) -> PairedDifference | None:
    """The paired cluster-bootstrap difference of ``metric`` (NEW - OLD) for ``predictor``
    over the drives both runs scored (of ``dataset`` only, if given); None when they share
    no drive.

    ``mean_m``, ``rmse_m`` and ``max_m`` come from the per-drive summaries of results.json;
    the quantiles read the runs' ``traces.parquet`` (a :class:`DataError` if one has none)."""
    a = drive_summaries(old, predictor, metric.kind, dataset)
    b = drive_summaries(new, predictor, metric.kind, dataset)
    common = sorted(set(a) & set(b))
    if not common:
        return None
    enough = len(common) >= MIN_DRIVES
    w = (
        resample_counts(len(common), resamples, seed)
        if enough
        else np.ones((1, len(common)), dtype=np.int64)
    )
    va, ra = _pooled(old, [a[k] for k in common], predictor, metric, common, w)
    vb, rb = _pooled(new, [b[k] for k in common], predictor, metric, common, w)
    lo, hi = paired_interval(ra, rb) if enough else (math.nan, math.nan)
    return PairedDifference(va, vb, vb - va, lo, hi, len(common))
