"""The figures of a ``bench run``: one function per figure, one save helper.

Every figure is drawn from the per-query traces (one row per query: ``t_query`` [s] in
drive time, positions ``x, y, x_ref, y_ref`` [m] in a local ENU frame, ``error_m`` [m];
see :mod:`posbench.runner`). :func:`write_plots` writes them and never raises on thin data:
a figure with nothing to show is not written, and :class:`PlotsWritten` says why.

Figures (each written once per requested format, see :data:`FORMATS`):

- ``error_cdf``: future / now error CDFs, one line per predictor (log x);
- ``error_vs_speed``: mean future-point error per speed bin (empty bins dropped);
- ``error_vs_since_fix``: mean current-position error by time since the last fix
  (runs with GPS outages only; empty bins dropped);
- ``path``: 40 s of the most-turning drive, with zoomed panels around its worst moments;
- ``trajectory_error``: that drive's reference path coloured by each predictor's
  future-point error, one panel per predictor, one shared colour scale;
- ``drives/<drive>-error_over_time``: per drive, future-point error over drive time,
  with GPS outages, scenario labels and the warm-up shaded.

Warm-up: where the traces have a boolean ``warmup`` column (queries before a drive's
second fix), those rows are left out of every figure but the per-drive error over time,
which shades them. Old traces without the column are drawn whole.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.metrics.accuracy import error_cdf, speed_bin_labels, speed_bin_order, summarize_groups

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    from matplotlib.figure import Figure

#: the output formats :func:`write_plots` and the paper's figures can write
FORMATS = ("png", "svg", "pdf")
#: errors [m] below this are drawn at it on log axes (a log axis cannot show 0)
FLOOR_M = 1e-3
#: resolution of the summary figures and of the per-drive figures [dots per inch]
DPI = 110
DRIVE_DPI = 80
#: at most this many per-drive error-over-time figures per run (the first drives in run
#: order); the note of ``error_over_time`` says when drives were left out
MAX_DRIVE_FIGURES = 250
#: per-drive plots drawn by default: every drive of a run with up to this many, else this
#: many drives with the largest mean future-point error (``bench run --drive-plots``)
DEFAULT_DRIVE_PLOTS = 20
#: points drawn per CDF curve (evenly spaced in rank; the curve is exact at each)
CDF_POINTS = 4000
TURN_LABELS = ("turn", "roundabout")
LABEL_COLORS = {"straight": "#c7e9c0", "turn": "#fdd0a2", "roundabout": "#d4b9da",
                "start_stop": "#fff2ae", "unlabelled": "#ffffff"}
#: edges of the time-since-last-fix bins [s]
SINCE_FIX_EDGES_S = (0, 0.1, 0.2, 0.3, 0.5, 0.75, 1, 1.5, 2, 3, 4, 5, 6, 8, 10, 15, 20, 30,
                     45, 60, 90, 120, 180, 300, 600)
PATH_WINDOW_S = 40.0
ZOOMS = 3


@dataclass
class PlotsWritten:
    """What :func:`write_plots` did: every file written (all formats) and, per figure
    not written, why (figure name -> note)."""

    files: list[Path] = field(default_factory=list)
    notes: dict[str, str] = field(default_factory=dict)


class NothingToPlot(Exception):
    """A figure has no data to show; the message says why (goes into the report)."""


def check_formats(formats: Iterable[str] | str) -> tuple[str, ...]:
    """The output formats as a tuple of lower-case names from :data:`FORMATS`, in the given
    order without repeats. A string is split on commas (``"png,svg"``).

    Raises:
        ValueError: an unknown format, or none at all.
    """
    items = formats.split(",") if isinstance(formats, str) else list(formats)
    out: list[str] = []
    for f in items:
        name = str(f).strip().lower().lstrip(".")
        if name not in FORMATS:
            raise ValueError(f"unknown plot format {f!r}: use one or more of {', '.join(FORMATS)}")
        if name not in out:
            out.append(name)
    if not out:
        raise ValueError(f"no plot format given: use one or more of {', '.join(FORMATS)}")
    return tuple(out)


def shown_format(formats: Iterable[str] | str) -> str:
    """The format a report links to among ``formats``: png, else svg, else pdf (the first
    two show inline in Markdown)."""
    fmts = check_formats(formats)
    return next(f for f in FORMATS if f in fmts)


_METADATA = {"png": {"Software": None}, "svg": {"Date": None}, "pdf": {"CreationDate": None}}


def _in_order(preds: Sequence[str], column: pd.Series) -> list[str]:
    """The predictors present in ``column``: those of ``preds`` in its order, then others sorted."""
    present = {str(x) for x in pd.unique(column)}
    return [p for p in preds if p in present] + sorted(present - set(preds))


def save_figure(fig: Figure, folder: Path, stem: str, formats: Sequence[str],
                dpi: int = DPI) -> list[Path]:
    """Write ``fig`` as ``folder/stem.<fmt>`` for each format (already checked by
    :func:`check_formats`); return the paths. No timestamps in the files, so the same run
    gives the same bytes."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in formats:
        p = folder / f"{stem}.{fmt}"
        extra = {"pil_kwargs": {"compress_level": 1}} if fmt == "png" else {}  # quicker; ~10 % larger
        fig.savefig(p, format=fmt, dpi=dpi, metadata=_METADATA[fmt], **extra)
        paths.append(p)
    return paths


