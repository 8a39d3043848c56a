"""Bootstrap confidence intervals for pooled error figures, resampling whole drives.

Queries inside one drive are correlated (the same stretch of road, the same filter state a
few milliseconds apart), so resampling single queries would make every interval too narrow.
Every interval here is a **cluster bootstrap**: one resample draws D clusters (drives) with
replacement from the D that contribute to a figure, the figure is recomputed over the pooled
queries of the drawn clusters (a cluster drawn twice counts twice), and the interval is the
percentile interval of the B recomputed figures. A resample is a row of integer
multiplicities, one per cluster (:func:`posbench.metrics.cluster_bootstrap.resample_counts`);
so that

- a pooled mean needs only each cluster's error sum and count: B resamples are one B x D
  matrix product (:func:`posbench.metrics.cluster_bootstrap.ratio_ci`,
  :func:`posbench.metrics.cluster_bootstrap.paired_ratio_diff`);
- a quantile (median, p95) of the pooled errors is computed exactly, as ``np.percentile``
  (linear interpolation) of each resample would give it, from the pooled errors sorted once
  with their cluster index (:mod:`posbench.metrics.resampled_quantiles`).

With one cluster (a single drive), queries are resampled in contiguous blocks instead
(circular block bootstrap, :mod:`posbench.metrics.block_bootstrap`): the blocks keep the
correlation that whole drives keep above. Everything is seeded: the same inputs and seed give
the same interval on any machine. This module gives the intervals of the figures a run
reports (:func:`summary_ci`, :func:`group_cis`, :func:`paired_summary`); the resamples and the
interval arithmetic are in :mod:`posbench.metrics.cluster_bootstrap` and
:mod:`posbench.metrics.block_bootstrap`. Pure numpy.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from typing import Any

import numpy as np

from posbench.metrics.block_bootstrap import block_length, block_resample
from posbench.metrics.cluster_bootstrap import (
    DEFAULT_RESAMPLES,
    LEVEL,
    cluster_weights,
    paired_ratio_diff,
    percentile_interval,
    ratio_ci,
)
from posbench.metrics.resampled_quantiles import resampled_quantiles_many

#: the quantiles whose intervals :func:`summary_ci` gives, with their results keys
QUANTILES = {"median_m": 0.5, "p95_m": 0.95}

#: what each figure of this module means (the report's glossary collects these)
DEFINITIONS = {
    "95 % CI": (
        "95 % confidence interval [lo, hi] of the figure beside it: percentile interval of "
        "the figure recomputed on B seeded resamples (B and the seed: the report's header). "
        "Cluster bootstrap: each resample draws, with replacement, as many "
        "drives as contribute to the figure and pools every scored query of the drawn drives "
        "(queries inside a drive are correlated, so they are never resampled one by one)."
    ),
    "block bootstrap": (
        "For a figure from a single drive: the drive's queries (in time order) are resampled "
        "as circular blocks of contiguous queries instead of drives; the block length follows "
        "the automatic rule of Politis & White (2004, corrected 2009) from the errors' "
        "autocorrelation (longer the longer errors stay correlated; at least 10 blocks per "
        "resample; for a whole drive, the longest among its predictors, so that they are "
        "resampled alike), is rounded to the block grid, and is given in queries where it is "
        "used."
    ),
    "paired difference": (
        "Δ mean = mean error of the predictor minus mean error of the baseline, over the "
        "queries both answered (negative: the predictor is better); its 95 % CI resamples "
        "drives jointly for both, so their shared difficulty cancels."
    ),
    "wins": (
        "drives (among those with paired queries) on which the predictor's mean error is "
        "below the baseline's; win share = wins / drives."
    ),
    "conclusive": (
        "`*` beside a paired difference: its 95 % CI excludes 0. `?` beside a route-type "
        "cell: not conclusive, its 95 % CI is wider than the value itself."
    ),
}


# ------------------------------------------------------------------ summaries
def _compact(clusters: np.ndarray) -> tuple[np.ndarray, int]:
    """Cluster labels as 0 .. D-1 (order of first sorted label) and D."""
    c = np.asarray(clusters)
    if c.dtype.kind in "iu" and (c.size == 0 or c.min() >= 0):
        present = np.bincount(c) > 0 if c.size else np.zeros(0, dtype=bool)
        index = (np.cumsum(present) - 1).astype(np.int32)  # half the bytes of int64
        return index[c], int(present.sum())
    uniq, inv = np.unique(c, return_inverse=True)
    return inv.ravel(), int(uniq.size)


def _time_order(values: np.ndarray, times: np.ndarray | None) -> np.ndarray:
    """Indices putting one cluster's values in time order (as given without times)."""
    if times is None:
        return np.arange(values.shape[-1])
    t = np.asarray(times, dtype=np.float64)
    if t.size < 2 or bool(np.all(t[1:] >= t[:-1])):
        return np.arange(t.size)
    return np.argsort(t, kind="stable")


