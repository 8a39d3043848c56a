"""The map figures of the most-turning drive: 40 s of its path with the predictors' future
points and zooms at the worst moments, and its reference path coloured by each predictor's
error. Each finds that drive reading a few columns one predictor at a time
(:func:`turning_drive`), then reads that drive's rows alone."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.figures.style import (
    FLOOR_M,
    TURN_LABELS,
    NothingToPlot,
    colors_for,
    finite_errors,
    gap_steps,
    headline,
    in_order,
    most_turning,
    tally_turns,
    warmup_mask,
)
from posbench.scoring.trace_parts import Keep, text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    from matplotlib.figure import Figure

PATH_WINDOW_S = 40.0
ZOOMS = 3


def _worst_moments(win: pd.DataFrame, k: int, gap_s: float) -> list[tuple[float, float, str]]:
    """Up to ``k`` (t_query [s], error [m], predictor) of the largest future errors in
    ``win``, at least ``gap_s`` apart."""
    w = finite_errors(win).sort_values("error_m", ascending=False)
    picked: list[tuple[float, float, str]] = []
    for tq, e, p in zip(
        w.t_query.to_numpy(), w.error_m.to_numpy(), w.predictor.to_numpy(), strict=True
    ):
        if all(abs(tq - q) >= gap_s for q, _, _ in picked):
            picked.append((float(tq), float(e), str(p)))
            if len(picked) == k:
                break
    return picked


def turning_drive(ts: TraceSet, known_error: bool) -> tuple[str, bool] | None:
    """The drive the map figures show: the one with the most turn / roundabout future queries
    with a reference position (``known_error``: and a finite error) past the warm-up, over
    all predictors (:func:`~posbench.figures.style.most_turning_drive` over the whole
    traces); and whether any such query is turning (else the first drive with one). None:
    no such query. Reads per predictor: drive, kind, x_ref, label, error_m, warmup."""
    turns: dict[str, int] = {}
    firsts: list[str] = []
    cols = ["drive", "kind", "x_ref", "label", "error_m", "warmup"]

    def future(t: pd.DataFrame) -> pd.DataFrame:
        keep = ~warmup_mask(t) & (text_values(t["kind"]) == "future")
        keep &= np.isfinite(t["x_ref"].to_numpy(dtype=float))
        return finite_errors(t[keep]) if known_error else t[keep]

    for p in ts.predictors():
        pieces = (future(t) for t in ts.pieces(p, cols, scored=False))
        _, first = tally_turns(pieces, turns)  # one part of the traces at a time
        if first is not None:
            firsts.append(first)
    if not firsts:
        return None
    if turns:
        return most_turning(turns), True
    order = ts.drives() if len(set(firsts)) > 1 else firsts
    return min(firsts, key=order.index), False


def drive_rows(
    ts: TraceSet,
    drive: str,
    columns: list[str],
    predictor: str | None = None,
    rows: Keep | None = None,
) -> pd.DataFrame:
    """The rows of ``drive`` past the warm-up, ``columns`` of them, every predictor's (or
    ``predictor``'s), in the traces' order; ``rows``: only those it keeps, chosen as they
    are read (:meth:`~posbench.scoring.trace_set.TraceSet.frame`: a long drive's figure
    reads the rows it draws, not the drive)."""
    return headline(ts.frame([*columns, "warmup"], predictor, drive, rows), columns)


def _future(column: Callable[[str], np.ndarray | None]) -> np.ndarray:
    """The future queries' rows (a ``rows`` of :func:`drive_rows`)."""
    kind = column("kind")
    assert kind is not None
    return np.asarray(kind == "future")