def most_turning_drive(fut: pd.DataFrame) -> tuple[str, bool]:
    """The drive with the most turn / roundabout queries in ``fut`` (a traces slice), and
    whether any query is turning at all (else the first drive)."""
    turns = fut[fut.label.isin(TURN_LABELS)]
    if turns.empty:
        return str(fut.drive.iloc[0]), False
    return str(turns.groupby("drive", observed=True).size().idxmax()), True


# --- helpers ------------------------------------------------------------------------------


def _colors(preds: Sequence[str]) -> dict[str, Any]:
    """One colour per predictor, the same in every figure."""
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return {p: cmap(i % 10) for i, p in enumerate(preds)}


def _warmup(traces: pd.DataFrame) -> np.ndarray:
    """Boolean mask of the warm-up rows (all False without a ``warmup`` column)."""
    if "warmup" not in traces.columns:
        return np.zeros(len(traces), dtype=bool)
    return traces["warmup"].fillna(False).astype(bool).to_numpy()


def headline(traces: pd.DataFrame, columns: Sequence[str] | None = None) -> pd.DataFrame:
    """The rows the headline figures use: all but the warm-up (only ``columns`` of them, if
    given: filtering a few columns of a long run is much cheaper than all of them)."""
    if columns is not None:
        traces = traces[[c for c in dict.fromkeys([*columns, "warmup"]) if c in traces.columns]]
    w = _warmup(traces)
    return traces[~w] if w.any() else traces


def _log_values(e: np.ndarray) -> tuple[np.ndarray, bool]:
    """Errors [m] ready for a log axis: values below :data:`FLOOR_M` raised to it; and
    whether any was."""
    low = e < FLOOR_M
    return (np.where(low, FLOOR_M, e), bool(low.any()))


def _floor_note(clipped: bool) -> str:
    return f"; < {1000 * FLOOR_M:g} mm drawn at {1000 * FLOOR_M:g} mm" if clipped else ""


def _finite(df: pd.DataFrame) -> pd.DataFrame:
    return df[np.isfinite(df["error_m"].to_numpy(dtype=float))]


def _gaps(t: np.ndarray) -> np.ndarray:
    """Mask of the steps between consecutive sorted query times ``t`` [s] that span a gap
    (an outage: longer than 2 s and than 5 median steps); lines are not drawn across them."""
    dt = np.diff(t)
    if dt.size == 0:
        return np.zeros(0, dtype=bool)
    return dt > max(2.0, 5 * float(np.median(dt)))


