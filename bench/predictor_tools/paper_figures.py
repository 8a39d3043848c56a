"""The paper's figures, made from a real run (matplotlib figures with titles; captions for
the report; written in each requested format of :data:`posbench.figures.style.FORMATS`).

1. A model prediction: the 8 resampled input points, the predicted future point and
   the reference (truth) 200 ms after the fix.
2. The current-position estimate: the cubic through the grid and the prediction,
   sampled every 50 ms between the fix and the prediction, against the reference.
3. A predicted path against the reference over 40 s of a route.
4. The Kalman filter's prediction (``kf-paper``, the paper's baseline) at the same fix.

The moment shown is the fix with the largest heading change over the next second on
the drive with the most turn / roundabout queries, so the figures show a turn. Of the traces
the figures read lstm's rows alone (:data:`COLUMNS`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from posbench.config import RunConfig, gps_condition
from posbench.figures.style import (
    check_formats,
    most_turning,
    most_turning_drive,
    save_figure,
    shown_format,
    tally_turns,
)
from posbench.replay.loop import replay
from posbench.replay.predictor_setup import build_predictor
from posbench.replay.prepare import PreparedDrive, prepare_drive
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import StoredDrive, as_drive
from posbench.scoring.records import DriveRun
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet, as_trace_set

if TYPE_CHECKING:
    from posbench.predictors.lstm.stages import LstmStep


#: the trace columns the figures read, of lstm's rows
COLUMNS = (
    "drive",
    "predictor",
    "kind",
    "t_issue",
    "t_query",
    "x",
    "y",
    "x_ref",
    "y_ref",
    "error_m",
    "label",
    "speed_mps",
)


def turning_drive(ts: TraceSet, predictor: str) -> str | None:
    """The drive :func:`pick_moment` picks among ``predictor``'s rows (the most turning, by
    :func:`~posbench.figures.style.most_turning_drive`), found one part of the traces at a
    time, each reduced to its drives' turn counts; None without a future query."""
    parts = ts.pieces(predictor, ["drive", "kind", "label"], scored=False)
    turns, first = tally_turns(rows[text_values(rows["kind"]) == "future"] for rows in parts)
    if first is None:
        return None
    return most_turning(turns) if turns else first


def pick_moment(traces: pd.DataFrame, predictor: str) -> tuple[str, float] | None:
    """(drive, fix time) in a turn: the drive with most turn queries, the fix whose
    reference course changes most over the following second (above 2 m/s).

    The course is the direction between neighbouring future-query reference points (a fix
    apart), not the traces' instantaneous ``heading_ref`` (0.1 s either side of the query):
    a course over a fix interval is what picks the moment of every reference report, and
    the instantaneous heading picks other moments on all eight."""
    fut = traces[(traces.kind == "future") & (traces.predictor == predictor)]
    if fut.empty:
        return None
    drive, _ = most_turning_drive(fut)
    f = fut[(fut.drive == drive)].dropna(subset=["x_ref"]).sort_values("t_issue")
    if len(f) < 20:
        return None
    hd = np.unwrap(np.arctan2(np.gradient(f.y_ref.to_numpy()), np.gradient(f.x_ref.to_numpy())))
    n = 5
    change = np.abs(hd[n:] - hd[:-n])
    speed = f.speed_mps.to_numpy()[:-n]
    change[~(speed > 2)] = 0
    i = int(np.argmax(change)) + n // 2
    return str(drive), float(f.t_issue.iloc[i])