def plot_path(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """40 s of the drive with the most turn queries: reference path [m, ENU] and every
    predictor's future points; beside it, zoomed panels at the worst moments (largest future
    error of any predictor), each scaled to that error so the misses are visible. Reads the
    drive (:func:`turning_drive`), then that drive's rows: predictor, kind, t_issue, t_query
    [s], x, y, x_ref, y_ref, error_m [m], label."""
    from matplotlib.figure import Figure

    ts = as_trace_set(traces)
    picked = turning_drive(ts, known_error=False)
    if picked is None:
        raise NothingToPlot("no future query with a reference position")
    drive, has_turns = picked
    cols = ["drive", "predictor", "kind", "t_issue", "t_query", "x", "y", "x_ref", "y_ref"]
    t = drive_rows(ts, drive, [*cols, "error_m", "label"], rows=_future)
    dfd = t[np.isfinite(t["x_ref"].to_numpy(dtype=float))]
    med = (dfd.loc[dfd.label.isin(TURN_LABELS), "t_issue"] if has_turns else dfd.t_issue).median()
    tc = float(dfd.t_issue.iloc[int(np.argmin(np.abs(dfd.t_issue.to_numpy(float) - med)))])
    half = PATH_WINDOW_S / 2
    win = dfd[(dfd.t_issue > tc - half) & (dfd.t_issue < tc + half)]

    def in_window(column: Callable[[str], np.ndarray | None]) -> np.ndarray:
        tq = column("t_query")
        assert tq is not None
        return np.asarray((tq > tc - half) & (tq < tc + half + 1))

    # the reference under the window: the first predictor's rows of any kind there
    ref_rows = drive_rows(
        ts, drive, [*cols, "error_m", "label"], str(win.predictor.iloc[0]), in_window
    )
    ref = ref_rows.dropna(subset=["x_ref"]).sort_values("t_query")
    moments = _worst_moments(win, ZOOMS, gap_s=3.0)
    colors = colors_for(preds)
    present = {str(x) for x in pd.unique(win.predictor)}
    names = [p for p in preds if p in present]
    fig = Figure(figsize=(13 if moments else 7.5, 7.5), layout="constrained")
    if moments:
        gs = fig.add_gridspec(len(moments), 2, width_ratios=(2.1, 1))
        ax = fig.add_subplot(gs[:, 0])
        zooms = [fig.add_subplot(gs[i, 1]) for i in range(len(moments))]
    else:
        ax, zooms = fig.add_subplot(), []
    ax.plot(ref.x_ref, ref.y_ref, "k-", lw=1, label="reference", zorder=1)
    for p in names:
        w = win[win.predictor == p]
        ax.plot(w.x, w.y, ".", ms=3, color=colors.get(p), label=f"{p} future points")
    for i, (tq, _, _) in enumerate(moments, 1):
        r = win.loc[(win.t_query - tq).abs().idxmin()]
        ax.annotate(
            str(i),
            (r.x_ref, r.y_ref),
            xytext=(8, 8),
            textcoords="offset points",
            fontsize=11,
            fontweight="bold",
            color="crimson",
            arrowprops={"arrowstyle": "-", "color": "crimson"},
        )
    if moments:
        ax.plot(
            [],
            [],
            "-",
            color="0.4",
            lw=0.8,
            label=f"zooms 1-{len(moments)}: prediction -> reference\nat the same time (the error)",
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    span = f"t = {win.t_query.min():.0f}-{win.t_query.max():.0f} s"
    ax.set_title(f"{drive}: {span}" + (" around a turn" if has_turns else ""))
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, alpha=0.3)
    for i, (zax, (tq, err, worst)) in enumerate(zip(zooms, moments, strict=True), 1):
        _zoom_panel(zax, win, ref, tq, err, names, colors)
        zax.set_title(f"{i}: t = {tq:.1f} s, {worst} misses by {err:.2f} m", fontsize=9)
    return fig


def _zoom_panel(
    ax: Any,
    win: pd.DataFrame,
    ref: pd.DataFrame,
    tq: float,
    err: float,
    names: Sequence[str],
    colors: dict[str, Any],
) -> None:
    """One zoomed panel: a box of half-width ~2.5x the worst error around the reference at
    ``tq`` [s]; future points joined to their reference point (the error vectors)."""
    from matplotlib.collections import LineCollection

    r = win.loc[(win.t_query - tq).abs().idxmin()]
    cx, cy = float(r.x_ref), float(r.y_ref)
    hw = float(np.clip(2.5 * err, 0.05, 100.0))
    near_ref = ref[(ref.t_query - tq).abs() < 3 + 10 * hw]
    ax.plot(near_ref.x_ref, near_ref.y_ref, "k-", lw=1, zorder=1)
    near = win[(win.t_query - tq).abs() < 3 + 10 * hw]
    for p in names:
        w = near[near.predictor == p]
        seg = np.stack([w[["x", "y"]].to_numpy(float), w[["x_ref", "y_ref"]].to_numpy(float)], 1)
        # a list of (2, 2) segments, as documented (matplotlib iterates the array the same way)
        ax.add_collection(LineCollection(list(seg), colors=[colors.get(p)], lw=0.8, alpha=0.8))
        ax.plot(w.x, w.y, "o", ms=4, color=colors.get(p))
    ax.plot(near.x_ref, near.y_ref, "k.", ms=3)
    ax.set_xlim(cx - hw, cx + hw)
    ax.set_ylim(cy - hw, cy + hw)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east [m]", fontsize=8)
    ax.set_ylabel("north [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, alpha=0.3)


def plot_trajectory_error(traces: TraceSet | pd.DataFrame, preds: Sequence[str]) -> Figure:
    """The most-turning drive's reference path [m, ENU] coloured by each predictor's future
    error [m]: one panel per predictor, one shared colour scale (log when the errors span
    more than a decade). Warm-up excluded. Reads the drive (:func:`turning_drive`), then
    that drive's rows: predictor, kind, t_query [s], x_ref, y_ref, error_m [m]."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.figure import Figure

    ts = as_trace_set(traces)
    picked = turning_drive(ts, known_error=True)
    if picked is None:
        raise NothingToPlot("no future query with a known error")
    drive, _ = picked
    cols = ["drive", "predictor", "kind", "t_query", "x_ref", "y_ref", "error_m"]
    t = drive_rows(ts, drive, cols, rows=_future)
    dfd = finite_errors(t[np.isfinite(t["x_ref"].to_numpy(dtype=float))])
    names = in_order(preds, dfd.predictor)
    # the grey track: the first predictor's rows of every kind (its now queries too)
    track = drive_rows(ts, drive, cols, names[0]).dropna(subset=["x_ref"])
    track = track.sort_values("t_query")
    e_all = dfd.error_m.to_numpy(dtype=float)
    lo, hi = np.percentile(e_all, [1, 99])
    lo = max(lo, FLOOR_M)
    hi = max(hi, lo * 1.01)
    norm = LogNorm(lo, hi, clip=True) if hi / lo > 10 else Normalize(lo, hi, clip=True)
    allxy = np.vstack(
        [track[["x_ref", "y_ref"]].to_numpy(float), dfd[["x_ref", "y_ref"]].to_numpy(float)]
    )
    lo_xy, hi_xy = allxy.min(axis=0), allxy.max(axis=0)
    pad = 0.05 * max(float((hi_xy - lo_xy).max()), 1.0)
    lo_xy, hi_xy = lo_xy - pad, hi_xy + pad
    ncols = min(len(names), 3)
    nrows = -(-len(names) // ncols)
    panel_h = 4.6
    dx, dy = hi_xy - lo_xy
    panel_w = float(np.clip(panel_h * dx / dy, 2.8, 7.0))
    fig = Figure(figsize=(panel_w * ncols + 1.4, panel_h * nrows + 0.5), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True).ravel()
    lc = None
    for ax, p in zip(axes, names, strict=False):
        d = dfd[dfd.predictor == p].sort_values("t_query")
        xy = d[["x_ref", "y_ref"]].to_numpy(dtype=float)
        tq = d.t_query.to_numpy(dtype=float)
        e = d.error_m.to_numpy(dtype=float)
        ax.plot(track.x_ref, track.y_ref, "-", color="0.85", lw=4, zorder=0)
        if len(d) >= 2:
            keep = ~gap_steps(tq)  # no segment across an outage
            seg = np.stack([xy[:-1], xy[1:]], axis=1)[keep]
            lc = LineCollection(seg, cmap="viridis", norm=norm, lw=2.5, capstyle="round")
            lc.set_array(0.5 * (e[:-1] + e[1:])[keep])
            ax.add_collection(lc)
        else:  # a single answer: a dot instead of a line
            ax.scatter(xy[:, 0], xy[:, 1], c=e, cmap="viridis", norm=norm, s=12, zorder=2)
        ax.plot(*xy[0], "o", mfc="none", mec="k", ms=9, zorder=3)
        ax.annotate("start", xy[0], xytext=(6, -10), textcoords="offset points", fontsize=8)
        ax.set_title(f"{p}: mean {e.mean():.3f} m, max {e.max():.3f} m", fontsize=10)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.grid(True, alpha=0.3)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    axes[0].set_xlim(lo_xy[0], hi_xy[0])  # shared by every panel
    axes[0].set_ylim(lo_xy[1], hi_xy[1])
    sm = lc if lc is not None else ScalarMappable(norm=norm, cmap="viridis")
    extend = (
        ("both" if e_all.min() < lo else "max")
        if e_all.max() > hi
        else ("min" if e_all.min() < lo else "neither")
    )
    fig.colorbar(
        sm, ax=list(axes[: len(names)]), label="future-point error [m]", extend=extend, shrink=0.9
    )
    fig.suptitle(
        f"{drive}: reference path coloured by future-point error\n(grey: no future "
        "query there, e.g. warm-up or outage; colours clipped to the 1st-99th "
        "percentile)",
        fontsize=10,
    )
    return fig