def _safe_name(name: str) -> str:
    """A drive name usable as a file name (no path separators or odd characters)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "drive"


# --- the figures --------------------------------------------------------------------------


def plot_error_cdf(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Future and now error CDFs [m], one line per predictor, warm-up excluded."""
    from matplotlib.figure import Figure

    t = _finite(headline(traces, ["predictor", "kind", "error_m"]))
    if t.empty:
        raise NothingToPlot("no query with a known error (no reference position)")
    colors = _colors(preds)
    fig = Figure(figsize=(11, 4), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    clipped = False
    for ax, kind in zip(axes, ("future", "now"), strict=True):
        tk = t[t.kind == kind]
        for p, g in tk.groupby("predictor", observed=True, sort=False):
            e, c = error_cdf(g["error_m"].to_numpy(dtype=float))
            n = e.size
            if n > CDF_POINTS:  # a drawn CDF needs no more points than pixels: thin evenly
                pick = np.unique(np.linspace(0, n - 1, CDF_POINTS).astype(int))
                e, c = e[pick], c[pick]
            v, low = _log_values(e)
            clipped |= low
            ax.step(v, c, where="post", label=f"{p} (n={n})", color=colors.get(p))
        if tk.empty:
            ax.text(0.5, 0.5, f"no {kind} query with a known error", transform=ax.transAxes,
                    ha="center", va="center")
        else:
            ax.set_xscale("log")
            ax.legend(fontsize=8, loc="lower right")
        ax.set_title(f"{kind} error CDF")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylim(0, 1.02)
    for ax in axes:
        ax.set_xlabel("error [m] (log" + _floor_note(clipped) + ")")
    axes[0].set_ylabel("fraction of queries")
    fig.suptitle("Error distribution per predictor"
                 + (" (warm-up excluded)" if _warmup(traces).any() else ""))
    return fig


def _mean_error_axes(ax: Any, xlabel: str, ylabel: str, clipped: bool, title: str) -> None:
    """Labels, log error axis (noting a clipped floor), title, grid and legend of a
    mean-error-per-bin figure."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel + " (log" + _floor_note(clipped) + ")")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def plot_error_vs_speed(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Mean future-point error [m] per speed bin [m/s]; bins where no predictor has a query
    are dropped. Warm-up excluded."""
    from matplotlib.figure import Figure

    t = headline(traces, ["predictor", "kind", "error_m", "speed_mps"])
    fut = _finite(t[(t.kind == "future") & np.isfinite(t["speed_mps"].to_numpy(dtype=float))])
    if fut.empty:
        raise NothingToPlot("no query with a known speed")
    order = speed_bin_order()
    stats = {p: summarize_groups(g["error_m"].to_numpy(dtype=float),
                                 speed_bin_labels(g["speed_mps"].to_numpy(dtype=float)), order)
             for p, g in fut.groupby("predictor", observed=True, sort=False)}
    bins = [b for b in order if any(s[b]["count"] for s in stats.values())]
    colors = _colors(preds)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    clipped = False
    for p in [p for p in preds if p in stats] + [p for p in stats if p not in preds]:
        ys, low = _log_values(np.array([stats[p][b]["mean_m"] for b in bins], dtype=float))
        clipped |= low
        ax.plot(range(len(bins)), ys, marker="o", label=p, color=colors.get(p))
    counts = [max(s[b]["count"] for s in stats.values()) for b in bins]
    ax.set_xticks(range(len(bins)), [f"{b.removesuffix(' m/s')}\nn={n}"
                                     for b, n in zip(bins, counts, strict=True)])
    ax.set_xlim(-0.5, len(bins) - 0.5)
    _mean_error_axes(ax, "speed [m/s] (n = queries per predictor)",
                     "mean future-point error [m]", clipped, "Future-point error vs speed")
    return fig


def plot_error_vs_since_fix(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Mean current-position error [m] by time since the last fix [s]; only for runs with
    GPS outages; bins where no predictor has a query are dropped. Warm-up excluded."""
    from matplotlib.figure import Figure

    t = headline(traces, ["predictor", "kind", "error_m", "since_fix_s", "outage"])
    now = t[t.kind == "now"]
    if not (now["outage"] >= 0).any():
        raise NothingToPlot("no GPS outage in this run")
    now = _finite(now[np.isfinite(now["since_fix_s"].to_numpy(dtype=float))])
    if now.empty:
        raise NothingToPlot("no current-position query with a known error")
    edges = np.asarray(SINCE_FIX_EDGES_S, dtype=float)
    b_all = np.digitize(now["since_fix_s"].to_numpy(dtype=float), edges) - 1
    b_all = np.where(b_all >= edges.size - 1, edges.size - 2, b_all)  # last bin open-ended
    frame = pd.DataFrame({"p": now["predictor"].to_numpy(), "b": b_all,
                          "e": now["error_m"].to_numpy(dtype=float)})
    mean = frame.groupby(["p", "b"], sort=True)["e"].mean()
    used = np.unique(b_all)  # bins where some predictor has a query
    mid = 0.5 * (edges[:-1] + edges[1:])
    colors = _colors(preds)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    clipped = False
    present = {str(x) for x in pd.unique(frame.p)}
    names = list(dict.fromkeys([p for p in preds if p in present] + list(frame.p.unique())))
    for p in names:
        m = mean.loc[p]
        ys, low = _log_values(m.reindex(used).to_numpy(dtype=float))
        clipped |= low
        ax.plot(mid[used], ys, marker="o", label=p, color=colors.get(p))
    if mid[used].max() > 10:
        ax.set_xscale("log")
    _mean_error_axes(ax, "time since last fix [s] (bin centres)",
                     "mean current-position error [m]", clipped,
                     "Current-position error vs time since the last fix")
    return fig


def _worst_moments(win: pd.DataFrame, k: int, gap_s: float) -> list[tuple[float, float, str]]:
    """Up to ``k`` (t_query [s], error [m], predictor) of the largest future errors in
    ``win``, at least ``gap_s`` apart."""
    w = _finite(win).sort_values("error_m", ascending=False)
    picked: list[tuple[float, float, str]] = []
    for tq, e, p in zip(w.t_query.to_numpy(), w.error_m.to_numpy(), w.predictor.to_numpy(),
                        strict=True):
        if all(abs(tq - q) >= gap_s for q, _, _ in picked):
            picked.append((float(tq), float(e), str(p)))
            if len(picked) == k:
                break
    return picked


def plot_path(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """40 s of the drive with the most turn queries: reference path [m, ENU] and every
    predictor's future points; beside it, zoomed panels at the worst moments (largest future
    error of any predictor), each scaled to that error so the misses are visible."""
    from matplotlib.figure import Figure

    t = headline(traces, ["drive", "predictor", "kind", "t_issue", "t_query", "x", "y", "x_ref",
                          "y_ref", "error_m", "label"])
    fut = t[(t.kind == "future") & np.isfinite(t["x_ref"].to_numpy(dtype=float))]
    if fut.empty:
        raise NothingToPlot("no future query with a reference position")
    drive, has_turns = most_turning_drive(fut)
    dfd = fut[fut.drive == drive]
    med = (dfd.loc[dfd.label.isin(TURN_LABELS), "t_issue"] if has_turns else dfd.t_issue).median()
    tc = float(dfd.t_issue.iloc[int(np.argmin(np.abs(dfd.t_issue.to_numpy(float) - med)))])
    half = PATH_WINDOW_S / 2
    win = dfd[(dfd.t_issue > tc - half) & (dfd.t_issue < tc + half)]
    ref_rows = t[(t.drive == drive) & (t.predictor == win.predictor.iloc[0])
                 & (t.t_query > tc - half) & (t.t_query < tc + half + 1)]
    ref = ref_rows.dropna(subset=["x_ref"]).sort_values("t_query")
    moments = _worst_moments(win, ZOOMS, gap_s=3.0)
    colors = _colors(preds)
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
        ax.annotate(str(i), (r.x_ref, r.y_ref), xytext=(8, 8), textcoords="offset points",
                    fontsize=11, fontweight="bold", color="crimson",
                    arrowprops={"arrowstyle": "-", "color": "crimson"})
    if moments:
        ax.plot([], [], "-", color="0.4", lw=0.8,
                label=f"zooms 1-{len(moments)}: prediction -> reference\nat the same time (the error)")
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


def _zoom_panel(ax: Any, win: pd.DataFrame, ref: pd.DataFrame, tq: float, err: float,
                names: Sequence[str], colors: dict[str, Any]) -> None:
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
        ax.add_collection(LineCollection(seg, colors=[colors.get(p)], lw=0.8, alpha=0.8))
        ax.plot(w.x, w.y, "o", ms=4, color=colors.get(p))
    ax.plot(near.x_ref, near.y_ref, "k.", ms=3)
    ax.set_xlim(cx - hw, cx + hw)
    ax.set_ylim(cy - hw, cy + hw)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east [m]", fontsize=8)
    ax.set_ylabel("north [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, alpha=0.3)


def plot_trajectory_error(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """The most-turning drive's reference path [m, ENU] coloured by each predictor's future
    error [m]: one panel per predictor, one shared colour scale (log when the errors span
    more than a decade). Warm-up excluded."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.figure import Figure

    t = headline(traces, ["drive", "predictor", "kind", "t_query", "x_ref", "y_ref", "error_m",
                          "label"])
    fut = _finite(t[(t.kind == "future") & np.isfinite(t["x_ref"].to_numpy(dtype=float))])
    if fut.empty:
        raise NothingToPlot("no future query with a known error")
    drive, _ = most_turning_drive(fut)
    dfd = fut[fut.drive == drive]
    names = _in_order(preds, dfd.predictor)
    track = t[(t.drive == drive) & (t.predictor == names[0])].dropna(subset=["x_ref"])
    track = track.sort_values("t_query")
    e_all = dfd.error_m.to_numpy(dtype=float)
    lo, hi = np.percentile(e_all, [1, 99])
    lo = max(lo, FLOOR_M)
    hi = max(hi, lo * 1.01)
    norm = LogNorm(lo, hi, clip=True) if hi / lo > 10 else Normalize(lo, hi, clip=True)
    allxy = np.vstack([track[["x_ref", "y_ref"]].to_numpy(float),
                       dfd[["x_ref", "y_ref"]].to_numpy(float)])
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
            keep = ~_gaps(tq)  # no segment across an outage
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
    for ax in axes[len(names):]:
        ax.set_visible(False)
    axes[0].set_xlim(lo_xy[0], hi_xy[0])  # shared by every panel
    axes[0].set_ylim(lo_xy[1], hi_xy[1])
    sm = lc if lc is not None else ScalarMappable(norm=norm, cmap="viridis")
    extend = ("both" if e_all.min() < lo else "max") if e_all.max() > hi else (
        "min" if e_all.min() < lo else "neither")
    fig.colorbar(sm, ax=list(axes[:len(names)]), label="future-point error [m]", extend=extend,
                 shrink=0.9)
    fig.suptitle(f"{drive}: reference path coloured by future-point error\n(grey: no future "
                 "query there, e.g. warm-up or outage; colours clipped to the 1st-99th "
                 "percentile)", fontsize=10)
    return fig


def _runs(t: np.ndarray, values: np.ndarray) -> list[tuple[Any, float, float]]:
    """(value, start, end) of the runs of equal consecutive ``values`` along sorted times
    ``t`` [s]; a run ends where the next one starts."""
    if t.size == 0:
        return []
    change = np.flatnonzero(values[1:] != values[:-1]) + 1
    starts = np.r_[0, change]
    ends = np.r_[change, t.size - 1]
    return [(values[s], float(t[s]), float(t[e])) for s, e in zip(starts, ends, strict=True)]


def draw_error_over_time(ax: Any, drive_rows: pd.DataFrame, preds: Sequence[str],
                         colors: dict[str, Any]) -> bool:
    """Draw one drive's future-point error [m] over drive time [s] into ``ax`` (log y);
    shade scenario labels (background bands), GPS outages (hatched: t_query min..max of
    each outage) and the warm-up (grey). False (nothing drawn) without a finite error.

    The y axis is linear in log10(error) with ticks at powers of ten: the same picture as a
    log axis at a third of the rendering time (this runs once per drive)."""
    from matplotlib.patches import Patch

    fut = _finite(drive_rows[drive_rows.kind == "future"])
    if fut.empty:
        return False
    handles: list[Any] = []
    clipped = False
    lo_hi = (np.inf, -np.inf)
    for p in _in_order(preds, fut.predictor):
        d = fut[fut.predictor == p].sort_values("t_query")
        e = d.error_m.to_numpy(dtype=float)
        v, low = _log_values(e)
        v = np.log10(v)
        clipped |= low
        lo_hi = (min(lo_hi[0], v.min()), max(lo_hi[1], v.max()))
        tq = d.t_query.to_numpy(dtype=float)
        gap = np.flatnonzero(_gaps(tq)) + 1  # break the line across outages
        (h,) = ax.plot(np.insert(tq, gap, np.nan), np.insert(v, gap, np.nan), "-", lw=0.8,
                       color=colors.get(p), label=f"{p} (mean {e.mean():.3f} m)")
        handles.append(h)
    xband = ax.get_xaxis_transform()  # x in data, y in axes fraction
    one = drive_rows[drive_rows.predictor == drive_rows.predictor.iloc[0]].sort_values("t_query")
    tq = one.t_query.to_numpy(dtype=float)
    if "label" in one.columns:
        spans: dict[str, list[tuple[float, float]]] = {}
        for lab, a, b in _runs(tq, one.label.astype(str).to_numpy()):
            spans.setdefault(lab, []).append((a, b - a))
        for lab, s in spans.items():
            c = LABEL_COLORS.get(lab, "#dddddd")
            ax.broken_barh(s, (0, 1), transform=xband, facecolors=c, alpha=0.6, zorder=0)
            handles.append(Patch(facecolor=c, alpha=0.6, label=lab))
    out = drive_rows[drive_rows.outage >= 0]
    if not out.empty:
        g = out.groupby("outage")["t_query"].agg(["min", "max"])
        ax.broken_barh(list(zip(g["min"], g["max"] - g["min"], strict=True)), (0, 1),
                       transform=xband, facecolors="none", edgecolors="0.3", hatch="////",
                       lw=0, zorder=0.5)
        handles.append(Patch(facecolor="none", edgecolor="0.3", hatch="////",
                             label=f"GPS outage ({len(g)})"))
    w = _warmup(drive_rows)
    if w.any():
        tw = drive_rows.t_query.to_numpy(dtype=float)[w]
        ax.broken_barh([(tw.min(), tw.max() - tw.min())], (0, 1), transform=xband,
                       facecolors="0.55", alpha=0.6, zorder=0.6)
        handles.append(Patch(facecolor="0.55", alpha=0.6, label="warm-up"))
    k = np.arange(np.floor(lo_hi[0]), np.ceil(lo_hi[1]) + 1)
    ax.set_yticks(k, [f"{10.0 ** i:g}" for i in k])
    ax.set_ylim(k[0] - 0.05, k[-1] + 0.05) if k.size > 1 else ax.set_ylim(k[0] - 1, k[0] + 1)
    t0, t1 = float(np.nanmin(drive_rows.t_query)), float(np.nanmax(drive_rows.t_query))
    ax.set_xlim(t0, t1 if t1 > t0 else t0 + 1.0)
    ax.set_xlabel("drive time [s]")
    ax.set_ylabel("future-point error [m] (log scale)")
    if clipped:
        ax.text(1.0, 1.01, f"< {1000 * FLOOR_M:g} mm drawn at {1000 * FLOOR_M:g} mm",
                transform=ax.transAxes, ha="right", va="bottom", fontsize=7)
    ax.grid(True, which="major", axis="y", alpha=0.3)
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              borderaxespad=0)
    return True


