"""The ``uncertainty`` block of results.json (schema 1.4): is each predictor's reported
covariance honest?

Per predictor that reports covariance (trace columns ``cov_xx``, ``cov_xy``, ``cov_yy``)
and kind, :func:`posbench.metrics.calibration.calibration_summary` of the scored queries (the
headline rows: past warm-up, reference known) with the NEES's cluster-bootstrap CI
(drives resampled), and without CI by data set, by route type (scenario label) and by
time since the last fix (:data:`posbench.metrics.calibration.SINCE_FIX_EDGES_S`), plus the
calibration curve. A predictor without any covariance is listed under ``none``: the
report says "no uncertainty" for it, never a made-up figure.

Computed from the traces one part (drive) at a time, never holding a predictor's rows: pass
one adds each group's counts and sums (per drive, for the NEES's interval) and counts its
sqrt(det P) per bin; pass two keeps the values of the bins that hold the medians (the
sharpness: :mod:`posbench.metrics.two_pass_quantiles`), and a kind's queries when they
come from one drive (the block bootstrap's series). The figures are
:func:`~posbench.metrics.calibration.calibration_of`'s: counts, coverage, sharpness and
intervals exactly, means to rounding (summed per drive, then exactly over the drives: the
same to the bit from parts on disk as from a frame in memory).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.drive_passes import run_passes
from posbench.metrics.bootstrap import summary_ci
from posbench.metrics.calibration import (
    COVERAGE_LEVELS,
    CURVE_LEVELS,
    calibration_figures,
    ellipse_r2,
    log_det,
    log_likelihood_of,
    mahalanobis_sq,
    sharpness_from_median,
    since_fix_bin,
)
from posbench.metrics.cluster_bootstrap import DEFAULT_RESAMPLES, cluster_weights, ratio_ci
from posbench.metrics.two_pass_quantiles import BinCounts
from posbench.scoring.schema import COV_COLUMNS, KINDS
from posbench.scoring.trace_parts import category_index, text_values
from posbench.scoring.trace_set import TraceSet

COV = list(COV_COLUMNS)
NEEDED = (
    "kind",
    "dataset",
    "drive",
    "label",
    "since_fix_s",
    "x",
    "y",
    "x_ref",
    "y_ref",
    "t_query",
    *COV,
)


#: the d^2 below which a query lies inside each level's ellipse: the coverage's, the curve's
_R2 = np.asarray(ellipse_r2(np.asarray(COVERAGE_LEVELS, dtype=float)))
_CURVE_R2 = np.asarray(ellipse_r2(np.asarray(CURVE_LEVELS, dtype=float)))
_BINS = since_fix_bin(np.empty(0))[1]


def _errors(rows: pd.DataFrame) -> np.ndarray:
    """(N, 2) answer minus reference [m, ENU]."""
    err: np.ndarray = rows[["x", "y"]].to_numpy(float) - rows[["x_ref", "y_ref"]].to_numpy(float)
    return err


class _Group:
    """One group's calibration figures (a kind's queries, or those of one data set, route
    type or time since the last fix), added one part of the traces at a time."""

    def __init__(self, curve: bool = False) -> None:
        self.n = 0
        self.covered = np.zeros(len(_R2), dtype=np.int64)
        self.curve = np.zeros(len(_CURVE_R2), dtype=np.int64) if curve else None
        self.nees: list[float] = []
        self.loglik: list[float] = []
        self.area = BinCounts(("median",))  # sqrt(det P) of the queries with a finite d^2

    def add(self, d2: np.ndarray, ld: np.ndarray) -> None:
        """Pass one: a part's queries of the group (d^2, ln det P)."""
        ok = np.isfinite(d2)
        v, lv = d2[ok], ld[ok]
        self.n += v.size
        self.covered += [np.count_nonzero(v <= r) for r in _R2]
        if self.curve is not None:
            self.curve += [np.count_nonzero(v <= r) for r in _CURVE_R2]
        self.nees.append(float(v.sum()))
        self.loglik.append(float(log_likelihood_of(v, lv).sum()))
        self.area.add(_areas(lv))

    def keep(self, d2: np.ndarray, ld: np.ndarray) -> None:
        """Pass two: the same part's queries of the group."""
        self.area.keep(_areas(ld[np.isfinite(d2)]))

    def shares(self, counts: np.ndarray) -> np.ndarray:
        """Counts of queries inside as shares of the group's (NaN with none)."""
        return counts / self.n if self.n else np.full(counts.shape, np.nan)

    def figures(self, nees_ci: list[float] | None = None) -> dict[str, Any]:
        """:func:`~posbench.metrics.calibration.calibration_of`'s figures of the group."""
        n = self.n
        return calibration_figures(
            n,
            math.fsum(self.nees) / n if n else math.nan,
            self.shares(self.covered),
            sharpness_from_median(self.area.quantiles()[0]),
            math.fsum(self.loglik) / n if n else math.nan,
            nees_ci,
        )


