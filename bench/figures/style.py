"""What every figure shares: the output formats and the one save helper (no timestamps: the
same run gives the same bytes), one colour per predictor, the log error axis with its floor,
the warm-up left out, and how a figure says it has nothing to show (:class:`NothingToPlot`,
:class:`PlotsWritten`). matplotlib is imported when a figure is drawn, not here."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    from matplotlib.figure import Figure


#: the output formats :func:`write_plots` and the paper's figures can write
FORMATS = ("png", "svg", "pdf")
#: errors [m] below this are drawn at it on log axes (a log axis cannot show 0)
FLOOR_M = 1e-3
#: resolution of the summary figures and of the per-drive figures [dots per inch]
DPI = 110
DRIVE_DPI = 80
TURN_LABELS = ("turn", "roundabout")
LABEL_COLORS = {
    "straight": "#c7e9c0",
    "turn": "#fdd0a2",
    "roundabout": "#d4b9da",
    "start_stop": "#fff2ae",
    "unlabelled": "#ffffff",
}


@dataclass
class PlotsWritten:
    """What :func:`write_plots` did: every file written (all formats) and, per figure
    not written, why (figure name -> note)."""

    files: list[Path] = field(default_factory=list)
    notes: dict[str, str] = field(default_factory=dict)


class NothingToPlot(Exception):
    """A figure has no data to show; the message says why (goes into the report)."""


#: the format name that asks for no figures at all (``--plot-format none``)
NO_FIGURES = "none"
#: why a run has no figures, in its report
NO_FIGURES_NOTE = "--plot-format none (no figure asked for)"


def check_formats(formats: Iterable[str] | str) -> tuple[str, ...]:
    """The output formats as a tuple of lower-case names from :data:`FORMATS`, in the given
    order without repeats. A string is split on commas (``"png,svg"``). ``"none"`` alone
    (:data:`NO_FIGURES`), or an empty tuple, is no figure at all: ``()``.

    Raises:
        ValueError: an unknown format, ``none`` beside a format, or an empty name.
    """
    items = formats.split(",") if isinstance(formats, str) else list(formats)
    names = [str(f).strip().lower().lstrip(".") for f in items]
    if NO_FIGURES in names:
        if len(names) > 1:
            raise ValueError(f"'{NO_FIGURES}' draws no figure: give it alone, not beside a format")
        return ()
    out: list[str] = []
    for f, name in zip(items, names, strict=True):
        if name not in FORMATS:
            raise ValueError(
                f"unknown plot format {f!r}: use one or more of {', '.join(FORMATS)}, or "
                f"{NO_FIGURES} for no figure"
            )
        if name not in out:
            out.append(name)
    return tuple(out)


def shown_format(formats: Iterable[str] | str) -> str:
    """The format a report links to among ``formats``: png, else svg, else pdf (the first
    two show inline in Markdown); "" for no figure (``none``)."""
    fmts = check_formats(formats)
    return next((f for f in FORMATS if f in fmts), "")


_METADATA = {"png": {"Software": None}, "svg": {"Date": None}, "pdf": {"CreationDate": None}}


def in_order(preds: Sequence[str], column: pd.Series) -> list[str]:
    """The predictors present in ``column``: those of ``preds`` in its order, then others sorted."""
    present = {str(x) for x in pd.unique(column)}
    return [p for p in preds if p in present] + sorted(present - set(preds))


def save_figure(
    fig: Figure, folder: Path, stem: str, formats: Sequence[str], dpi: int = DPI
) -> list[Path]:
    """Write ``fig`` as ``folder/stem.<fmt>`` for each format (already checked by
    :func:`check_formats`); return the paths. No timestamps in the files, so the same run
    gives the same bytes."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in formats:
        p = folder / f"{stem}.{fmt}"
        extra: dict[str, Any] = (
            {"pil_kwargs": {"compress_level": 1}} if fmt == "png" else {}
        )  # quicker; ~10 % larger
        fig.savefig(p, format=fmt, dpi=dpi, metadata=_METADATA[fmt], **extra)
        paths.append(p)
    return paths