def drives_to_plot(traces: pd.DataFrame, limit: int | None) -> tuple[list[str], str | None]:
    """Which drives get an error-over-time plot: all of them when there are at most
    ``limit`` (None: no limit; never more than :data:`MAX_DRIVE_FIGURES`), else the
    ``limit`` drives with the largest mean future-point error over all predictors (past the
    warm-up), in drive order; and a note saying which were chosen, or None."""
    drives = [str(d) for d in pd.unique(traces.drive)]
    cap = MAX_DRIVE_FIGURES if limit is None else min(limit, MAX_DRIVE_FIGURES)
    if len(drives) <= cap:
        return drives, None
    if cap == 0:
        return [], f"not drawn for the {len(drives)} drives (--drive-plots 0)"
    fut = headline(traces[traces.kind == "future"])
    worst = (fut.groupby(fut.drive, sort=False, observed=True)["error_m"].mean()
             .sort_values(ascending=False, kind="stable").index[:cap])
    worst = {str(d) for d in worst}
    chosen = [d for d in drives if d in worst]
    why = ("cap MAX_DRIVE_FIGURES in bench/plots.py" if limit is None or limit > MAX_DRIVE_FIGURES
           else "--drive-plots all for every drive")
    return chosen, (f"drawn for the {len(chosen)} of {len(drives)} drives with the largest mean "
                    f"future-point error ({why})")


