"""Confidence intervals and the paired comparison, placed into the figures of ``results.json``.

The statistics themselves are pure functions of :mod:`posbench.metrics.bootstrap`; this module knows
which queries make each summary and which drive each query comes from (the cluster), and
writes:

- ``"ci95"`` inside every summary that has mean/median/p95: ``{"mean_m": [lo, hi],
  "median_m": [lo, hi], "p95_m": [lo, hi], "drives": D, "block_len": L}`` ([m]; D drives
  resampled; L queries per block when the summary comes from one drive, else None; from no
  query: null intervals, D = 0);
- ``"paired"``: each predictor against the baseline on the queries both answered
  (:func:`paired_results`);
- ``"statistics"``: how (:meth:`Statistics.to_dict`).
"""

from __future__ import annotations

import copy
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from posbench.metrics.block_bootstrap import MIN_BLOCKS
from posbench.metrics.bootstrap import group_cis, paired_summary, summary_ci
from posbench.metrics.cluster_bootstrap import DEFAULT_RESAMPLES, LEVEL
from posbench.metrics.outages import (
    MISS_THRESHOLD_M,
    outage_drive,
    per_outage,
)
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import text_values


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
    return _entry(
        summary_ci(
            errors, codes, times, n_resamples=stats.resamples, seed=stats.seed, level=stats.level
        )
    )


