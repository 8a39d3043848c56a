"""Confidence intervals, placed into the figures of ``results.json``.

The statistics themselves are pure functions of :mod:`posbench.metrics.bootstrap`; this module knows
which queries make each summary and which drive each query comes from (the cluster), and
writes:

- ``"ci95"`` inside every summary that has mean/median/p95: ``{"mean_m": [lo, hi],
  "median_m": [lo, hi], "p95_m": [lo, hi], "drives": D, "block_len": L}`` ([m]; D drives
  resampled; L queries per block when the summary comes from one drive, else None; from no
  query: null intervals, D = 0);
- ``"paired"``: each predictor against the baseline on the queries both answered is
  :mod:`posbench.aggregation.paired_sums`' (from per-drive sums);
- ``"statistics"``: how (:meth:`Statistics.to_dict`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from posbench.metrics.block_bootstrap import MIN_BLOCKS
from posbench.metrics.bootstrap import group_cis, summary_ci
from posbench.metrics.cluster_bootstrap import DEFAULT_RESAMPLES, LEVEL
from posbench.metrics.outages import (
    MISS_THRESHOLD_M,
    outage_drive,
    per_outage,
)


@dataclass(frozen=True)
class Statistics:
    """How the intervals of a run are computed.

    Attributes:
        baseline: predictor every other one is compared with (None: no paired comparison).
        resamples: bootstrap resamples per interval (B, >= 1000).
        seed: seed of the resampling (the same seed gives the same intervals).
        level: coverage of every interval.
    """

    baseline: str | None = None
    resamples: int = DEFAULT_RESAMPLES
    seed: int = 0
    level: float = LEVEL

    def to_dict(self) -> dict[str, Any]:
        """``results["statistics"]``."""
        return {
            "method": "cluster bootstrap over drives, percentile interval",
            "single_drive_method": "circular block bootstrap of contiguous queries "
            "(block length: Politis & White 2004/2009 automatic "
            f"rule, at least {MIN_BLOCKS} blocks per resample)",
            "resamples": self.resamples,
            "seed": self.seed,
            "level": self.level,
            "baseline": self.baseline,
        }


def drive_codes(df: pd.DataFrame) -> np.ndarray:
    """An integer per distinct (dataset, drive) of ``df``'s rows (the bootstrap clusters)."""
    if df.empty:
        return np.zeros(0, dtype=np.int64)
    ds = pd.factorize(df["dataset"])[0].astype(np.int64)
    dr = pd.factorize(df["drive"])[0].astype(np.int64)
    codes: np.ndarray = pd.factorize(ds * (int(dr.max()) + 1) + dr)[0].astype(np.int64)
    return codes


def ci_entry(
    errors: np.ndarray, codes: np.ndarray, times: np.ndarray | None, stats: Statistics
) -> dict[str, Any]:
    """The ``ci95`` dict of one summary from its queries' errors [m], drive codes, times [s]."""
    return ci95_of(
        summary_ci(
            errors, codes, times, n_resamples=stats.resamples, seed=stats.seed, level=stats.level
        )
    )


def ci95_of(r: Mapping[str, Any]) -> dict[str, Any]:
    """results.json's ``ci95`` of a summary from the intervals ``r`` of
    :func:`~posbench.metrics.bootstrap.summary_ci` (its ``clusters`` as ``drives``)."""
    return {
        "mean_m": r["mean_m"],
        "median_m": r["median_m"],
        "p95_m": r["p95_m"],
        "drives": r["clusters"],
        "block_len": r["block_len"],
    }


def one_drive_cis(
    queries: Mapping[str, tuple[np.ndarray, np.ndarray]], stats: Statistics
) -> dict[str, dict[str, Any]]:
    """``ci95`` per predictor of one drive and kind (block bootstrap): ``queries`` maps each
    predictor to its errors [m] and query times [s]. Each predictor is resampled in blocks
    of its own :func:`posbench.metrics.block_bootstrap.block_length`, so its interval does
    not depend on which other predictors share the run (a run of ``cv`` alone, or answers scored by
    ``bench score``, give ``cv`` the same interval as a run of every predictor)."""
    out: dict[str, dict[str, Any]] = {}
    for name, (errors, times) in queries.items():
        out[name] = ci95_of(
            summary_ci(
                errors,
                np.zeros(times.size, dtype=np.int64),
                times,
                n_resamples=stats.resamples,
                seed=stats.seed,
                level=stats.level,
            )
        )
    return out


def with_ci(
    summary: dict[str, Any],
    errors: np.ndarray,
    codes: np.ndarray,
    times: np.ndarray | None,
    stats: Statistics | None,
) -> dict[str, Any]:
    """``summary`` with its ``ci95`` added (unchanged when ``stats`` is None)."""
    if stats is not None:
        summary["ci95"] = ci_entry(errors, codes, times, stats)
    return summary


def add_group_cis(
    summaries: Mapping[str, dict[str, Any]],
    errors: np.ndarray,
    keys: np.ndarray,
    codes: np.ndarray,
    times: np.ndarray | None,
    stats: Statistics | None,
) -> None:
    """Add ``ci95`` to each summary of :func:`posbench.metrics.accuracy.summarize_groups` (key ->
    summary), the queries of key k being those with ``keys == k``."""
    if stats is None:
        return
    code, names = pd.factorize(np.asarray(keys))
    wanted = {str(n): i for i, n in enumerate(names) if str(n) in summaries}
    cis = group_cis(  # only the groups with a summary, one at a time
        errors,
        code,
        codes,
        times,
        n_resamples=stats.resamples,
        seed=stats.seed,
        level=stats.level,
        only=set(wanted.values()),
    )
    empty = ci95_of(summary_ci(np.empty(0), np.empty(0, dtype=np.int64)))
    for k, s in summaries.items():
        i = wanted.get(str(k))
        s["ci95"] = ci95_of(cis[i]) if i is not None else dict(empty)


def outage_cis(
    errors: np.ndarray, t_query: np.ndarray, ids: np.ndarray, stats: Statistics | None
) -> dict[str, Any] | None:
    """Intervals of the outage scores (ADE mean, FDE mean and p95, miss rate), resampling the
    drives the outages belong to (``ids``: :func:`posbench.metrics.outages.outage_keys`)."""
    if stats is None:
        return None
    oid, ade, fde, t_end = per_outage(errors, t_query, ids)
    return outage_cis_of(ade, fde, t_end, outage_drive(oid), stats)


def outage_cis_of(
    ade: np.ndarray, fde: np.ndarray, t_end: np.ndarray, drive: np.ndarray, stats: Statistics
) -> dict[str, Any]:
    """:func:`outage_cis` from each outage's ADE and FDE [m], end time [s] and drive (an
    integer per drive, in drive order)."""
    a = summary_ci(
        ade, drive, t_end, n_resamples=stats.resamples, seed=stats.seed, level=stats.level
    )
    f = summary_ci(
        fde, drive, t_end, n_resamples=stats.resamples, seed=stats.seed, level=stats.level
    )
    miss = summary_ci(
        (fde > MISS_THRESHOLD_M).astype(float),
        drive,
        t_end,
        n_resamples=stats.resamples,
        seed=stats.seed,
        level=stats.level,
    )
    return {
        "ade_mean_m": a["mean_m"],
        "fde_mean_m": f["mean_m"],
        "fde_p95_m": f["p95_m"],
        "miss_rate": miss["mean_m"],
        "drives": f["clusters"],
        "block_len": f["block_len"],
    }