def summary_ci(
    errors: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
    quantiles: bool = True,
) -> dict[str, Any]:
    """Intervals of the mean, median and p95 of the finite ``errors`` (what
    :func:`posbench.metrics.accuracy.summarize` reports), resampling ``clusters`` (e.g. the drive of
    each query); with a single cluster, a block bootstrap over the queries in time order
    (``times`` [s]; default: the order given).

    Returns:
        ``{"mean_m": [lo, hi], "median_m": [lo, hi], "p95_m": [lo, hi], "clusters": D,
        "block_len": L}``: ``block_len`` is the block length [queries] when one cluster was
        block-resampled, else None; with no finite error every interval is NaN and D = 0.
        ``quantiles`` False: the mean's interval only (median and p95 NaN, no quantile
        pass paid).
    """
    return interval_batch([(errors, clusters, times)], False, n_resamples, seed, level, quantiles)[
        0
    ]


def summary_cis(
    errors: Sequence[np.ndarray],
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> list[dict[str, Any]]:
    """:func:`summary_ci` of several error arrays over the same queries (``clusters`` and
    ``times`` shared; e.g. each predictor's errors on one drive), in one pass per set of
    resamples. With a single cluster, the series with the same number of finite errors are
    resampled alike: in blocks of the longest of their
    :func:`posbench.metrics.block_bootstrap.block_length` (so one
    series alone gets exactly what :func:`summary_ci` gives it)."""
    return interval_batch([(e, clusters, times) for e in errors], True, n_resamples, seed, level)


def group_cis(
    errors: np.ndarray,
    keys: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
    only: Collection[object] | None = None,
) -> dict[object, dict[str, Any]]:
    """:func:`summary_ci` of the errors of each distinct key (e.g. scenario label, speed
    bin, query kind; those in ``only``, given it): key -> intervals, exactly what
    :func:`summary_ci` gives each group. One group at a time: what is held beside the
    inputs is one group's rows, never a sorted copy of them all."""
    k = np.asarray(keys)
    if k.size == 0:
        return {}
    if k.dtype.kind in "iu" and k.min() >= 0:
        present: list[int] = np.flatnonzero(np.bincount(k)).tolist()
        names: list[object] = list(present)
        code, ids = k, present
    else:
        uniq, code = np.unique(k, return_inverse=True)
        code = code.ravel()
        names, ids = list(uniq.tolist()), list(range(len(uniq)))
    e, c = np.asarray(errors, dtype=np.float64), np.asarray(clusters)
    t = None if times is None else np.asarray(times, dtype=np.float64)
    out: dict[object, dict[str, Any]] = {}
    for name, i in zip(names, ids, strict=True):
        if only is not None and name not in only:
            continue
        rows = np.flatnonzero(code == i)  # in their order: each group keeps its time order
        item = (e[rows], c[rows], None if t is None else t[rows])
        del rows
        out[name] = interval_batch([item], False, n_resamples, seed, level)[0]
        del item
    return out


def interval_batch(
    items: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray | None]],
    share_blocks: bool,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
    quantiles: bool = True,
) -> list[dict[str, Any]]:
    """:func:`summary_ci` of each (errors, clusters, times) of ``items``; those that end up
    with the same resamples (as many clusters, or one cluster and the same block) share one
    quantile pass. ``share_blocks``: the items are series over the same queries, and the
    single-cluster ones of equal length use the longest of their block lengths.
    ``quantiles`` False: the means' intervals only (no quantile pass)."""
    nan2 = [float("nan"), float("nan")]
    out: list[dict[str, Any]] = []
    prepared: list[tuple[int, np.ndarray, np.ndarray | None, int]] = []
    for i, (err, clusters, times) in enumerate(items):
        e = np.asarray(err, dtype=np.float64)
        finite = np.isfinite(e)
        # every error finite: the arrays as they are, not copies
        ok: np.ndarray | slice = slice(None) if finite.all() else finite
        e = e[ok]
        out.append(
            {
                "mean_m": list(nan2),
                "median_m": list(nan2),
                "p95_m": list(nan2),
                "clusters": 0,
                "block_len": None,
            }
        )
        if e.size == 0:
            continue
        c, d = _compact(np.asarray(clusters)[ok])
        if d == 1:
            e = e[_time_order(e, None if times is None else np.asarray(times)[ok])]
            prepared.append((i, e, None, block_length(e)))
        else:
            prepared.append((i, e, c, d))
    blocks: dict[int, int] = {}
    if share_blocks:  # one block length per series length among the single-cluster series
        for _, values, codes, block_len in prepared:
            if codes is None:
                blocks[values.size] = max(blocks.get(values.size, 1), block_len)
    shared: dict[tuple[int, int], tuple[np.ndarray, list[tuple[int, np.ndarray, np.ndarray]]]] = {}
    prepared.reverse()
    while prepared:  # each item let go once its intervals are done
        i, e, codes, d = prepared.pop()
        if codes is None:
            br = block_resample(
                e.size, blocks.get(e.size, d) if share_blocks else d, n_resamples, seed
            )
            units, w, block, n_clusters = br.units, br.counts, br.block_len, 1
        else:
            units, w, block, n_clusters = codes, cluster_weights(d, n_resamples, seed), None, d
        n_units = w.shape[1]
        sums = np.bincount(units, weights=e, minlength=n_units)
        counts = np.bincount(units, minlength=n_units)
        out[i].update(
            mean_m=list(ratio_ci(sums, counts, w, level)), clusters=n_clusters, block_len=block
        )
        if not quantiles:
            continue
        order = np.argsort(e)  # ties hold equal values: any order of them gives the same
        member = (i, e[order], units[order])
        del order, e, units
        if share_blocks:  # series over the same queries share a pass when they share resamples
            shared.setdefault((id(w), member[1].size), (w, []))[1].append(member)
        else:  # a pass of its own, now: its sorted copies are gone before the next item's
            _quantile_pass(out, w, [member], level)
        del member
    for w, members in shared.values():
        _quantile_pass(out, w, members, level)
    return out