def write_error_over_time(traces: pd.DataFrame, preds: Sequence[str], out: Path,
                          formats: Sequence[str], limit: int | None = DEFAULT_DRIVE_PLOTS
                          ) -> tuple[list[Path], str | None]:
    """``out/drives/<drive>-error_over_time.<fmt>`` for the drives of :func:`drives_to_plot`,
    drawn into one reused figure at :data:`DRIVE_DPI`; return the files and a note (drives
    left out and why), or None."""
    from matplotlib.figure import Figure

    colors = _colors(preds)
    fig = Figure(figsize=(12, 4))  # fixed margins: a layout engine would double the cost
    ax = fig.add_subplot()
    fig.subplots_adjust(left=0.065, right=0.80, bottom=0.13, top=0.91)
    files: list[Path] = []
    empty: list[str] = []
    chosen, chosen_note = drives_to_plot(traces, limit)
    used = [c for c in ("drive", "predictor", "kind", "t_query", "error_m", "label", "outage",
                        "warmup") if c in traces.columns]
    picked = traces.loc[traces.drive.isin(chosen).to_numpy(), used]
    stems: set[str] = set()
    # iterate the groups (first appearance order): get_group fails on 1-row groups (pandas 3.1)
    for i, (drive, rows) in enumerate(picked.groupby(picked.drive, sort=False, observed=True)):
        ax.clear()
        if not draw_error_over_time(ax, rows, preds, colors):
            empty.append(str(drive))
            continue
        ax.set_title(f"{drive}: future-point error over time", fontsize=10, loc="left")
        stem = _safe_name(str(drive))
        stem = stem if stem not in stems else f"{stem}-{i}"  # two names, one file name
        stems.add(stem)
        files += save_figure(fig, out / "drives", f"{stem}-error_over_time", formats,
                             dpi=DRIVE_DPI)
    notes = []
    if empty:
        notes.append(f"{len(empty)} of {len(chosen)} drives have no future query with a known "
                     f"error ({', '.join(empty[:5])}{', ...' if len(empty) > 5 else ''})")
    if chosen_note:
        notes.append(chosen_note)
    return files, "; ".join(notes) or None