def _areas(ld: np.ndarray) -> np.ndarray:
    """sqrt(det P) of the finite ln det P (the sharpness's median is of these)."""
    mine: np.ndarray = np.exp(0.5 * ld[np.isfinite(ld)])
    return mine


class _Kind:
    """A kind's groups, and per drive (in order of first appearance) the sum and count of
    its finite d^2: the NEES's cluster bootstrap needs nothing more."""

    def __init__(self) -> None:
        self.all = _Group(curve=True)
        self.groups: dict[str, dict[Any, _Group]] = {"dataset": {}, "label": {}, "since": {}}
        self.drives: dict[tuple[Any, Any], list[float]] = {}
        self.series: list[tuple[np.ndarray, np.ndarray]] = []  # pass two, one drive only
        #: whether the kind's finite d^2 come from one drive (then its interval is the block
        #: bootstrap's, of that drive's queries in time order): settled after pass one
        self.one_drive = False

    def add_drives(self, pairs: np.ndarray, first: list[tuple[Any, Any]], d2: np.ndarray) -> None:
        """The drives of a part's queries of the kind (``pairs``: per query, its drive's
        index in ``first``, the (dataset, drive) of each) and their d^2 sums and counts."""
        ok = np.isfinite(d2)
        sums = np.bincount(pairs[ok], weights=d2[ok], minlength=len(first))
        counts = np.bincount(pairs, weights=ok, minlength=len(first))
        for key, s, c in zip(first, sums.tolist(), counts.tolist(), strict=True):
            acc = self.drives.setdefault(key, [0.0, 0.0])
            acc[0] += s
            acc[1] += c

    def settle(self) -> None:
        """After pass one, every drive seen: :attr:`one_drive`, counted once (not once per
        drive of pass two)."""
        self.one_drive = sum(c > 0 for _, c in self.drives.values()) == 1

    def nees_ci(self) -> list[float] | None:
        """The NEES's interval (None: no query with a finite d^2)."""
        if not self.all.n:
            return None
        if self.one_drive:
            d2 = np.concatenate([s for s, _ in self.series])
            t = np.concatenate([t for _, t in self.series])
            ci = summary_ci(d2, np.zeros(d2.size, dtype=np.int64), t, quantiles=False)
            return list(ci["mean_m"])
        live = [(s, c) for s, c in self.drives.values() if c > 0]
        sums, counts = (np.array(v) for v in zip(*live, strict=True))
        w = cluster_weights(len(live), DEFAULT_RESAMPLES, 0)
        return list(ratio_ci(sums, counts.astype(np.int64), w))


def _codes(column: pd.Series) -> tuple[np.ndarray, list[Any]]:
    """A text column as indices into a list of its values (-1: missing): a categorical's
    own codes and categories, no string per row."""
    if isinstance(column.dtype, pd.CategoricalDtype):
        return column.cat.codes.to_numpy().astype(np.int64), list(column.cat.categories)
    codes, names = pd.factorize(text_values(column), use_na_sentinel=True)
    return codes, list(names)


def _grouped(rows: pd.DataFrame) -> dict[str, tuple[np.ndarray, list[Any]]]:
    """Per group column of :class:`_Kind`: each query's group (an index into the list of
    the groups' names; -1: in none), and that list."""
    since = since_fix_bin(rows["since_fix_s"].to_numpy(float))[0]
    out = {"since": (since.astype(np.int64), list(range(len(_BINS))))}
    for col in ("dataset", "label"):
        out[col] = _codes(rows[col])
    return out


