"""The paper's figures, made from a real run (matplotlib figures with titles; captions for
the report; written in each requested format of :data:`posbench.figures.style.FORMATS`).

1. A model prediction: the 8 resampled input points, the predicted future point and
   the reference (truth) 200 ms after the fix.
2. The current-position estimate: the cubic through the grid and the prediction,
   sampled every 50 ms between the fix and the prediction, against the reference.
3. A predicted path against the reference over 40 s of a route.
4. The Kalman filter's prediction (``kf-paper``, the paper's baseline) at the same fix.

The moment shown is the fix with the largest heading change over the next second on
the drive with the most turn / roundabout queries, so the figures show a turn. Nothing is
replayed again: each drive's moment was chosen, and lstm's step there recorded, while the run
replayed it (:mod:`posbench.replay.paper_moment`, ``DriveRun.paper_moment``); kf-paper's
answer and lstm's path are the run's traces (lstm's future answers within 20 s of the fix,
:data:`COLUMNS` of them, and kf-paper's at the fix, each chosen as it is read).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.config import RunConfig
from posbench.figures.style import (
    check_formats,
    most_turning,
    save_figure,
    shown_format,
)
from posbench.replay.paper_moment import PAPER_PREDICTOR
from posbench.replay.prepare import prepare_drive
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import StoredDrive, as_drive
from posbench.scoring.records import DriveRun
from posbench.scoring.trace_parts import Keep
from posbench.scoring.trace_set import TraceSet, as_trace_set

#: the trace columns the path figure reads, of lstm's future answers near the fix
COLUMNS = ("kind", "t_issue", "t_query", "x", "y", "x_ref", "y_ref", "error_m")


def shown_moment(runs: Sequence[DriveRun]) -> DriveRun | None:
    """The run whose recorded moment the figures show: of the drives with turn or roundabout
    queries the one with the most (the first by name among equals,
    :func:`~posbench.figures.style.most_turning`), else the first drive with a record; None
    when no drive has a record (no lstm) or lstm made no network step at that drive's
    moment."""
    recorded = [r for r in runs if not r.skipped and r.paper_moment]
    if not recorded:
        return None
    turns = {r.name: int(r.paper_moment["turns"]) for r in recorded if r.paper_moment["turns"]}
    name = most_turning(turns) if turns else recorded[0].name
    run = next(r for r in recorded if r.name == name)
    return run if "t_fix" in run.paper_moment else None


def _future_issued(when: Callable[[np.ndarray], np.ndarray]) -> Keep:
    """The future queries whose issue time [s] ``when`` accepts (a choice of rows made as
    they are read, :meth:`~posbench.scoring.trace_set.TraceSet.frame`'s ``rows``: of a long
    drive, the figures read the rows they draw)."""

    def keep(column: Callable[[str], np.ndarray | None]) -> np.ndarray:
        kind, t = column("kind"), column("t_issue")
        assert kind is not None and t is not None
        return np.asarray((kind == "future") & when(t))

    return keep


def _future_answer(held: TraceSet, predictor: str, drive: str, t_fix: float) -> np.ndarray:
    """``predictor``'s future answer (x, y) [m] to the query issued at ``t_fix`` on
    ``drive`` (NaN where it has none)."""
    at_fix = _future_issued(lambda t: t == t_fix)
    rows = held.frame(["kind", "t_issue", "x", "y"], predictor, drive, at_fix)
    return rows[["x", "y"]].to_numpy(float)[0] if len(rows) else np.full(2, np.nan)


def paper_figures(
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    traces: TraceSet | pd.DataFrame,
    out: Path,
    runs: Sequence[DriveRun] | None = None,
    formats: Iterable[str] = ("png",),
) -> list[tuple[str, str]]:
    """Write the figures, each in every one of ``formats`` (png, svg, pdf); return
    (file name, caption) pairs, the file in the format a report shows
    (:func:`posbench.figures.style.shown_format`: png, else svg, else pdf). Needs ``lstm`` in
    the run and ``runs``, the run's DriveRuns, whose recorded moments the figures draw
    (:func:`shown_moment`; none without them). ``traces``: where they are (a frame is
    wrapped in a :class:`TraceSet`); of them, lstm's future answers near the fix are read,
    :data:`COLUMNS` of them, and kf-paper's answer at the fix.

    Raises:
        ValueError: an unknown format.
    """
    fmts = check_formats(formats)
    held = as_trace_set(traces)
    if PAPER_PREDICTOR not in cfg.predictors or held.empty or not fmts:  # --plot-format none
        return []
    run = shown_moment(runs or [])
    if run is None:
        return []
    from matplotlib.figure import Figure

    from posbench.replay.reference import reference_at

    m: dict[str, Any] = run.paper_moment
    name, t_fix = run.name, float(m["t_fix"])
    grid, pred, now = m["grid"], m["pred"], m["now_xy"]
    ts = m["now_t"]
    # the path figure's rows: lstm's future answers within 20 s of the fix
    near = _future_issued(lambda t: (t > t_fix - 20) & (t < t_fix + 20))
    path_rows = held.frame(COLUMNS, PAPER_PREDICTOR, name, near)
    drive = as_drive(next(d for d in drives if d.name == name))  # the one drawn, read here
    fed = run.with_fixes_and_track().fixes  # the fixes the run fed (read back from disk)
    if fed is None:
        g = prepare_drive(drive, cfg).gps
        fed = pd.DataFrame({"t": g.t, "x": g.x, "y": g.y, "received": True})
    shown = fed[
        fed.received.to_numpy(bool) & (fed.t > t_fix - 2.5).to_numpy() & (fed.t <= t_fix).to_numpy()
    ]
    fix_x, fix_y = shown.x.to_numpy(float), shown.y.to_numpy(float)
    around = drive.window(t_fix - 30.0, t_fix + 5.0)
    ref_now = reference_at(around, ts)
    ref_path = reference_at(around, np.arange(t_fix - 2.0, t_fix + 1.0, 0.05))
    figs: list[tuple[str, str]] = []

    def new(title: str) -> tuple[Figure, Any]:
        """A square map figure with its title."""
        fig = Figure(figsize=(6, 6), layout="constrained")
        ax = fig.add_subplot()
        ax.set_title(title, fontsize=11)
        return fig, ax

    def save(fig: Figure, stem: str, caption: str) -> None:
        """Style the figure's map axes (equal scale, ENU labels, legend), write it in every
        format, keep its caption."""
        for ax in fig.axes:
            ax.set_aspect("equal", adjustable="datalim")
            ax.legend(fontsize=8)
            ax.set_xlabel("east [m]")
            ax.set_ylabel("north [m]")
            ax.grid(True, alpha=0.3)
        save_figure(fig, out, stem, fmts)
        figs.append((f"{stem}.{shown_format(fmts)}", caption))

    fig, ax = new(
        f"Model prediction: lstm, {cfg.horizon_s:g} s ahead of the fix at t = {t_fix:.2f} s"
    )
    ax.plot(ref_path[:, 0], ref_path[:, 1], "k-", lw=0.8, label="reference path")
    ax.plot(fix_x, fix_y, "rx", label="GPS fixes received")
    ax.plot(grid[:, 0], grid[:, 1], "o", color="tab:green", label="resampled input (8 x 200 ms)")
    ax.plot(*pred, "X", color="gold", ms=12, mec="k", label="lstm prediction (+0.2 s)")
    ax.plot(*ref_now[-1], "*", color="k", ms=14, label="reference at +0.2 s")
    err = float(np.hypot(*(pred - ref_now[-1])))
    save(
        fig,
        "paper_fig_prediction",
        f"Model prediction: drive `{name}`, fix at t = {t_fix:.2f} s; the 8 resampled inputs, "
        f"the predicted point 0.2 s ahead and the reference there (error {100 * err:.1f} cm).",
    )

    fig, ax = new("Current-position estimates between the fix and the prediction")
    ax.plot(ref_path[:, 0], ref_path[:, 1], "k-", lw=0.8, label="reference path")
    ax.plot(grid[:, 0], grid[:, 1], "o", color="tab:green", label="resampled input")
    ax.plot(*pred, "X", color="gold", ms=12, mec="k", label="lstm prediction")
    ax.plot(now[:, 0], now[:, 1], "*", color="m", ms=10, label="current-position estimates")
    ax.plot(ref_now[:, 0], ref_now[:, 1], "k.", ms=6, label="reference at those times")
    e_now = np.hypot(*(now - ref_now).T)
    save(
        fig,
        "paper_fig_current_position",
        f"Current position between the fix and the prediction: drive `{name}`, "
        f"t = {t_fix:.2f}-{t_fix + cfg.horizon_s:.2f} s every {cfg.horizon_s / 4:.2f} s; "
        f"errors {', '.join(f'{100 * e:.1f}' for e in e_now)} cm.",
    )

    fig = Figure(figsize=(7, 7), layout="constrained")
    ax = fig.add_subplot()
    ax.set_title(f"Predicted path against the reference: lstm, {name}", fontsize=11)
    r = path_rows.sort_values("t_query")
    ax.plot(r.x_ref, r.y_ref, "k-", lw=1, label="reference")
    ax.plot(r.x, r.y, ".", ms=4, color="tab:orange", label="lstm future points")
    save(
        fig,
        "paper_fig_path",
        f"Predicted path against the reference: drive `{name}`, t = {max(t_fix - 20, 0):.0f}-"
        f"{t_fix + 20:.0f} s, lstm future points (mean error {100 * r.error_m.mean():.1f} cm).",
    )

    kp = _future_answer(held, "kf-paper", name, t_fix) if "kf-paper" in cfg.predictors else None
    if kp is not None and np.isfinite(kp).all():
        fig, ax = new(
            f"The paper's Kalman filter (kf-paper), {cfg.horizon_s:g} s ahead of the same fix"
        )
        ax.plot(ref_path[:, 0], ref_path[:, 1], "k-", lw=0.8, label="reference path")
        ax.plot(fix_x, fix_y, "rx", label="known points (fixes)")
        ax.plot(*kp, "X", color="gold", ms=12, mec="k", label="kf-paper prediction")
        ax.plot(*ref_now[-1], "*", color="k", ms=14, label="reference at +0.2 s")
        save(
            fig,
            "paper_fig_kalman",
            f"The paper's Kalman filter at the same fix: drive `{name}`, t = {t_fix:.2f} s "
            f"(error {100 * float(np.hypot(*(kp - ref_now[-1]))):.1f} cm).",
        )
    return figs