def plot_calibration(traces: pd.DataFrame, preds: Sequence[str]) -> Figure:
    """Calibration curve of the reported covariances: observed vs expected coverage of the
    p-ellipses (:func:`posbench.metrics.calibration.calibration_curve`), future and now panels, one
    line per predictor that reports covariance; the diagonal is honest, below it
    overconfident. Warm-up excluded."""
    from matplotlib.figure import Figure

    from posbench.metrics.calibration import calibration_curve, mahalanobis_sq

    cols = ["predictor", "kind", "x", "y", "x_ref", "y_ref", "error_m", "cov_xx", "cov_xy",
            "cov_yy"]
    if any(c not in traces for c in cols):
        raise NothingToPlot("traces without covariance columns")
    t = _finite(headline(traces, cols))
    t = t[np.isfinite(t["cov_xx"].to_numpy(dtype=float))]
    if t.empty:
        raise NothingToPlot("no predictor reports uncertainty for an answer with a known error")
    colors = _colors(preds)
    fig = Figure(figsize=(9, 4.5), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    present = {str(x) for x in pd.unique(t.predictor)}
    for ax, kind in zip(axes, ("future", "now"), strict=True):
        ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="calibrated")
        rows = t[t.kind == kind]
        for p in [q for q in preds if q in present]:
            r = rows[rows.predictor == p]
            err = r[["x", "y"]].to_numpy(float) - r[["x_ref", "y_ref"]].to_numpy(float)
            curve = np.array(calibration_curve(mahalanobis_sq(
                err, r[["cov_xx", "cov_xy", "cov_yy"]].to_numpy(float))))
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


