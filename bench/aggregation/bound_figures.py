"""The bound's figures from each drive's bound rows, one drive at a time.

Each replayed drive's bound (:func:`posbench.replay.limit.drive_limit`) is a frame of
:data:`~posbench.replay.limit.LIMIT_COLUMNS`, held or spilled to a Parquet part. Here a drive's
rows are read, summed into every figure they count in and dropped, twice (TrackEval's
per-sequence step, then combine): pass one counts, sums and bins each group's bounds
(:class:`~posbench.metrics.streamed_summary.StreamedSummary`: the mean's cluster-bootstrap
interval from per-drive sums), pass two keeps the few bounds the medians and p95s read. A
scope (every drive, or one data set's) holds per kind and column a summary and the per-drive
sums of its floor's uncertainty (:func:`floor_of`); the route types only their summaries. What
is held: a few numbers per drive and group, never the rows of the run (at 64 drive hours the
rows held 300 MB).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import Statistics, ci95_of
from posbench.metrics.accuracy import summarize
from posbench.metrics.streamed_summary import Intervals, StreamedSummary
from posbench.scenarios.labels import LABELS
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import category_index

#: the bound's columns: fixes only, and with the IMU [m]
BOUND_COLUMNS = ("limit_m", "limit_imu_m")


def z_of(level: float) -> float:
    """The standard normal quantile of a two-sided ``level`` interval (1.96 at 0.95)."""
    return NormalDist().inv_cdf(0.5 + level / 2.0)


def widened(ci: Any, mean: float, sd: float, level: float) -> Any:
    """``ci`` ([lo, hi] of a mean ``mean`` > 0) widened by the floor's uncertainty ``sd`` [m]
    (:func:`floor_sd`), in quadrature on the log scale: each end's log-ratio to the mean and
    ``z sd / mean`` combine as root sum of squares. A mean error stays positive however
    uncertain its floor (added in metres, a floor measured on few samples gave intervals
    below 0); to first order in the widths the same as adding ``z sd`` to each half-width.
    As it is where ``sd`` is 0 or not finite."""
    if not (sd > 0 and math.isfinite(sd)) or ci is None:
        return ci
    lo, hi = ci
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return ci
    if not (mean > 0 and lo > 0 and hi > 0):
        return ci
    extra = (z_of(level) * sd / mean) ** 2
    down = math.sqrt(math.log(mean / lo) ** 2 + extra) if lo < mean else math.sqrt(extra)
    up = math.sqrt(math.log(hi / mean) ** 2 + extra) if hi > mean else math.sqrt(extra)
    return [mean * math.exp(-down), mean * math.exp(up)]


@dataclass(frozen=True)
class DriveBound:
    """One drive's bound rows (its runs' in order) as arrays: the bound [m] per column of
    :data:`BOUND_COLUMNS` (NaN: none), ``t_query`` [s], ``kind`` (index into :data:`KINDS`),
    ``label`` (index into :data:`LABELS`; -1: none) and ``slow_sd_m2`` [m^2] (per row, the
    standard deviation of its run's measured slow floor: 0 if none)."""

    bound: dict[str, np.ndarray]
    t_query: np.ndarray
    kind: np.ndarray
    label: np.ndarray
    slow_sd_m2: np.ndarray


def drive_bounds(runs: Sequence[DriveRun]) -> Iterator[tuple[tuple[str, str], DriveBound]]:
    """Per drive with bound rows, in order of first appearance: its (data set, name) and its
    runs' rows (:class:`DriveBound`), read one drive at a time."""
    by_drive: dict[tuple[str, str], list[DriveRun]] = {}
    for r in runs:
        if r.has_limit and not r.skipped:
            by_drive.setdefault((r.dataset, r.name), []).append(r)
    for key, mine in by_drive.items():
        frames, sds = [], []
        for r in mine:
            rows = r.load_limit()
            if rows is not None and not rows.empty:
                frames.append(rows)
                sds.append(np.full(len(rows), float(r.limit_info.get("slow_var_sd_m2") or 0.0)))
        if not frames:
            continue
        rows = frames[0] if len(frames) == 1 else pd.concat(frames, ignore_index=True)
        yield (
            key,
            DriveBound(
                bound={c: rows[c].to_numpy(dtype=float) for c in BOUND_COLUMNS},
                t_query=rows["t_query"].to_numpy(dtype=float),
                kind=category_index(rows["kind"], KINDS),
                label=category_index(rows["label"], LABELS),
                slow_sd_m2=np.concatenate(sds),
            ),
        )


def _floor_terms(bound_m: np.ndarray, slow_sd_m2: np.ndarray) -> np.ndarray:
    """Per query with a bound and a floor, how far a m^2 of its slow variance moves its
    bound: ``pi sd / (4 b)`` [m] (a query's bound is ``c sqrt(V)``, ``c^2 = pi/2``)."""
    ok = np.isfinite(bound_m) & (bound_m > 0) & np.isfinite(slow_sd_m2)
    terms: np.ndarray = math.pi * slow_sd_m2[ok] / (4.0 * bound_m[ok])
    return terms


def floor_of(per_drive: np.ndarray, count: int) -> float:
    """The standard deviation [m] of a mean bound over ``count`` queries that the drives'
    measured slow floors leave, from each drive's sum of :func:`_floor_terms`
    (``per_drive``): fully correlated within a drive (one floor), independent across."""
    share = per_drive / count
    return float(np.sqrt(np.sum(share * share)))


def floor_sd(bound_m: np.ndarray, slow_sd_m2: np.ndarray, codes: np.ndarray) -> float:
    """:func:`floor_of` of the queries ``bound_m`` [m] (``slow_sd_m2`` [m^2] each, its
    drive's; ``codes`` the drives): 0 where no drive's floor was measured."""
    b = np.asarray(bound_m, dtype=float)
    sd = np.asarray(slow_sd_m2, dtype=float)
    ok = np.isfinite(b) & (b > 0) & np.isfinite(sd)
    if not ok.any() or not (sd[ok] > 0).any():
        return 0.0
    per_drive = np.bincount(np.asarray(codes)[ok], weights=_floor_terms(b, sd))
    return floor_of(per_drive, int(ok.sum()))


class _Floor:
    """:func:`floor_sd` of one group, one drive at a time: per drive its sum (in row order,
    as a bincount sums), the count of queries, whether a floor was measured."""

    def __init__(self) -> None:
        self.sums: list[float] = []  # per drive of the scope, 0 where it has none
        self.last = 0  # drives up to the last with a query: a bincount's length
        self.count = 0
        self.measured = False

    def add(self, bound_m: np.ndarray, slow_sd_m2: np.ndarray) -> None:
        terms = _floor_terms(bound_m, slow_sd_m2)
        self.sums.append(float(np.bincount(np.zeros(terms.size, np.intp), terms, 1)[0]))
        if terms.size:
            self.count += int(terms.size)
            self.last = len(self.sums)
            self.measured = self.measured or bool((terms > 0).any())

    def value(self) -> float:
        if not self.count or not self.measured:
            return 0.0
        return floor_of(np.array(self.sums[: self.last]), self.count)


class _Scope:
    """The bound's figures over one set of drives: per column and kind a summary with the
    mean's interval, and its floor's uncertainty."""

    def __init__(self, stats: Statistics | None) -> None:
        self.stats = stats
        s = stats or Statistics()
        how: Intervals = "mean" if stats is not None else "none"
        self.sums = {
            (c, k): StreamedSummary(s.resamples, s.seed, s.level, how)
            for c in BOUND_COLUMNS
            for k in KINDS
        }
        self.floors = {key: _Floor() for key in self.sums}
        self.finite = dict.fromkeys(BOUND_COLUMNS, False)

    def slices(self, d: DriveBound) -> Iterator[tuple[tuple[str, str], np.ndarray, np.ndarray]]:
        for i, k in enumerate(KINDS):
            mine = d.kind == i
            for c in BOUND_COLUMNS:
                yield (c, k), d.bound[c][mine], mine

    def first(self, d: DriveBound) -> None:
        for c in BOUND_COLUMNS:
            self.finite[c] = self.finite[c] or bool(np.isfinite(d.bound[c]).any())
        for key, e, mine in self.slices(d):
            self.sums[key].add(e)
            self.floors[key].add(e, d.slow_sd_m2[mine])

    def between(self) -> None:
        for s in self.sums.values():
            s.wanted()

    def second(self, d: DriveBound) -> None:
        for key, e, mine in self.slices(d):
            self.sums[key].keep(e, d.t_query[mine])

    def kinds(self, column: str) -> dict[str, Any] | None:
        """Per kind the bound's summary in ``column`` with ``floor_sd_m`` and its ``ci95``
        (drives resampled, as a predictor's; its median and p95 are no bound: no interval;
        the mean's widened by the floor, :func:`widened`); None when no query has one
        (e.g. no IMU)."""
        if not self.finite[column]:
            return None
        out: dict[str, Any] = {}
        for k in KINDS:
            summary = self.sums[(column, k)].summary()
            ci = summary.pop("ci", None)
            sd = self.floors[(column, k)].value()
            out[k] = {**summary, "floor_sd_m": sd}
            if self.stats is not None and ci is not None:
                out[k]["ci95"] = ci95_of(ci)
                out[k]["ci95"]["mean_m"] = widened(
                    ci["mean_m"], summary["mean_m"], sd, self.stats.level
                )
        return out

    def result(self) -> dict[str, Any]:
        """The scope's figures: per kind fixes only, and ``imu``."""
        out = self.kinds("limit_m") or {k: summarize(np.empty(0)) for k in KINDS}
        return {**out, "imu": self.kinds("limit_imu_m")}


class _Labels:
    """One data set's bound (fixes only) per kind and route type: summaries, no interval."""

    def __init__(self) -> None:
        self.sums = {
            (k, j): StreamedSummary(intervals="none") for k in KINDS for j in range(len(LABELS))
        }

    def slices(self, d: DriveBound) -> Iterator[tuple[tuple[str, int], np.ndarray]]:
        for i, k in enumerate(KINDS):
            mine = d.kind == i
            e, label = d.bound["limit_m"][mine], d.label[mine]
            for j in range(len(LABELS)):
                yield (k, j), e[label == j]

    def first(self, d: DriveBound) -> None:
        for key, e in self.slices(d):
            self.sums[key].add(e)

    def between(self) -> None:
        for s in self.sums.values():
            s.wanted()

    def second(self, d: DriveBound) -> None:
        for key, e in self.slices(d):
            self.sums[key].keep(e)

    def result(self) -> dict[str, Any]:
        return {k: {n: self.sums[(k, j)].summary() for j, n in enumerate(LABELS)} for k in KINDS}


def drive_entry(d: DriveBound) -> dict[str, Any]:
    """A drive's bound per kind, fixes only and ``imu`` (None without one): its part of
    ``drives[].limit``."""
    imu = d.bound["limit_imu_m"]
    return {
        **{k: summarize(d.bound["limit_m"][d.kind == i]) for i, k in enumerate(KINDS)},
        "imu": {k: summarize(imu[d.kind == i]) for i, k in enumerate(KINDS)}
        if np.isfinite(imu).any()
        else None,
    }


@dataclass
class BoundFigures:
    """The bound's figures of a run: ``overall`` and per data set its scope's
    (:meth:`_Scope.result`), per data set its route types', and per drive (data set, name)
    its :func:`drive_entry`."""

    overall: dict[str, Any]
    by_dataset: dict[str, dict[str, Any]]
    by_label: dict[str, dict[str, Any]]
    drives: dict[tuple[str, str], dict[str, Any]]


def bound_figures(
    runs: Sequence[DriveRun], datasets: Sequence[str], stats: Statistics | None
) -> BoundFigures | None:
    """The bound's figures over ``runs`` (per data set for those of ``datasets``), each
    drive's rows read twice, one drive at a time; None when no drive has a bound row. With
    one data set, its scope is the overall one (the same drives, the same figures)."""
    planned = list(dict.fromkeys(r.dataset for r in runs if r.has_limit and not r.skipped))
    overall = _Scope(stats)
    wanted = [ds for ds in datasets if ds in planned]
    scopes = {ds: _Scope(stats) for ds in wanted} if len(planned) > 1 else {}
    labels = {ds: _Labels() for ds in wanted}
    drives: dict[tuple[str, str], dict[str, Any]] = {}
    seen: list[str] = []

    def parts(ds: str) -> list[_Scope | _Labels]:
        """What a drive of data set ``ds`` counts in."""
        return [p for p in (overall, scopes.get(ds), labels.get(ds)) if p is not None]

    for (ds, name), d in drive_bounds(runs):
        seen.append(ds)
        drives[(ds, name)] = drive_entry(d)
        for part in parts(ds):
            part.first(d)
    if not drives:
        return None
    everything: list[_Scope | _Labels] = [overall, *scopes.values(), *labels.values()]
    for part in everything:
        part.between()
    for (ds, _), d in drive_bounds(runs):
        for part in parts(ds):
            part.second(d)
    found = set(seen)  # the data sets with bound rows
    whole = overall.result()
    by_dataset = {
        ds: dict(whole) if len(found) == 1 else scopes[ds].result() for ds in wanted if ds in found
    }
    by_label = {ds: labels[ds].result() for ds in by_dataset}
    return BoundFigures(whole, by_dataset, by_label, drives)
