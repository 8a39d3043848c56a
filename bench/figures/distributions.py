"""The figures of error distributions over all drives: error CDFs, mean error by speed and by
time since the last fix, and the calibration curve of reported uncertainty. Each reads the
traces one predictor at a time (:mod:`posbench.figures.reading`), a few columns of its rows
past the warm-up, and keeps only what it draws (a CDF's bin counts, a mean per bin, a curve)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.figures.reading import first_seen
from posbench.figures.style import (
    NothingToPlot,
    colors_for,
    finite_errors,
    floor_note,
    log_values,
    warmup_mask,
)
from posbench.metrics.accuracy import speed_bin_index, speed_bin_order
from posbench.metrics.outages import SINCE_FIX_CURVE_EDGES_S, since_fix_bins
from posbench.metrics.two_pass_quantiles import BinCounts
from posbench.scoring.schema import COV_COLUMNS, KINDS
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    from matplotlib.figure import Figure


class _CdfCounts:
    """A predictor's errors of one kind counted for its CDF, one part at a time: bin counts
    (:class:`~posbench.metrics.two_pass_quantiles.BinCounts`), minimum and maximum; no
    error held."""

    def __init__(self) -> None:
        self.bins = BinCounts(())
        self.low, self.high = math.inf, -math.inf

    def add(self, errors: np.ndarray) -> None:
        self.bins.add(errors)
        self.low = min(self.low, float(errors.min()))
        self.high = max(self.high, float(errors.max()))

    def curve(self) -> tuple[np.ndarray, np.ndarray, int]:
        """(errors [m], fractions) of the CDF as drawn (exact at each point:
        :meth:`~posbench.metrics.two_pass_quantiles.BinCounts.cdf`), and the count."""
        e, c = self.bins.cdf(self.low, self.high)
        return e, c, self.bins.total


def plot_error_cdf(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Future and now error CDFs [m], one line per predictor, warm-up excluded. Reads per
    predictor: drive, kind, error_m, warmup."""
    from matplotlib.figure import Figure

    ts = as_trace_set(traces)
    curves: dict[str, dict[str, tuple[np.ndarray, np.ndarray, int]]] = {k: {} for k in KINDS}
    firsts: dict[str, dict[str, str]] = {k: {} for k in KINDS}
    warm = False
    for p in ts.predictors():
        # one part of the traces at a time, its finite errors per kind counted in bins
        counts = {k: _CdfCounts() for k in KINDS}
        for rows in ts.pieces(p, ["drive", "kind", "error_m", "warmup"], scored=False):
            w = warmup_mask(rows)
            warm |= bool(w.any())
            e = rows["error_m"].to_numpy(dtype=float)
            keep = ~w & np.isfinite(e)
            kinds = text_values(rows["kind"])
            for kind in KINDS:
                m = keep & (kinds == kind)
                if m.any():
                    counts[kind].add(e[m])
                    firsts[kind].setdefault(p, str(rows["drive"].iloc[int(np.argmax(m))]))
        for kind in KINDS:
            if counts[kind].bins.total:
                curves[kind][p] = counts[kind].curve()
    if not any(curves.values()):
        raise NothingToPlot("no query with a known error (no reference position)")
    colors = colors_for(preds)
    fig = Figure(figsize=(11, 4), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    clipped = False
    for ax, kind in zip(axes, KINDS, strict=True):
        for p in first_seen(ts, firsts[kind]):
            e, c, n = curves[kind][p]
            v, low = log_values(e)
            clipped |= low
            ax.plot(v, c, label=f"{p} (n={n})", color=colors.get(p))
        if not curves[kind]:
            ax.text(
                0.5,
                0.5,
                f"no {kind} query with a known error",
                transform=ax.transAxes,
                ha="center",
                va="center",
            )
        else:
            ax.set_xscale("log")
            ax.legend(fontsize=8, loc="lower right")
        ax.set_title(f"{kind} error CDF")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylim(0, 1.02)
    for ax in axes:
        ax.set_xlabel("error [m] (log" + floor_note(clipped) + ")")
    axes[0].set_ylabel("fraction of queries")
    fig.suptitle("Error distribution per predictor" + (" (warm-up excluded)" if warm else ""))
    return fig


def _mean_error_axes(ax: Any, xlabel: str, ylabel: str, clipped: bool, title: str) -> None:
    """Labels, log error axis (noting a clipped floor), title, grid and legend of a
    mean-error-per-bin figure."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel + " (log" + floor_note(clipped) + ")")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def plot_error_vs_speed(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Mean future-point error [m] per speed bin [m/s]; bins where no predictor has a query
    are dropped. Warm-up excluded. Reads per predictor: drive, kind, error_m, speed_mps,
    warmup."""
    from matplotlib.figure import Figure

    ts = as_trace_set(traces)
    order = speed_bin_order()
    found: dict[str, dict[str, dict[str, float]]] = {}
    firsts: dict[str, str] = {}
    cols = ["drive", "kind", "error_m", "speed_mps", "warmup"]
    for p in ts.predictors():
        # one part of the traces at a time, each reduced to its future rows' count and sum
        # of errors per speed bin
        counts = np.zeros(len(order), dtype=np.int64)
        sums = np.zeros(len(order))
        for rows in ts.pieces(p, cols, scored=False):
            e = rows["error_m"].to_numpy(dtype=float)
            speed = rows["speed_mps"].to_numpy(dtype=float)
            keep = ~warmup_mask(rows) & (text_values(rows["kind"]) == "future")
            keep &= np.isfinite(speed) & np.isfinite(e)
            if keep.any():
                b = speed_bin_index(speed[keep])
                counts += np.bincount(b, minlength=len(order))
                sums += np.bincount(b, e[keep], minlength=len(order))
                firsts.setdefault(p, str(rows["drive"].iloc[int(np.argmax(keep))]))
        if counts.any():
            found[p] = {
                b: {"count": int(n), "mean_m": sm / n if n else np.nan}
                for b, n, sm in zip(order, counts, sums, strict=True)
            }
    if not found:
        raise NothingToPlot("no query with a known speed")
    stats = {p: found[p] for p in first_seen(ts, firsts)}
    bins = [b for b in order if any(s[b]["count"] for s in stats.values())]
    colors = colors_for(preds)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    clipped = False
    for p in [p for p in preds if p in stats] + [p for p in stats if p not in preds]:
        ys, low = log_values(np.array([stats[p][b]["mean_m"] for b in bins], dtype=float))
        clipped |= low
        ax.plot(range(len(bins)), ys, marker="o", label=p, color=colors.get(p))
    most = [max(s[b]["count"] for s in stats.values()) for b in bins]
    ax.set_xticks(
        range(len(bins)),
        [f"{b.removesuffix(' m/s')}\nn={n}" for b, n in zip(bins, most, strict=True)],
    )
    ax.set_xlim(-0.5, len(bins) - 0.5)
    _mean_error_axes(
        ax,
        "speed [m/s] (n = queries per predictor)",
        "mean future-point error [m]",
        clipped,
        "Future-point error vs speed",
    )
    return fig


def plot_error_vs_since_fix(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Mean current-position error [m] by time since the last fix [s]; only for runs with
    GPS outages; bins where no predictor has a query are dropped. Warm-up excluded. Reads
    per predictor: drive, kind, error_m, since_fix_s, outage, warmup."""
    from matplotlib.figure import Figure

    ts = as_trace_set(traces)
    edges = np.asarray(SINCE_FIX_CURVE_EDGES_S, dtype=float)
    means: dict[str, pd.Series] = {}  # predictor -> mean error [m] per occupied bin
    firsts: dict[str, str] = {}
    outages = False
    cols = ["drive", "kind", "error_m", "since_fix_s", "outage", "warmup"]
    for p in ts.predictors():
        # one part of the traces at a time, each reduced to its now-rows' count and sum of
        # errors per bin
        counts = np.zeros(edges.size - 1, dtype=np.int64)
        sums = np.zeros(edges.size - 1)
        for rows in ts.pieces(p, cols, scored=False):
            now = rows[~warmup_mask(rows) & (text_values(rows["kind"]) == "now")]
            outages |= bool((now["outage"] >= 0).any())
            now = finite_errors(now[np.isfinite(now["since_fix_s"].to_numpy(dtype=float))])
            b = since_fix_bins(now["since_fix_s"].to_numpy(dtype=float), edges, open_last=True)
            mine = b >= 0
            if mine.any():
                counts += np.bincount(b[mine], minlength=counts.size)
                e = now["error_m"].to_numpy(dtype=float)[mine]
                sums += np.bincount(b[mine], e, minlength=counts.size)
                firsts.setdefault(p, str(now["drive"].iloc[int(np.argmax(mine))]))
        if counts.any():
            used = np.flatnonzero(counts)
            means[p] = pd.Series(sums[used] / counts[used], index=used)
    if not outages:
        raise NothingToPlot("no GPS outage in this run")
    if not means:
        raise NothingToPlot("no current-position query with a known error")
    used = np.unique(np.concatenate([m.index.to_numpy() for m in means.values()]))
    mid = 0.5 * (edges[:-1] + edges[1:])
    colors = colors_for(preds)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    clipped = False
    names = list(dict.fromkeys([p for p in preds if p in means] + first_seen(ts, firsts)))
    for p in names:
        ys, low = log_values(means[p].reindex(used).to_numpy(dtype=float))
        clipped |= low
        ax.plot(mid[used], ys, marker="o", label=p, color=colors.get(p))
    if mid[used].max() > 10:
        ax.set_xscale("log")
    _mean_error_axes(
        ax,
        "time since last fix [s] (bin centres)",
        "mean current-position error [m]",
        clipped,
        "Current-position error vs time since the last fix",
    )
    return fig


def plot_calibration(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Calibration curve of the reported covariances: observed vs expected coverage of the
    p-ellipses (:func:`posbench.metrics.calibration.calibration_curve`), future and now panels, one
    line per predictor that reports covariance; the diagonal is honest, below it
    overconfident. Warm-up excluded. Reads per predictor: kind, x, y, x_ref, y_ref, error_m
    [m], cov_xx, cov_xy, cov_yy [m^2], warmup."""
    from matplotlib.figure import Figure

    from posbench.metrics.calibration import CURVE_LEVELS, coverage_counts, mahalanobis_sq

    ts = as_trace_set(traces)
    cols = ["predictor", "kind", "x", "y", "x_ref", "y_ref", "error_m", *COV_COLUMNS]
    if any(c not in ts.columns for c in cols):
        raise NothingToPlot("traces without covariance columns")
    curves: dict[str, dict[str, np.ndarray]] = {}  # predictor -> kind -> (p, observed) rows
    reports = False
    for p in ts.predictors():
        # past the warm-up with a reference, a finite error and a reported covariance, one
        # part of the traces at a time: each part reduced to how many of its rows fall in
        # each level's ellipse, per kind (the shares of the whole from added counts)
        inside = {k: np.zeros(len(CURVE_LEVELS), dtype=np.int64) for k in KINDS}
        finite = dict.fromkeys(KINDS, 0)
        kept = False
        for rows in ts.pieces(p, cols[1:]):
            keep = np.isfinite(rows["error_m"].to_numpy(dtype=float))
            keep &= np.isfinite(rows["cov_xx"].to_numpy(dtype=float))
            kept |= bool(keep.any())
            if p not in preds:
                continue
            kinds = text_values(rows["kind"])
            for kind in KINDS:
                m = keep & (kinds == kind)
                err = np.column_stack(
                    [rows[c].to_numpy(float)[m] - rows[f"{c}_ref"].to_numpy(float)[m] for c in "xy"]
                )
                cov = np.column_stack([rows[c].to_numpy(float)[m] for c in COV_COLUMNS])
                counted, n = coverage_counts(mahalanobis_sq(err, cov), CURVE_LEVELS)
                inside[kind] += counted
                finite[kind] += n
        reports |= kept
        if kept and p in preds:
            nan = np.full(len(CURVE_LEVELS), np.nan)  # a kind without such a row: no curve
            shares = {k: inside[k] / finite[k] if finite[k] else nan for k in KINDS}
            curves[p] = {k: np.column_stack([CURVE_LEVELS, shares[k]]) for k in KINDS}
    if not reports:
        raise NothingToPlot("no predictor reports uncertainty for an answer with a known error")
    colors = colors_for(preds)
    fig = Figure(figsize=(9, 4.5), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    for ax, kind in zip(axes, KINDS, strict=True):
        ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="calibrated")
        for p in [q for q in preds if q in curves]:
            curve = curves[p][kind]
            ax.plot(curve[:, 0], curve[:, 1], marker="o", ms=3, label=p, color=colors.get(p))
        ax.set_title(f"{kind}: reported ellipse vs truth")
        ax.set_xlabel("expected coverage p of the reported p-ellipse")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1.01)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("observed share of references inside")
    axes[1].legend(loc="lower right", fontsize=8)
    fig.suptitle("Calibration of reported uncertainty (below the diagonal: overconfident)")
    return fig
