"""The figures of error distributions over all drives: error CDFs, mean error by speed and by
time since the last fix, and the calibration curve of reported uncertainty."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.figures.style import (
    NothingToPlot,
    colors_for,
    finite_errors,
    floor_note,
    headline,
    log_values,
    warmup_mask,
)
from posbench.metrics.accuracy import error_cdf, speed_bin_labels, speed_bin_order, summarize_groups
from posbench.metrics.outages import SINCE_FIX_CURVE_EDGES_S, since_fix_bins
from posbench.scoring.schema import COV_COLUMNS, KINDS

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    from matplotlib.figure import Figure

#: points drawn per CDF curve (evenly spaced in rank; the curve is exact at each)
CDF_POINTS = 4000


def plot_error_cdf(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Future and now error CDFs [m], one line per predictor, warm-up excluded."""
    from matplotlib.figure import Figure

    t = finite_errors(headline(traces, ["predictor", "kind", "error_m"]))
    if t.empty:
        raise NothingToPlot("no query with a known error (no reference position)")
    colors = colors_for(preds)
    fig = Figure(figsize=(11, 4), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    clipped = False
    for ax, kind in zip(axes, KINDS, strict=True):
        tk = t[t.kind == kind]
        for p, g in tk.groupby("predictor", observed=True, sort=False):
            e, c = error_cdf(g["error_m"].to_numpy(dtype=float))
            n = e.size
            if n > CDF_POINTS:  # a drawn CDF needs no more points than pixels: thin evenly
                pick = np.unique(np.linspace(0, n - 1, CDF_POINTS).astype(int))
                e, c = e[pick], c[pick]
            v, low = log_values(e)
            clipped |= low
            ax.step(v, c, where="post", label=f"{p} (n={n})", color=colors.get(p))
        if tk.empty:
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
    fig.suptitle(
        "Error distribution per predictor"
        + (" (warm-up excluded)" if warmup_mask(traces).any() else "")
    )
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


def plot_error_vs_speed(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Mean future-point error [m] per speed bin [m/s]; bins where no predictor has a query
    are dropped. Warm-up excluded."""
    from matplotlib.figure import Figure

    t = headline(traces, ["predictor", "kind", "error_m", "speed_mps"])
    fut = finite_errors(t[(t.kind == "future") & np.isfinite(t["speed_mps"].to_numpy(dtype=float))])
    if fut.empty:
        raise NothingToPlot("no query with a known speed")
    order = speed_bin_order()
    stats = {
        p: summarize_groups(
            g["error_m"].to_numpy(dtype=float),
            speed_bin_labels(g["speed_mps"].to_numpy(dtype=float)),
            order,
        )
        for p, g in fut.groupby("predictor", observed=True, sort=False)
    }
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


def plot_error_vs_since_fix(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Mean current-position error [m] by time since the last fix [s]; only for runs with
    GPS outages; bins where no predictor has a query are dropped. Warm-up excluded."""
    from matplotlib.figure import Figure

    t = headline(traces, ["predictor", "kind", "error_m", "since_fix_s", "outage"])
    now = t[t.kind == "now"]
    if not (now["outage"] >= 0).any():
        raise NothingToPlot("no GPS outage in this run")
    now = finite_errors(now[np.isfinite(now["since_fix_s"].to_numpy(dtype=float))])
    if now.empty:
        raise NothingToPlot("no current-position query with a known error")
    edges = np.asarray(SINCE_FIX_CURVE_EDGES_S, dtype=float)
    b_all = since_fix_bins(now["since_fix_s"].to_numpy(dtype=float), edges, open_last=True)
    frame = pd.DataFrame(
        {"p": now["predictor"].to_numpy(), "b": b_all, "e": now["error_m"].to_numpy(dtype=float)}
    )
    mean = frame.groupby(["p", "b"], sort=True)["e"].mean()
    used = np.unique(b_all)  # bins where some predictor has a query
    mid = 0.5 * (edges[:-1] + edges[1:])
    colors = colors_for(preds)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    clipped = False
    present = {str(x) for x in pd.unique(frame.p)}
    names = list(dict.fromkeys([p for p in preds if p in present] + list(frame.p.unique())))
    for p in names:
        m = mean.loc[p]
        ys, low = log_values(m.reindex(used).to_numpy(dtype=float))
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


def plot_calibration(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Calibration curve of the reported covariances: observed vs expected coverage of the
    p-ellipses (:func:`posbench.metrics.calibration.calibration_curve`), future and now panels, one
    line per predictor that reports covariance; the diagonal is honest, below it
    overconfident. Warm-up excluded."""
    from matplotlib.figure import Figure

    from posbench.metrics.calibration import calibration_curve, mahalanobis_sq

    cols = [
        "predictor",
        "kind",
        "x",
        "y",
        "x_ref",
        "y_ref",
        "error_m",
        "cov_xx",
        "cov_xy",
        "cov_yy",
    ]
    if any(c not in traces for c in cols):
        raise NothingToPlot("traces without covariance columns")
    t = finite_errors(headline(traces, cols))
    t = t[np.isfinite(t["cov_xx"].to_numpy(dtype=float))]
    if t.empty:
        raise NothingToPlot("no predictor reports uncertainty for an answer with a known error")
    colors = colors_for(preds)
    fig = Figure(figsize=(9, 4.5), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    present = {str(x) for x in pd.unique(t.predictor)}
    for ax, kind in zip(axes, KINDS, strict=True):
        ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="calibrated")
        rows = t[t.kind == kind]
        for p in [q for q in preds if q in present]:
            r = rows[rows.predictor == p]
            err = r[["x", "y"]].to_numpy(float) - r[["x_ref", "y_ref"]].to_numpy(float)
            curve = np.array(
                calibration_curve(mahalanobis_sq(err, r[list(COV_COLUMNS)].to_numpy(float)))
            )
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