def _quantile_pass(
    out: list[dict[str, Any]],
    w: np.ndarray,
    members: list[tuple[int, np.ndarray, np.ndarray]],
    level: float,
) -> None:
    """The quantiles' intervals of ``members`` (item index, sorted values, their units),
    which share the resamples ``w``, into ``out[index]``."""
    stats = resampled_quantiles_many([(v, u) for _, v, u in members], w, tuple(QUANTILES.values()))
    for (i, _, _), st in zip(members, stats, strict=True):
        for j, figure in enumerate(QUANTILES):
            out[i][figure] = list(percentile_interval(st[:, j], level))


def paired_summary(
    errors_a: np.ndarray,
    errors_b: np.ndarray,
    clusters: np.ndarray,
    times: np.ndarray | None = None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> dict[str, object]:
    """Paired comparison of two sets of errors on the same queries (a: baseline, b: the
    predictor compared), over the queries both answered (finite in both); ``times`` [s]
    order the queries of a single cluster for its block bootstrap.

    Returns:
        ``diff_m`` (mean b - mean a: negative = b better), ``ci95`` [lo, hi] (cluster
        bootstrap over ``clusters``, or a block bootstrap of the queries in the given order
        when there is one cluster; block length from the per-query differences),
        ``drives`` (clusters with paired queries), ``wins`` (clusters where b's mean error
        is below a's), ``win_share``, ``conclusive`` (the interval excludes 0),
        ``queries`` (paired queries) and ``block_len`` (None unless block-resampled).
        With several clusters, this is :func:`paired_from_sums` of each cluster's sums.
    """
    a = np.asarray(errors_a, dtype=np.float64)
    b = np.asarray(errors_b, dtype=np.float64)
    both = np.isfinite(a) & np.isfinite(b)
    # every pair finite: the arrays as they are, not copies
    ok: np.ndarray | slice = slice(None) if both.all() else both
    del both
    a, b = a[ok], b[ok]
    if a.size == 0:
        return paired_from_sums(np.empty(0), np.empty(0), np.empty(0, dtype=np.int64))
    c, d = _compact(np.asarray(clusters)[ok])
    if d > 1:
        return paired_from_sums(
            np.bincount(c, weights=a, minlength=d),
            np.bincount(c, weights=b, minlength=d),
            np.bincount(c, minlength=d),
            n_resamples,
            seed,
            level,
        )
    # the sums as the cluster's (in the queries' given order), before the time order
    wins = int(np.bincount(c, weights=b)[0] < np.bincount(c, weights=a)[0])
    order = _time_order(a, None if times is None else np.asarray(times)[ok])
    a, b = a[order], b[order]
    br = block_resample(a.size, block_length(b - a), n_resamples, seed)
    n_units = br.counts.shape[1]
    cnt = np.bincount(br.units, minlength=n_units)
    r = paired_ratio_diff(
        np.bincount(br.units, weights=a, minlength=n_units),
        cnt,
        np.bincount(br.units, weights=b, minlength=n_units),
        cnt,
        br.counts,
        level,
    )
    return _paired_entry(r, 1, wins, int(a.size), br.block_len)


def paired_from_sums(
    sums_a: np.ndarray,
    sums_b: np.ndarray,
    counts: np.ndarray,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    level: float = LEVEL,
) -> dict[str, object]:
    """:func:`paired_summary` of queries from several clusters, from each cluster's sums of
    both sides' errors [m] over its paired queries (``counts``; clusters in the order of
    their labels, each with at least one query): all the cluster bootstrap needs, so the
    figures of many drives come from a few numbers per drive."""
    d = int(np.size(counts))
    if d == 0 or int(np.sum(counts)) == 0:
        nan = float("nan")
        return _paired_entry({"diff": nan, "lo": nan, "hi": nan}, 0, 0, 0, None)
    sums_a, sums_b = np.asarray(sums_a, dtype=np.float64), np.asarray(sums_b, dtype=np.float64)
    cnt = np.asarray(counts)
    w = cluster_weights(d, n_resamples, seed)
    r = paired_ratio_diff(sums_a, cnt, sums_b, cnt, w, level)
    wins = int(np.sum(sums_b < sums_a))  # same counts on both sides: compare the sums
    return _paired_entry(r, d, wins, int(cnt.sum()), None)


def _paired_entry(
    r: dict[str, float], drives: int, wins: int, queries: int, block: int | None
) -> dict[str, object]:
    return {
        "diff_m": r["diff"],
        "ci95": [r["lo"], r["hi"]],
        "drives": drives,
        "wins": wins,
        "win_share": wins / drives if drives else float("nan"),
        "conclusive": bool(r["lo"] > 0 or r["hi"] < 0),
        "queries": queries,
        "block_len": block,
    }
