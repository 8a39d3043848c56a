"""The per-drive figures: future-point error over drive time, with GPS outages, scenario
labels and the warm-up shaded, for every drive of a small run or the worst ones of a large
one (``drives/<drive>-error_over_time.<fmt>``). The worst drives are found reading a few
columns one predictor at a time; each figure reads its drive's rows alone."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.figures.style import (
    DRIVE_DPI,
    FLOOR_M,
    LABEL_COLORS,
    colors_for,
    finite_errors,
    gap_steps,
    in_order,
    log_values,
    save_figure,
    warmup_mask,
)
from posbench.naming import unique_file_safe
from posbench.scoring.trace_parts import Keep, text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

#: at most this many per-drive error-over-time figures per run (the first drives in run
#: order); the note of ``error_over_time`` says when drives were left out
MAX_DRIVE_FIGURES = 250
#: per-drive plots drawn by default: every drive of a run with up to this many, else this
#: many drives with the largest mean future-point error (``bench run --drive-plots``)
DEFAULT_DRIVE_PLOTS = 20


def _runs(t: np.ndarray, values: np.ndarray) -> list[tuple[Any, float, float]]:
    """(value, start, end) of the runs of equal consecutive ``values`` along sorted times
    ``t`` [s]; a run ends where the next one starts."""
    if t.size == 0:
        return []
    change = np.flatnonzero(values[1:] != values[:-1]) + 1
    starts = np.r_[0, change]
    ends = np.r_[change, t.size - 1]
    return [(values[s], float(t[s]), float(t[e])) for s, e in zip(starts, ends, strict=True)]


#: a drive with more rows than this has only the rows it draws read (:func:`_drawn_rows`)
CHOSEN_ABOVE_ROWS = 1 << 18


def _drawn_rows(ts: TraceSet, drive: str) -> Keep | None:
    """The rows of ``drive`` :func:`draw_error_over_time` reads: every predictor's future
    queries, the first predictor's every query (the route types' bands, the time axis), and
    the rows in an outage or the warm-up (their bands); a long drive's now queries of the
    other predictors are not read. None (all rows) for a drive of at most
    :data:`CHOSEN_ABOVE_ROWS` rows: choosing would cost more than it spares."""
    first = ts.frame(["predictor"], drive=drive)["predictor"]
    if len(first) <= CHOSEN_ABOVE_ROWS:
        return None
    name = str(first.iloc[0])

    def keep(column: Callable[[str], np.ndarray | None]) -> np.ndarray:
        kind, predictor = column("kind"), column("predictor")
        outage, warmup = column("outage"), column("warmup")
        assert kind is not None and predictor is not None
        mask = (kind == "future") | (predictor == name)
        if outage is not None:
            mask |= outage >= 0
        if warmup is not None:
            mask |= warmup.astype(bool)
        return np.asarray(mask)

    return keep


def draw_error_over_time(
    ax: Any, drive_rows: pd.DataFrame, preds: Sequence[str], colors: dict[str, Any]
) -> bool:
    """Draw one drive's future-point error [m] over drive time [s] into ``ax`` (log y);
    shade scenario labels (background bands), GPS outages (hatched: t_query min..max of
    each outage) and the warm-up (grey). False (nothing drawn) without a finite error.

    The y axis is linear in log10(error) with ticks at powers of ten: the same picture as a
    log axis at a third of the rendering time (this runs once per drive)."""
    from matplotlib.patches import Patch

    fut = finite_errors(drive_rows[drive_rows.kind == "future"])
    if fut.empty:
        return False
    handles: list[Any] = []
    clipped = False
    lo_hi = (np.inf, -np.inf)
    for p in in_order(preds, fut.predictor):
        d = fut[fut.predictor == p].sort_values("t_query")
        e = d.error_m.to_numpy(dtype=float)
        v, low = log_values(e)
        v = np.log10(v)
        clipped |= low
        lo_hi = (min(lo_hi[0], v.min()), max(lo_hi[1], v.max()))
        tq = d.t_query.to_numpy(dtype=float)
        gap = np.flatnonzero(gap_steps(tq)) + 1  # break the line across outages
        (h,) = ax.plot(
            np.insert(tq, gap, np.nan),
            np.insert(v, gap, np.nan),
            "-",
            lw=0.8,
            color=colors.get(p),
            label=f"{p} (mean {e.mean():.3f} m)",
        )
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
        ax.broken_barh(
            list(zip(g["min"], g["max"] - g["min"], strict=True)),
            (0, 1),
            transform=xband,
            facecolors="none",
            edgecolors="0.3",
            hatch="////",
            lw=0,
            zorder=0.5,
        )
        handles.append(
            Patch(facecolor="none", edgecolor="0.3", hatch="////", label=f"GPS outage ({len(g)})")
        )
    w = warmup_mask(drive_rows)
    if w.any():
        tw = drive_rows.t_query.to_numpy(dtype=float)[w]
        ax.broken_barh(
            [(tw.min(), tw.max() - tw.min())],
            (0, 1),
            transform=xband,
            facecolors="0.55",
            alpha=0.6,
            zorder=0.6,
        )
        handles.append(Patch(facecolor="0.55", alpha=0.6, label="warm-up"))
    k = np.arange(np.floor(lo_hi[0]), np.ceil(lo_hi[1]) + 1)
    ax.set_yticks(k, [f"{10.0**i:g}" for i in k])
    ax.set_ylim(k[0] - 0.05, k[-1] + 0.05) if k.size > 1 else ax.set_ylim(k[0] - 1, k[0] + 1)
    t0, t1 = float(np.nanmin(drive_rows.t_query)), float(np.nanmax(drive_rows.t_query))
    ax.set_xlim(t0, t1 if t1 > t0 else t0 + 1.0)
    ax.set_xlabel("drive time [s]")
    ax.set_ylabel("future-point error [m] (log scale)")
    if clipped:
        ax.text(
            1.0,
            1.01,
            f"< {1000 * FLOOR_M:g} mm drawn at {1000 * FLOOR_M:g} mm",
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=7,
        )
    ax.grid(True, which="major", axis="y", alpha=0.3)
    ax.legend(
        handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0
    )
    return True


def drives_to_plot(
    traces: TraceSet | pd.DataFrame, limit: int | None
) -> tuple[list[str], str | None]:
    """Which drives get an error-over-time plot: all of them when there are at most
    ``limit`` (None: no limit; never more than :data:`MAX_DRIVE_FIGURES`), else the
    ``limit`` drives with the largest mean future-point error [m] over all predictors (past
    the warm-up), in drive order; and a note saying which were chosen, or None. The means
    are summed one predictor at a time (drive, kind, error_m, warmup)."""
    ts = as_trace_set(traces)
    drives = ts.drives()
    cap = MAX_DRIVE_FIGURES if limit is None else min(limit, MAX_DRIVE_FIGURES)
    if len(drives) <= cap:
        return drives, None
    if cap == 0:
        return [], f"not drawn for the {len(drives)} drives (--drive-plots 0)"
    sums = pd.DataFrame(0.0, index=pd.Index(drives), columns=["sum", "count", "rows"])
    for p in ts.predictors():
        pieces = []  # one part of the traces at a time, each reduced to its drives' sums
        for t in ts.pieces(p, ["drive", "kind", "error_m", "warmup"], scored=False):
            fut = t[~warmup_mask(t) & (text_values(t["kind"]) == "future")]
            g = fut.groupby("drive", sort=False, observed=True)["error_m"]
            piece = pd.DataFrame({"sum": g.sum(), "count": g.count(), "rows": g.size()})
            piece.index = pd.Index([str(d) for d in piece.index])
            pieces.append(piece)
        if pieces:  # a drive in several parts (none today) adds up its pieces
            part = pd.concat(pieces).groupby(level=0, sort=False).sum()
            sums = sums.add(part.reindex(sums.index, fill_value=0.0))
    sums = sums[sums["rows"] > 0]  # drives with a future query past the warm-up
    mean = (sums["sum"] / sums["count"]).where(sums["count"] > 0)
    worst = mean.sort_values(ascending=False, kind="stable").index[:cap]
    worst = {str(d) for d in worst}
    chosen = [d for d in drives if d in worst]
    why = (
        "cap MAX_DRIVE_FIGURES in bench/plots.py"
        if limit is None or limit > MAX_DRIVE_FIGURES
        else "--drive-plots all for every drive"
    )
    return chosen, (
        f"drawn for the {len(chosen)} of {len(drives)} drives with the largest mean "
        f"future-point error ({why})"
    )


def write_error_over_time(
    traces: TraceSet | pd.DataFrame,
    preds: Sequence[str],
    out: Path,
    formats: Sequence[str],
    limit: int | None = DEFAULT_DRIVE_PLOTS,
) -> tuple[list[Path], str | None]:
    """``out/drives/<drive>-error_over_time.<fmt>`` for the drives of :func:`drives_to_plot`,
    drawn into one reused figure at :data:`DRIVE_DPI`; return the files and a note (drives
    left out and why), or None."""
    from matplotlib.figure import Figure

    colors = colors_for(preds)
    fig = Figure(figsize=(12, 4))  # fixed margins: a layout engine would double the cost
    ax = fig.add_subplot()
    fig.subplots_adjust(left=0.065, right=0.80, bottom=0.13, top=0.91)
    files: list[Path] = []
    empty: list[str] = []
    ts = as_trace_set(traces)
    chosen, chosen_note = drives_to_plot(ts, limit)
    used = [
        c
        for c in ("drive", "predictor", "kind", "t_query", "error_m", "label", "outage", "warmup")
        if c in ts.columns
    ]
    stems = dict(zip(chosen, unique_file_safe(chosen), strict=True))  # two names, one file name
    for drive in chosen:  # one drive's rows at a time: those it draws
        rows = ts.frame(used, drive=drive, rows=_drawn_rows(ts, drive))
        ax.clear()
        if not draw_error_over_time(ax, rows, preds, colors):
            empty.append(drive)
            continue
        ax.set_title(f"{drive}: future-point error over time", fontsize=10, loc="left")
        files += save_figure(
            fig, out / "drives", f"{stems[drive]}-error_over_time", formats, dpi=DRIVE_DPI
        )
    notes = []
    if empty:
        notes.append(
            f"{len(empty)} of {len(chosen)} drives have no future query with a known "
            f"error ({', '.join(empty[:5])}{', ...' if len(empty) > 5 else ''})"
        )
    if chosen_note:
        notes.append(chosen_note)
    return files, "; ".join(notes) or None