def _prepared_window(drive: Drive, fixes: pd.DataFrame, t0: float, t1: float) -> PreparedDrive:
    """The run's own received fixes and the drive's other streams within [t0, t1] [s], ready
    to replay (no queries): the figures show exactly what the predictors saw in the run."""
    from posbench.replay.prepare import Queries
    from posbench.replay.reference import FIX_CUBIC, TRUTH
    from posbench.scenarios.drive import GpsStream

    sub = drive.window(t0, t1)
    f = fixes[fixes.received & (fixes.t >= t0) & (fixes.t <= t1)]
    gps = GpsStream(f.t.to_numpy(), f.x.to_numpy(), f.y.to_numpy())
    e = np.empty(0)
    none = Queries(e, e, np.empty((0, 2)), e, np.empty(0, dtype=str), e)
    return PreparedDrive(
        sub,
        drive.meta.format,
        gps,
        gps,
        TRUTH if drive.truth is not None else FIX_CUBIC,
        none,
        none,
    )


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
    the run. With ``runs`` (the run's DriveRuns) the replay uses the run's own fixes over a
    40 s window, so long drives cost no more than short ones. ``traces``: where they are (a
    frame is wrapped in a :class:`TraceSet`); lstm's rows are read, :data:`COLUMNS` of them.

    Raises:
        ValueError: an unknown format.
    """
    fmts = check_formats(formats)
    held = as_trace_set(traces)
    if "lstm" not in cfg.predictors or held.empty or not fmts:  # not: --plot-format none
        return []
    drawn = turning_drive(held, "lstm")
    if drawn is None:
        return []
    # all the figures draw of the traces: the drawn drive's rows (pick_moment picks this
    # drive again among them), never the predictor's rows over every drive
    lstm_rows = held.frame(COLUMNS, "lstm", drive=drawn)
    moment = pick_moment(lstm_rows, "lstm")
    if moment is None:
        return []
    from matplotlib.figure import Figure

    name, t_fix = moment
    drive = as_drive(next(d for d in drives if d.name == name))  # the one drawn, read here
    fixes_fed = next(  # the fixes the run fed (read back when its worker wrote them to disk)
        (
            f
            for r in runs or []
            if r.name == name and (f := r.with_fixes_and_track().fixes) is not None
        ),
        None,
    )
    if fixes_fed is None:
        g = prepare_drive(drive, cfg).gps
        fixes_fed = pd.DataFrame({"t": g.t, "x": g.x, "y": g.y, "received": True})
    # the predictors replay the run's fixes up to the fix shown; references use a wider window
    prep = _prepared_window(drive, fixes_fed, t_fix - 30.0, t_fix)
    around = drive.window(t_fix - 30.0, t_fix + 5.0)
    cond = gps_condition(cfg, drive)
    lstm = build_predictor(cfg, "lstm", cond)
    replay(lstm, prep, cfg.horizon_s)
    # LstmPredictor's seam; a predictor registered as "lstm" in its place may lack it
    last_step: Callable[[], LstmStep | None] | None = getattr(lstm, "last_step", None)
    step = last_step() if last_step is not None else None
    if step is None:
        return []  # too few fixes before the moment for a model prediction (or no seam)
    grid, pred = step.grid, step.pred
    ts = np.linspace(t_fix, t_fix + cfg.horizon_s, 5)
    now = np.array([lstm.position_at(t) for t in ts])
    from posbench.replay.reference import reference_at

    ref_now = reference_at(around, ts)
    ref_path = reference_at(around, np.arange(t_fix - 2.0, t_fix + 1.0, 0.05))
    fixes = prep.gps.t > t_fix - 2.5
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
    ax.plot(prep.gps.x[fixes], prep.gps.y[fixes], "rx", label="GPS fixes received")
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

    f = lstm_rows[
        (lstm_rows.drive == name)
        & (lstm_rows.kind == "future")
        & (lstm_rows.t_issue > t_fix - 20)
        & (lstm_rows.t_issue < t_fix + 20)
    ]
    fig = Figure(figsize=(7, 7), layout="constrained")
    ax = fig.add_subplot()
    ax.set_title(f"Predicted path against the reference: lstm, {name}", fontsize=11)
    r = f[f.predictor == "lstm"].sort_values("t_query")
    ax.plot(r.x_ref, r.y_ref, "k-", lw=1, label="reference")
    ax.plot(r.x, r.y, ".", ms=4, color="tab:orange", label="lstm future points")
    save(
        fig,
        "paper_fig_path",
        f"Predicted path against the reference: drive `{name}`, t = {max(t_fix - 20, 0):.0f}-"
        f"{t_fix + 20:.0f} s, lstm future points (mean error {100 * r.error_m.mean():.1f} cm).",
    )

    if "kf-paper" in cfg.predictors:
        kfp = build_predictor(cfg, "kf-paper", cond)
        replay(kfp, prep, cfg.horizon_s)
        kp = np.asarray(kfp.position_at(t_fix + cfg.horizon_s))
        fig, ax = new(
            f"The paper's Kalman filter (kf-paper), {cfg.horizon_s:g} s ahead of the same fix"
        )
        ax.plot(ref_path[:, 0], ref_path[:, 1], "k-", lw=0.8, label="reference path")
        ax.plot(prep.gps.x[fixes], prep.gps.y[fixes], "rx", label="known points (fixes)")
        ax.plot(*kp, "X", color="gold", ms=12, mec="k", label="kf-paper prediction")
        ax.plot(*ref_now[-1], "*", color="k", ms=14, label="reference at +0.2 s")
        save(
            fig,
            "paper_fig_kalman",
            f"The paper's Kalman filter at the same fix: drive `{name}`, t = {t_fix:.2f} s "
            f"(error {100 * float(np.hypot(*(kp - ref_now[-1]))):.1f} cm).",
        )
    return figs
