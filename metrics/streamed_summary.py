"""A summary of errors and its cluster-bootstrap interval from the errors one drive at a time,
holding little: what :func:`posbench.metrics.accuracy.summarize` and
:func:`posbench.metrics.bootstrap.summary_ci` give on all of them, computed in two passes.

Pass one (:meth:`StreamedSummary.add`, one drive's errors at a time, in time order): the
drive's count, sums and maximum, and its errors counted per bin
(:func:`posbench.metrics.two_pass_quantiles.value_bins`). Between the passes
(:meth:`StreamedSummary.wanted`): the resamples (as many drives as have errors), each
resample's weighted count per bin (one matrix product), and so the range of bins that holds
every order statistic a resample's median and p95 read. Pass two (:meth:`StreamedSummary.keep`):
the errors in those bins, with their drive (and, with one drive, its whole series: the block
bootstrap's). Then :meth:`StreamedSummary.summary`: counts, max, quantiles and every interval
exactly as on all the errors, to the bit; the mean and RMSE summed per drive and then exactly
(last bits only). What is held: per drive a few numbers and its bins' counts, and the errors of
a few bins. Pure numpy.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from posbench.metrics.bootstrap import QUANTILES, summary_ci
from posbench.metrics.cluster_bootstrap import (
    DEFAULT_RESAMPLES,
    LEVEL,
    cluster_weights,
    percentile_interval,
    ratio_ci,
)
from posbench.metrics.resampled_quantiles import resampled_quantiles_within
from posbench.metrics.two_pass_quantiles import BinCounts, count_bins, value_bins

_NAN2 = [math.nan, math.nan]
#: which intervals :meth:`StreamedSummary.summary` gives: every one, the mean's alone (the
#: quantiles' NaN, as ``summary_ci(quantiles=False)``), or none (no ``ci`` key)
Intervals = Literal["all", "mean", "none"]


class StreamedSummary:
    """One group of queries' error summary with its interval, one drive at a time.
    ``intervals``: which intervals it gives (:data:`Intervals`); with fewer, it holds less
    (no bins per drive; with none, no drive's series)."""

    def __init__(
        self,
        n_resamples: int = DEFAULT_RESAMPLES,
        seed: int = 0,
        level: float = LEVEL,
        intervals: Intervals = "all",
    ):
        self.resamples, self.seed, self.level = n_resamples, seed, level
        self.intervals = intervals
        self.missing = 0
        self.max = -math.inf
        #: per drive with a finite error: its count, its sum in order (the intervals'), its
        #: sum and sum of squares (pairwise), its bins and their counts
        self.counts: list[int] = []
        self.in_order: list[float] = []
        self.sums: list[float] = []
        self.squares: list[float] = []
        self.bins: list[tuple[np.ndarray, np.ndarray]] = []
        self.pooled = BinCounts(("median", 95))
        self._ranges: list[tuple[int, int, np.ndarray, np.ndarray]] | None = None
        self._kept: list[list[tuple[np.ndarray, np.ndarray]]] = []
        self._series: list[tuple[np.ndarray, np.ndarray]] = []  # one drive: its errors, times
        self._drive = -1  # pass two: the drive being kept

    @property
    def count(self) -> int:
        return int(sum(self.counts))

    def add(self, errors: np.ndarray) -> None:
        """Pass one: one drive's errors [m] (NaN: missing), in time order."""
        e = np.asarray(errors, dtype=float)
        ok = np.isfinite(e)
        self.missing += int(e.size - ok.sum())
        v = e[ok]
        if v.size == 0:
            return
        self.counts.append(int(v.size))
        self.in_order.append(float(np.bincount(np.zeros(v.size, np.intp), weights=v)[0]))
        self.sums.append(float(v.sum()))
        self.squares.append(float((v * v).sum()))
        self.max = max(self.max, float(v.max()))
        bins, counts = count_bins(value_bins(v))
        self.pooled.add_counts(bins, counts)
        if self.intervals == "all":  # the drive's own counts, 4 bytes each (half the bytes)
            wide = np.int32 if v.size < 2**31 else np.int64
            self.bins.append((bins.astype(np.int32), counts.astype(wide)))

    def _weights(self) -> np.ndarray:
        return cluster_weights(len(self.counts), self.resamples, self.seed)

    def wanted(self) -> None:
        """Between the passes: per quantile, the range of bins that holds the order
        statistics every resample reads, and each resample's weighted counts."""
        self._ranges = []
        self.pooled.wanted()
        d = len(self.counts)
        if d < 2 or self.intervals != "all":
            return
        every = np.unique(np.concatenate([b for b, _ in self.bins]))
        dense = np.zeros((d, every.size))
        for i, (b, c) in enumerate(self.bins):
            dense[i, np.searchsorted(every, b)] = c
        np.cumsum(dense, axis=1, out=dense)
        upto = self._weights().astype(np.float64) @ dense  # (B, K): count up to each bin
        del dense
        total = upto[:, -1].copy()  # copies: a view would hold the (B, K) table
        last = np.where(total > 0, total - 1.0, 0.0)
        for q in QUANTILES.values():
            r = np.floor(last * q)
            lo = (upto <= r[:, None]).sum(axis=1)
            hi = (upto <= np.minimum(r + 1.0, last)[:, None]).sum(axis=1)
            first, end = int(lo.min()), int(hi.max())
            below = upto[:, first - 1].copy() if first > 0 else np.zeros(total.size)
            self._ranges.append((int(every[first]), int(every[end]), total, below))
        self._kept = [[] for _ in self._ranges]

    def keep(self, errors: np.ndarray, times: np.ndarray | None = None) -> None:
        """Pass two: the same drive's errors, as pass one had them, and their query times
        [s] (the block bootstrap's order when there is one drive; None: as given)."""
        e = np.asarray(errors, dtype=float)
        ok = np.isfinite(e)
        v = e[ok]
        if v.size == 0:
            return
        self._drive += 1
        if len(self.counts) == 1:
            self.pooled.keep(v)
            if self.intervals == "none":
                return
            t = np.arange(v.size, dtype=float) if times is None else np.asarray(times)[ok]
            self._series.append((v, t))
            return
        assert self._ranges is not None, "keep() before wanted()"
        bins = value_bins(v)
        self.pooled.keep(v, bins)
        for kept, (a, b, _, _) in zip(self._kept, self._ranges, strict=True):
            mine = v[(bins >= a) & (bins <= b)]
            if mine.size:
                kept.append((mine, np.full(mine.size, self._drive, dtype=np.int32)))

    def summary(self) -> dict[str, Any]:
        """:func:`~posbench.metrics.accuracy.summarize` with ``ci`` (the entry of
        :func:`~posbench.metrics.bootstrap.summary_ci`, key ``clusters``; none with
        ``intervals`` "none")."""
        n = self.count
        out: dict[str, Any] = {"count": n, "missing": self.missing}
        nan = float("nan")
        if n == 0:
            out.update(mean_m=nan, median_m=nan, rmse_m=nan, p95_m=nan, max_m=nan)
            if self.intervals == "none":
                return out
            none = {"mean_m": list(_NAN2), "median_m": list(_NAN2), "p95_m": list(_NAN2)}
            return {**out, "ci": {**none, "clusters": 0, "block_len": None}}
        median, p95 = self.pooled.quantiles()
        out.update(
            mean_m=math.fsum(self.sums) / n,
            median_m=median,
            rmse_m=math.sqrt(math.fsum(self.squares) / n),
            p95_m=p95,
            max_m=self.max,
        )
        if self.intervals == "none":
            return out
        quantiles = self.intervals == "all"
        if len(self.counts) == 1:
            v, t = (np.concatenate(x) for x in zip(*self._series, strict=True))
            clusters = np.zeros(v.size, np.int64)
            one = summary_ci(v, clusters, t, self.resamples, self.seed, self.level, quantiles)
            return {**out, "ci": one}
        w = self._weights()
        ci: dict[str, Any] = {
            "mean_m": list(ratio_ci(np.array(self.in_order), np.array(self.counts), w, self.level)),
            "clusters": len(self.counts),
            "block_len": None,
        }
        if not quantiles:
            return {**out, "ci": {**ci, "median_m": list(_NAN2), "p95_m": list(_NAN2)}}
        assert self._ranges is not None
        for name, q, kept, (_, _, total, below) in zip(
            QUANTILES, QUANTILES.values(), self._kept, self._ranges, strict=True
        ):
            values = np.concatenate([v for v, _ in kept])
            units = np.concatenate([u for _, u in kept])
            order = np.argsort(values, kind="stable")
            stats = resampled_quantiles_within(values[order], units[order], w, (q,), total, below)
            ci[name] = list(percentile_interval(stats[:, 0], self.level))
        return {**out, "ci": ci}