FIGURES = {"error_cdf": plot_error_cdf, "error_vs_speed": plot_error_vs_speed,
           "error_vs_since_fix": plot_error_vs_since_fix, "path": plot_path,
           "trajectory_error": plot_trajectory_error, "calibration": plot_calibration}
REQUIRED = ("drive", "predictor", "kind", "t_query", "x", "y", "x_ref", "y_ref", "error_m",
            "label", "speed_mps", "since_fix_s", "outage")


def _plottable(traces: pd.DataFrame) -> str | None:
    """Why ``traces`` cannot be drawn at all (empty, or lacking a column), or None."""
    missing = [c for c in REQUIRED if c not in traces.columns]
    if traces.empty or missing:
        return "no query in this run" if traces.empty else f"traces lack {', '.join(missing)}"
    return None


def plot_predictors(traces: pd.DataFrame, res: dict[str, Any]) -> list[str]:
    """The predictors the figures show, in order: the run's (``res["predictors"]``), else
    those in the traces (which must have the ``predictor`` column)."""
    return list(res.get("predictors") or [str(p) for p in pd.unique(traces.predictor)])


def write_summary_plots(traces: pd.DataFrame, preds: Sequence[str], out: Path,
                        formats: Iterable[str] = ("png",)) -> PlotsWritten:
    """The run's figures of :data:`FIGURES` (not the per-drive ones) into ``out``; see
    :func:`write_plots`."""
    fmts = check_formats(formats)
    written = PlotsWritten()
    why = _plottable(traces)
    if why:
        written.notes = dict.fromkeys(FIGURES, why)
        return written
    out.mkdir(parents=True, exist_ok=True)
    for name, draw in FIGURES.items():
        try:
            fig = draw(traces, list(preds))
            written.files += save_figure(fig, out, name, fmts)
        except NothingToPlot as e:
            written.notes[name] = str(e)
        except Exception as e:  # noqa: BLE001 - one bad figure must not lose the report
            written.notes[name] = f"failed ({type(e).__name__}: {e})"
    return written