def _drives(rows: pd.DataFrame) -> tuple[np.ndarray, list[tuple[Any, Any]]]:
    """Each query's drive as an index into the part's (dataset, drive) pairs, in order of
    first appearance, and those pairs."""
    (ds, ds_names), (dr, dr_names) = _codes(rows["dataset"]), _codes(rows["drive"])
    pairs, first = pd.factorize(ds * (len(dr_names) + 1) + dr)
    width = len(dr_names) + 1
    names = [(ds_names[int(f) // width], dr_names[int(f) % width]) for f in first]
    return pairs, names


class UncertaintyFigures:
    """A predictor's calibration groups per kind: a
    :class:`~posbench.aggregation.drive_passes.Family` of the scored rows."""

    columns: tuple[str, ...] = NEEDED
    scored: bool = True

    def __init__(self) -> None:
        self.kinds = {k: _Kind() for k in KINDS}
        #: whether any row reports a covariance (else the predictor is listed under none)
        self.reported = False

    def first(self, rows: pd.DataFrame) -> None:
        self._visit(rows, second=False)

    def between(self) -> bool:
        for acc in self.kinds.values():
            acc.settle()
        return self.reported

    def second(self, rows: pd.DataFrame) -> None:
        self._visit(rows, second=True)

    def _visit(self, rows: pd.DataFrame, second: bool) -> None:
        cov = rows[COV].to_numpy(float)
        self.reported = self.reported or bool(np.isfinite(cov[:, 0]).any())
        d2, ld = mahalanobis_sq(_errors(rows), cov), log_det(cov)
        del cov
        kind = category_index(rows["kind"], KINDS)
        groups = _grouped(rows)
        pairs, first = _drives(rows) if not second else (None, [])
        for i, k in enumerate(KINDS):
            mine = kind == i
            if not mine.any():
                continue
            acc, sub_d2, sub_ld = self.kinds[k], d2[mine], ld[mine]
            if not second:
                assert pairs is not None
                acc.all.add(sub_d2, sub_ld)
                acc.add_drives(pairs[mine], first, sub_d2)
            else:
                acc.all.keep(sub_d2, sub_ld)
                if acc.one_drive:
                    ok = np.isfinite(sub_d2)
                    acc.series.append((sub_d2[ok], rows["t_query"].to_numpy(float)[mine][ok]))
            for col, (codes, names) in groups.items():
                of = codes[mine]
                table = acc.groups[col]
                for j in pd.unique(of[of >= 0]):
                    sel = of == j
                    if not second:
                        table.setdefault(names[j], _Group()).add(sub_d2[sel], sub_ld[sel])
                    else:
                        table[names[j]].keep(sub_d2[sel], sub_ld[sel])

    def result(self) -> dict[str, dict[str, Any]]:
        """Per block (``predictors``, ``by_dataset``, ``by_label``, ``by_since_fix``,
        ``curve``), per kind, the figures (call only when :attr:`reported`)."""
        out: dict[str, dict[str, Any]] = {
            b: {} for b in ("predictors", "by_dataset", "by_label", "by_since_fix", "curve")
        }
        for k, acc in self.kinds.items():
            out["predictors"][k] = acc.all.figures(acc.nees_ci())
            assert acc.all.curve is not None
            shares = acc.all.shares(acc.all.curve)
            curve = zip(CURVE_LEVELS, shares, strict=True)
            out["curve"][k] = [[float(p), float(o)] for p, o in curve]
            for block, col in (("by_dataset", "dataset"), ("by_label", "label")):
                out[block][k] = {str(g): v.figures() for g, v in acc.groups[col].items()}
            since = acc.groups["since"]
            out["by_since_fix"][k] = {_BINS[b]: since[b].figures() for b in sorted(since)}
        return out


def uncertainty_available(traces: TraceSet) -> bool:
    """Whether the traces have the covariance columns (older runs, answers without them
    have not)."""
    return not traces.empty and all(c in traces for c in NEEDED)


def empty_section() -> dict[str, Any]:
    """The section before any predictor is put in."""
    blocks = ("predictors", "by_dataset", "by_label", "by_since_fix", "curve")
    return {**{b: {} for b in blocks}, "none": []}


def add_predictor(out: dict[str, Any], name: str, figures: UncertaintyFigures) -> None:
    """Predictor ``name``'s figures into section ``out`` (under ``none`` without any)."""
    if not figures.reported:
        out["none"].append(name)
        return
    for block, value in figures.result().items():
        out[block][name] = value


def uncertainty_section(traces: TraceSet, predictors: Sequence[str]) -> dict[str, Any]:
    """``{"predictors": {name: {kind: summary}}, "by_dataset": {name: {kind: {ds: summary}}},
    "by_label": {...}, "by_since_fix": {name: {kind: {bin: summary}}}, "curve": {name:
    {kind: [[expected, observed], ...]}}, "none": [names without covariance]}`` over the
    scored rows of ``traces`` (one predictor at a time). Traces without covariance columns
    (older runs, answers without them): every predictor under ``none``."""
    out = empty_section()
    if not uncertainty_available(traces):
        out["none"] = list(predictors)
        return out
    for name in predictors:
        figures = UncertaintyFigures()
        run_passes(traces, name, [figures])
        add_predictor(out, name, figures)
    return out