def _entry(r: Mapping[str, Any]) -> dict[str, Any]:
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
        out[name] = _entry(
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
    empty = _entry(summary_ci(np.empty(0), np.empty(0, dtype=np.int64)))
    for k, s in summaries.items():
        i = wanted.get(str(k))
        s["ci95"] = _entry(cis[i]) if i is not None else dict(empty)


def outage_cis(
    errors: np.ndarray, t_query: np.ndarray, ids: np.ndarray, stats: Statistics | None
) -> dict[str, Any] | None:
    """Intervals of the outage scores (ADE mean, FDE mean and p95, miss rate), resampling the
    drives the outages belong to (``ids``: :func:`posbench.metrics.outages.outage_keys`)."""
    if stats is None:
        return None
    oid, ade, fde, t_end = per_outage(errors, t_query, ids)
    drive = outage_drive(oid)
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


# --------------------------------------------------------------- paired
@dataclass(frozen=True)
class Aligned:
    """A predictor's scored rows with the baseline's error of the same query beside
    (column ``error_base``; :func:`align`), their drive codes, and whether the two lists of
    queries were the same (then ``codes`` are the predictor's own ``code`` column)."""

    rows: pd.DataFrame
    codes: np.ndarray
    same: bool

    def without(self, drives: Collection[str]) -> Aligned:
        """These rows less those of ``drives``, as :func:`align` gives them from the two
        frames less those drives, when the lists were the same (a subset of two equal lists
        is equal: the codes are the predictor's own)."""
        if not self.same:
            raise ValueError("only the rows of the same queries can be cut without their frames")
        keep = ~self.rows["drive"].isin(list(drives)).to_numpy()
        return Aligned(self.rows[keep], self.codes[keep], True)


def align(df: pd.DataFrame, base: pd.DataFrame) -> Aligned:
    """``df``'s rows with the baseline's error of the same query beside (column
    ``error_base``), and their drive codes. Traces of one run list every predictor's
    queries in the same order, so this is usually a column copy (both frames need the
    ``code`` column of :func:`drive_codes`); otherwise the queries are matched on data set,
    drive, kind and query time."""
    keys = ["dataset", "drive", "kind", "t_query"]
    same = (
        len(df) == len(base)
        and all(np.array_equal(df[k].to_numpy(), base[k].to_numpy()) for k in ("code", "t_query"))
        and np.array_equal(text_values(df["kind"]), text_values(base["kind"]))
        and all(np.array_equal(pd.unique(df[k]), pd.unique(base[k])) for k in ("dataset", "drive"))
    )
    if same:  # the same drives in the same order, the same queries in each
        # a copy: the aligned rows keep no block of the baseline's frame alive
        out = df.assign(error_base=base["error_m"].to_numpy(copy=True))
    else:
        b = base[keys + ["error_m"]].rename(columns={"error_m": "error_base"})
        out = df.merge(b, on=keys, how="inner", sort=False)
    return Aligned(out, out["code"].to_numpy() if same else drive_codes(out), bool(same))


def _paired_columns(
    df: pd.DataFrame, base: pd.DataFrame
) -> tuple[pd.DataFrame, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The queries both answered (:func:`align`), their drive codes, and as arrays their
    kind, the predictor's error, the baseline's error [m] and the query time [s]."""
    return _aligned_columns(align(df, base))


def _aligned_columns(
    aligned: Aligned,
) -> tuple[pd.DataFrame, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_paired_columns` of rows already aligned."""
    both, codes = aligned.rows, aligned.codes
    return (
        both,
        codes,
        text_values(both["kind"]),
        both["error_m"].to_numpy(dtype=float),
        both["error_base"].to_numpy(dtype=float),
        both["t_query"].to_numpy(dtype=float),
    )


def _paired(
    e_base: np.ndarray, e: np.ndarray, codes: np.ndarray, times: np.ndarray, stats: Statistics
) -> dict[str, Any]:
    r = paired_summary(
        e_base, e, codes, times, n_resamples=stats.resamples, seed=stats.seed, level=stats.level
    )
    return {
        "diff_m": r["diff_m"],
        "ci95": r["ci95"],
        "drives": r["drives"],
        "wins": r["wins"],
        "win_share": r["win_share"],
        "conclusive": r["conclusive"],
        "queries": r["queries"],
        "block_len": r["block_len"],
    }


def paired_by_dataset(
    df: pd.DataFrame, base: pd.DataFrame, datasets: Sequence[str], stats: Statistics
) -> dict[str, dict[str, Any]]:
    """``{ds: {kind: entry}}`` of :func:`paired_results` alone (no overall, no labels): one
    predictor's scored rows ``df`` against ``base`` per data set and query kind."""
    both, codes, kind, e, eb, t = _paired_columns(df, base)
    ds = text_values(both["dataset"], as_str=True)
    out: dict[str, dict[str, Any]] = {}
    for name in datasets:
        out[name] = {}
        for k in KINDS:
            m = (kind == k) & (ds == name)
            out[name][k] = _paired(eb[m], e[m], codes[m], t[m], stats)
    return out


def paired_results(
    df: pd.DataFrame, base: pd.DataFrame, datasets: Sequence[str], stats: Statistics
) -> dict[str, Any]:
    """One predictor against the baseline: its scored rows ``df`` and the baseline's
    ``base`` (both with columns dataset, drive, kind, t_query, error_m and ``code``; ``df``
    with label too): :func:`paired_aligned` of :func:`align`.

    Returns:
        ``{"overall": {kind: entry}, "by_dataset": {ds: {kind: entry}},
        "by_label": {ds: {kind: {label: entry}}}}``; entry: ``diff_m`` (predictor's mean
        error - baseline's, [m], over the queries both answered: negative = better than
        the baseline), ``ci95``, ``drives``, ``wins``, ``win_share``, ``conclusive``,
        ``queries``, ``block_len`` (see :func:`posbench.metrics.bootstrap.paired_summary`).
    """
    return paired_aligned(align(df, base), datasets, stats)


def paired_aligned(aligned: Aligned, datasets: Sequence[str], stats: Statistics) -> dict[str, Any]:
    """:func:`paired_results` of rows already aligned (:func:`align`): the baseline's frame
    need not be held while the intervals are drawn."""
    out: dict[str, Any] = {
        "overall": {},
        "by_dataset": {ds: {} for ds in datasets},
        "by_label": {ds: {} for ds in datasets},
    }
    both, codes, kind, e, eb, t = _aligned_columns(aligned)
    del aligned
    ds_code, ds_names = pd.factorize(both["dataset"])
    lab_code, lab_names = pd.factorize(both["label"])
    ds_code, lab_code = ds_code.astype(np.int32), lab_code.astype(np.int32)
    ds_index = {str(n): i for i, n in enumerate(ds_names)}
    lab_index = {str(n): i for i, n in enumerate(lab_names)}
    del both
    for k in KINDS:
        mk = kind == k
        out["overall"][k] = _paired(eb[mk], e[mk], codes[mk], t[mk], stats)
        n_kind = int(mk.sum())
        for ds in datasets:
            m = mk & (ds_code == ds_index.get(ds, -2))
            if int(m.sum()) == n_kind:  # the kind's queries are all this data set's
                out["by_dataset"][ds][k] = copy.deepcopy(out["overall"][k])
            else:
                out["by_dataset"][ds][k] = _paired(eb[m], e[m], codes[m], t[m], stats)
            out["by_label"][ds][k] = {}
            for lab in LABELS:
                ml = m & (lab_code == lab_index.get(lab, -2))
                out["by_label"][ds][k][lab] = _paired(eb[ml], e[ml], codes[ml], t[ml], stats)
    return out
