"""Write a run's figures into its folder (:func:`write_plots`: the summary figures of
:data:`FIGURES`, then the per-drive ones), never raising on thin data: a figure with nothing
to show is not written and gets a note instead. The figures read the traces from a
:class:`~posbench.scoring.trace_set.TraceSet` (a frame is wrapped in one), one predictor or
one drive at a time."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from posbench.figures.distributions import (
    plot_calibration,
    plot_error_cdf,
    plot_error_vs_since_fix,
    plot_error_vs_speed,
)
from posbench.figures.maps import plot_path, plot_trajectory_error
from posbench.figures.outage_lengths import NAME as OUTAGE_LENGTHS
from posbench.figures.outage_lengths import plot_outage_lengths
from posbench.figures.per_drive import DEFAULT_DRIVE_PLOTS, write_error_over_time
from posbench.figures.style import (
    NO_FIGURES_NOTE,
    NothingToPlot,
    PlotsWritten,
    check_formats,
    save_figure,
)
from posbench.heap import trim_heap
from posbench.scoring.trace_set import TraceSet, as_trace_set

FIGURES = {
    "error_cdf": plot_error_cdf,
    "error_vs_speed": plot_error_vs_speed,
    "error_vs_since_fix": plot_error_vs_since_fix,
    "path": plot_path,
    "trajectory_error": plot_trajectory_error,
    "calibration": plot_calibration,
}
#: figures drawn from results.json rather than the traces (they show its intervals), each
#: only for a run whose results have the key it draws
RESULT_FIGURES = {OUTAGE_LENGTHS: ("outage_lengths", plot_outage_lengths)}
REQUIRED = (
    "drive",
    "predictor",
    "kind",
    "t_query",
    "x",
    "y",
    "x_ref",
    "y_ref",
    "error_m",
    "label",
    "speed_mps",
    "since_fix_s",
    "outage",
)


def _plottable(traces: TraceSet) -> str | None:
    """Why ``traces`` cannot be drawn at all (empty, or lacking a column), or None."""
    missing = [c for c in REQUIRED if c not in traces.columns]
    if traces.empty or missing:
        return "no query in this run" if traces.empty else f"traces lack {', '.join(missing)}"
    return None


def plot_predictors(traces: TraceSet | pd.DataFrame, res: dict[str, Any]) -> list[str]:
    """The predictors the figures show, in order: the run's (``res["predictors"]``), else
    those in the traces (which must have the ``predictor`` column)."""
    return list(res.get("predictors") or as_trace_set(traces).predictors())


def write_summary_plots(
    traces: TraceSet | pd.DataFrame,
    preds: Sequence[str],
    out: Path,
    formats: Iterable[str] = ("png",),
) -> PlotsWritten:
    """The run's figures of :data:`FIGURES` (not the per-drive ones) into ``out``; see
    :func:`write_plots`."""
    fmts = check_formats(formats)
    written = PlotsWritten()
    if not fmts:  # --plot-format none: one note for every figure of the run
        written.notes = {"figures": NO_FIGURES_NOTE}
        return written
    traces = as_trace_set(traces)
    why = _plottable(traces)
    if why:
        written.notes = dict.fromkeys(FIGURES, why)
        return written
    out.mkdir(parents=True, exist_ok=True)
    for name, draw in FIGURES.items():
        try:
            written.files += save_figure(draw(traces, list(preds)), out, name, fmts)
        except NothingToPlot as e:
            written.notes[name] = str(e)
        except Exception as e:  # noqa: BLE001 - one bad figure must not lose the report
            written.notes[name] = f"failed ({type(e).__name__}: {e})"
        trim_heap()  # what this figure read goes back: the next one's peak is its own
    return written


def write_drive_plots(
    traces: TraceSet | pd.DataFrame,
    preds: Sequence[str],
    out: Path,
    formats: Iterable[str] = ("png",),
    drive_plots: int | None = DEFAULT_DRIVE_PLOTS,
) -> PlotsWritten:
    """The per-drive error-over-time figures into ``out/drives`` (:func:`write_error_over_time`);
    never raises on thin data (see :func:`write_plots`)."""
    fmts = check_formats(formats)
    written = PlotsWritten()
    if not fmts:  # --plot-format none (noted by write_summary_plots)
        return written
    traces = as_trace_set(traces)
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


def write_result_plots(
    res: dict[str, Any], out: Path, formats: Iterable[str] = ("png",)
) -> PlotsWritten:
    """The figures of :data:`RESULT_FIGURES` whose results key ``res`` has, into ``out``;
    never raises on thin data (see :func:`write_plots`)."""
    fmts = check_formats(formats)
    written = PlotsWritten()
    if not fmts:  # --plot-format none (noted by write_summary_plots)
        return written
    for name, (key, draw) in RESULT_FIGURES.items():
        if not res.get(key):
            continue
        try:
            written.files += save_figure(draw(res), out, name, fmts)
        except NothingToPlot as e:
            written.notes[name] = str(e)
        except Exception as e:  # noqa: BLE001 - one bad figure must not lose the report
            written.notes[name] = f"failed ({type(e).__name__}: {e})"
    return written


def joined(*parts: PlotsWritten) -> PlotsWritten:
    """Several :class:`PlotsWritten` as one, files and notes in the order given."""
    out = PlotsWritten()
    for p in parts:
        out.files += p.files
        out.notes.update(p.notes)
    return out


def write_plots(
    traces: TraceSet | pd.DataFrame,
    res: dict[str, Any],
    out: Path,
    formats: Iterable[str] = ("png",),
    drive_plots: int | None = DEFAULT_DRIVE_PLOTS,
) -> PlotsWritten:
    """Write the run's figures into ``out`` (per-drive ones into ``out/drives``, for the
    drives of :func:`drives_to_plot` with limit ``drive_plots``), each in every one of
    ``formats`` (from :data:`FORMATS`). Never raises on thin data: a figure with nothing to
    show is not written and gets a note instead. The same as :func:`write_summary_plots`
    then :func:`write_drive_plots` (which ``bench run`` draws in parallel,
    :mod:`posbench.pipeline.jobs`).

    Raises:
        ValueError: an unknown format (checked before anything is written).
    """
    fmts = check_formats(formats)
    traces = as_trace_set(traces)
    preds = plot_predictors(traces, res) if _plottable(traces) is None else []
    return joined(
        write_summary_plots(traces, preds, out, fmts),
        write_drive_plots(traces, preds, out, fmts, drive_plots),
    )