def write_drive_plots(traces: pd.DataFrame, preds: Sequence[str], out: Path,
                      formats: Iterable[str] = ("png",),
                      drive_plots: int | None = DEFAULT_DRIVE_PLOTS) -> PlotsWritten:
    """The per-drive error-over-time figures into ``out/drives`` (:func:`write_error_over_time`);
    never raises on thin data (see :func:`write_plots`)."""
    fmts = check_formats(formats)
    written = PlotsWritten()
    why = _plottable(traces)
    if why:
        written.notes = {"error_over_time": why}
        return written
    try:
        files, note = write_error_over_time(traces, list(preds), out, fmts, drive_plots)
        written.files += files
        if note:
            written.notes["error_over_time"] = note
    except Exception as e:  # noqa: BLE001
        written.notes["error_over_time"] = f"failed ({type(e).__name__}: {e})"
    return written


def joined(*parts: PlotsWritten) -> PlotsWritten:
    """Several :class:`PlotsWritten` as one, files and notes in the order given."""
    out = PlotsWritten()
    for p in parts:
        out.files += p.files
        out.notes.update(p.notes)
    return out


def write_plots(traces: pd.DataFrame, res: dict[str, Any], out: Path,
                formats: Iterable[str] = ("png",),
                drive_plots: int | None = DEFAULT_DRIVE_PLOTS) -> PlotsWritten:
    """Write the run's figures into ``out`` (per-drive ones into ``out/drives``, for the
    drives of :func:`drives_to_plot` with limit ``drive_plots``), each in every one of
    ``formats`` (from :data:`FORMATS`). Never raises on thin data: a figure with nothing to
    show is not written and gets a note instead. The same as :func:`write_summary_plots`
    then :func:`write_drive_plots` (which ``bench run`` draws in parallel,
    :mod:`posbench.figure_jobs`).

    Raises:
        ValueError: an unknown format (checked before anything is written).
    """
    fmts = check_formats(formats)
    preds = plot_predictors(traces, res) if _plottable(traces) is None else []
    return joined(write_summary_plots(traces, preds, out, fmts),
                  write_drive_plots(traces, preds, out, fmts, drive_plots))
