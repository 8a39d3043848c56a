"""The figures of error distributions over all drives: error CDFs, mean error by speed and by
time since the last fix, and the calibration curve of reported uncertainty. Each reads the
traces one predictor at a time (:mod:`posbench.figures.reading`), a few columns of its rows
past the warm-up, and keeps only what it draws (a thinned CDF, a mean per bin, a curve)."""

from __future__ import annotations

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
from posbench.metrics.accuracy import error_cdf, speed_bin_labels, speed_bin_order, summarize_groups
from posbench.metrics.outages import SINCE_FIX_CURVE_EDGES_S, since_fix_bins
from posbench.scoring.schema import COV_COLUMNS, KINDS
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    from matplotlib.figure import Figure

#: points drawn per CDF curve (evenly spaced in rank; the curve is exact at each)
CDF_POINTS = 4000


def _cdf_curve(errors: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The error CDF of ``errors`` [m] as drawn: (errors, fractions) thinned to at most
    :data:`CDF_POINTS` points evenly spaced in rank (exact at each), and the count."""
    e, c = error_cdf(errors)
    n = e.size
    if n > CDF_POINTS:  # a drawn CDF needs no more points than pixels: thin evenly
        pick = np.unique(np.linspace(0, n - 1, CDF_POINTS).astype(int))
        e, c = e[pick], c[pick]
    return e, c, n


def plot_error_cdf(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Future and now error CDFs [m], one line per predictor, warm-up excluded. Reads per
    predictor: drive, kind, error_m, warmup."""
    from matplotlib.figure import Figure

    ts = as_trace_set(traces)
    curves: dict[str, dict[str, tuple[np.ndarray, np.ndarray, int]]] = {k: {} for k in KINDS}
    firsts: dict[str, dict[str, str]] = {k: {} for k in KINDS}
    warm = False
    for p in ts.predictors():
        # one part of the traces at a time, each reduced to its finite errors per kind
        errors: dict[str, list[np.ndarray]] = {k: [] for k in KINDS}
        for rows in ts.pieces(p, ["drive", "kind", "error_m", "warmup"], scored=False):
            w = warmup_mask(rows)
            warm |= bool(w.any())
            e = rows["error_m"].to_numpy(dtype=float)
            keep = ~w & np.isfinite(e)
            kinds = text_values(rows["kind"])
            for kind in KINDS:
                m = keep & (kinds == kind)
                if m.any():
                    errors[kind].append(e[m])
                    firsts[kind].setdefault(p, str(rows["drive"].iloc[int(np.argmax(m))]))
        for kind in KINDS:
            if errors[kind]:
                curves[kind][p] = _cdf_curve(np.concatenate(errors[kind]))
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
            ax.step(v, c, where="post", label=f"{p} (n={n})", color=colors.get(p))
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
        # one part of the traces at a time, each reduced to its future rows' errors and speeds
        errors: list[np.ndarray] = []
        speeds: list[np.ndarray] = []
        for rows in ts.pieces(p, cols, scored=False):
            e = rows["error_m"].to_numpy(dtype=float)
            speed = rows["speed_mps"].to_numpy(dtype=float)
            keep = ~warmup_mask(rows) & (text_values(rows["kind"]) == "future")
            keep &= np.isfinite(speed) & np.isfinite(e)
            if keep.any():
                errors.append(e[keep])
                speeds.append(speed[keep])
                firsts.setdefault(p, str(rows["drive"].iloc[int(np.argmax(keep))]))
        if errors:
            found[p] = summarize_groups(
                np.concatenate(errors), speed_bin_labels(np.concatenate(speeds)), order
            )
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
    counts = [max(s[b]["count"] for s in stats.values()) for b in bins]
    ax.set_xticks(
        range(len(bins)),
        [f"{b.removesuffix(' m/s')}\nn={n}" for b, n in zip(bins, counts, strict=True)],
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
        # one part of the traces at a time, each reduced to its now-rows' bins and errors
        bins: list[np.ndarray] = []
        errors: list[np.ndarray] = []
        for rows in ts.pieces(p, cols, scored=False):
            now = rows[~warmup_mask(rows) & (text_values(rows["kind"]) == "now")]
            outages |= bool((now["outage"] >= 0).any())
            now = finite_errors(now[np.isfinite(now["since_fix_s"].to_numpy(dtype=float))])
            if len(now):
                since = now["since_fix_s"].to_numpy(dtype=float)
                bins.append(since_fix_bins(since, edges, open_last=True))
                errors.append(now["error_m"].to_numpy(dtype=float))
                firsts.setdefault(p, str(now["drive"].iloc[0]))
        if bins:
            frame = pd.DataFrame({"b": np.concatenate(bins), "e": np.concatenate(errors)})
            means[p] = frame.groupby("b", sort=True)["e"].mean()
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

    from posbench.metrics.calibration import calibration_curve, mahalanobis_sq

    ts = as_trace_set(traces)
    cols = ["predictor", "kind", "x", "y", "x_ref", "y_ref", "error_m", *COV_COLUMNS]
    if any(c not in ts.columns for c in cols):
        raise NothingToPlot("traces without covariance columns")
    curves: dict[str, dict[str, np.ndarray]] = {}  # predictor -> kind -> (p, observed) rows
    reports = False
    for p in ts.predictors():
        # past the warm-up with a reference, a finite error and a reported covariance, one
        # part of the traces at a time: each part reduced to its rows' Mahalanobis distances
        # per kind (8 bytes a row), so a long run's columns are never held together
        d2: dict[str, list[np.ndarray]] = {k: [] for k in KINDS}
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
                d2[kind].append(mahalanobis_sq(err, cov))
        reports |= kept
        if kept and p in preds:
            curves[p] = {
                k: np.array(calibration_curve(np.concatenate(d2[k]) if d2[k] else np.empty(0)))
                for k in KINDS
            }
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