def most_turning_drive(fut: pd.DataFrame) -> tuple[str, bool]:
    """The drive with the most turn / roundabout queries in ``fut`` (a traces slice), and
    whether any query is turning at all (else the first drive)."""
    counts = turn_counts(fut)
    return (most_turning(counts), True) if counts else (str(fut.drive.iloc[0]), False)


def turn_counts(fut: pd.DataFrame) -> dict[str, int]:
    """drive -> its turn / roundabout queries in ``fut`` (drives with one or more)."""
    turns = fut[fut.label.isin(TURN_LABELS)]
    if turns.empty:
        return {}
    counts = turns.groupby("drive", observed=True).size()
    return {str(d): int(n) for d, n in counts.items() if n}


def tally_turns(
    parts: Iterable[pd.DataFrame], turns: dict[str, int] | None = None
) -> tuple[dict[str, int], str | None]:
    """The turn counts of ``parts`` (pieces of one predictor's future queries, each with
    drive and label: e.g. one part of the traces at a time) added to ``turns`` (drive ->
    count; a new dict if None), and the first drive of the first piece with a row (None:
    no row). Each piece is reduced to its counts before the next is read."""
    out = {} if turns is None else turns
    first: str | None = None
    for fut in parts:
        if len(fut):
            first = first or str(fut["drive"].iloc[0])
            for d, n in turn_counts(fut).items():
                out[d] = out.get(d, 0) + n
    return out, first


def most_turning(turns: dict[str, int]) -> str:
    """The drive with the most turn / roundabout queries (``turns``: drive -> count, not
    empty), the first by name among equals: what ``groupby("drive").size().idxmax()`` picks
    over a text column or :func:`~posbench.scoring.trace_set.lean_traces`' categorical one
    (sorted categories), whichever way the rows were read."""
    top = max(turns.values())
    return min(d for d, n in turns.items() if n == top)


def colors_for(preds: Sequence[str]) -> dict[str, Any]:
    """One colour per predictor, the same in every figure."""
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return {p: cmap(i % 10) for i, p in enumerate(preds)}


def warmup_mask(traces: pd.DataFrame) -> np.ndarray:
    """Boolean mask of the warm-up rows (all False without a ``warmup`` column)."""
    if "warmup" not in traces.columns:
        return np.zeros(len(traces), dtype=bool)
    mask: np.ndarray = traces["warmup"].fillna(False).astype(bool).to_numpy()
    return mask


def headline(traces: pd.DataFrame, columns: Sequence[str] | None = None) -> pd.DataFrame:
    """The rows the headline figures use: all but the warm-up (only ``columns`` of them, if
    given: filtering a few columns of a long run is much cheaper than all of them)."""
    if columns is not None:
        traces = traces[[c for c in dict.fromkeys([*columns, "warmup"]) if c in traces.columns]]
    w = warmup_mask(traces)
    return traces[~w] if w.any() else traces


def log_values(e: np.ndarray) -> tuple[np.ndarray, bool]:
    """Errors [m] ready for a log axis: values below :data:`FLOOR_M` raised to it; and
    whether any was."""
    low = e < FLOOR_M
    return (np.where(low, FLOOR_M, e), bool(low.any()))


def floor_note(clipped: bool) -> str:
    return f"; < {1000 * FLOOR_M:g} mm drawn at {1000 * FLOOR_M:g} mm" if clipped else ""


def finite_errors(df: pd.DataFrame) -> pd.DataFrame:
    return df[np.isfinite(df["error_m"].to_numpy(dtype=float))]


def gap_steps(t: np.ndarray) -> np.ndarray:
    """Mask of the steps between consecutive sorted query times ``t`` [s] that span a gap
    (an outage: longer than 2 s and than 5 median steps); lines are not drawn across them."""
    dt = np.diff(t)
    if dt.size == 0:
        return np.zeros(0, dtype=bool)
    return dt > max(2.0, 5 * float(np.median(dt)))
