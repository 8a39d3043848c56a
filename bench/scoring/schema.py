"""What a trace is: its columns (:data:`TRACE_COLUMNS`, with type, unit and meaning), the query
kinds (:data:`KINDS`), the scenario label categories, and which rows count in the headline
figures (:func:`scored_mask`).

``bench run`` replays a drive through each predictor and scores the answers
(:mod:`posbench.scoring.score`); answers that come from elsewhere (a file written by another
program) are scored the same way. Aggregation (:mod:`posbench.aggregation.aggregate`) works
from the traces only. The README's table of ``traces.parquet`` is generated from
:data:`TRACE_COLUMNS` (:func:`trace_columns_markdown`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from posbench.scenarios.labels import LABELS

#: the two kinds of query: the position at fix time + horizon, asked at the fix; the
#: current position, asked every now-step
KINDS = ("future", "now")
#: which queries the figures are over (the report's glossary collects this)
DEFINITIONS = {
    "scored queries": "every figure is over the queries of its row and cell (predictor; data "
    "set, route type, speed bin, drive) that are past their drive's warm-up "
    "(issued after its second received fix) and have a reference position; "
    "`future` and `now` queries are never mixed.",
}


#: the columns :func:`scored_mask` reads
SCORED_BY = ("x_ref", "y_ref", "warmup")


def scored_mask(traces: pd.DataFrame) -> np.ndarray:
    """Rows that count in the headline figures: past the warm-up (see
    :func:`posbench.replay.queries.warmup_end_s`) and with a known reference position."""
    if traces.empty:
        return np.zeros(0, dtype=bool)
    return scored_of(lambda c: traces[c].to_numpy() if c in traces else None)


def scored_of(column: Callable[[str], np.ndarray | None]) -> np.ndarray:
    """:func:`scored_mask` of the rows whose columns ``column`` gives (name -> numpy array,
    None where there is no such column): for a read that chooses its rows before they
    become a frame (:func:`posbench.scoring.trace_parts.read_part`'s ``keep``)."""
    x, y, warm = column("x_ref"), column("y_ref"), column("warmup")
    assert x is not None and y is not None
    m: np.ndarray = pd.notna(x) & pd.notna(y)
    if warm is not None:
        m &= ~warm.astype(bool)
    return m


#: column -> (type, unit, meaning); frames: x/y in the drive's local ENU metres
TRACE_COLUMNS: dict[str, tuple[str, str, str]] = {
    "dataset": ("str", "", "data set (the loader's format, e.g. kitti, aslan, synthetic)"),
    "drive": ("str", "", "drive name"),
    "predictor": ("str", "", "predictor name as run (NAME or NAME@ALIAS)"),
    "kind": (
        "category",
        "",
        "`future`: position at fix time + horizon, asked at the fix; "
        "`now`: current position, asked every now-step",
    ),
    "t_issue": (
        "float64",
        "s",
        "when the query was asked (every observation given is at or before it)",
    ),
    "t_query": ("float64", "s", "the instant whose position was asked for"),
    "x": ("float64", "m", "answer, east (NaN: no answer)"),
    "y": ("float64", "m", "answer, north"),
    "x_ref": (
        "float64",
        "m",
        "reference position, east (truth, or a cubic through the fixes; NaN: none)",
    ),
    "y_ref": ("float64", "m", "reference position, north"),
    "error_m": ("float64", "m", "Euclidean distance answer - reference"),
    "along_m": (
        "float64",
        "m",
        "error along the reference's direction of travel: + ahead, "
        "- lagging (NaN at standstill, below 0.5 m/s)",
    ),
    "cross_m": (
        "float64",
        "m",
        "error across the reference's direction of travel: + left, "
        "- right (ENU; NaN at standstill)",
    ),
    "label": (
        "category",
        "",
        "scenario at t_query: straight, turn, roundabout, start_stop, unlabelled",
    ),
    "speed_mps": ("float64", "m/s", "reference speed at t_query (NaN: unknown)"),
    "since_fix_s": ("float64", "s", "t_query minus the time of the last fix received by t_issue"),
    "outage": ("int64", "", "index of the GPS outage t_query falls in within its drive, -1: none"),
    "warmup": (
        "bool",
        "",
        "asked before the drive's second received fix (left out of headline figures)",
    ),
    "heading_ref": (
        "float64",
        "rad",
        "the reference's direction of travel at t_query, "
        "counter-clockwise from east (from the reference 0.1 s before and after; "
        "NaN: standstill or unknown)",
    ),
    "yaw_rate_ref": (
        "float64",
        "rad/s",
        "the reference's yaw rate at t_query, + = turning left (NaN: unknown)",
    ),
    "cov_xx": (
        "float64",
        "m^2",
        "the answer's reported covariance (`covariance_at`, ENU): "
        "variance east (NaN: the predictor reports no uncertainty for it)",
    ),
    "cov_xy": ("float64", "m^2", "reported covariance east-north"),
    "cov_yy": ("float64", "m^2", "reported variance north"),
}
#: the answer's reported uncertainty (filled with NaN in traces written before it existed)
COV_COLUMNS = ("cov_xx", "cov_xy", "cov_yy")
#: the columns a query table holds (all but the predictor and its answer)
ANSWER_COLUMNS = ("predictor", "x", "y", "error_m", "along_m", "cross_m", *COV_COLUMNS)
QUERY_COLUMNS = tuple(c for c in TRACE_COLUMNS if c not in ANSWER_COLUMNS)
#: query columns an answer key written before they existed may lack (filled with NaN)
TRACK_QUERY_COLUMNS = ("heading_ref", "yaw_rate_ref")
#: fixed categories keep the string columns of long traces at one byte a row, also
#: after concatenation (identical categories concatenate as categoricals)
LABEL_CATEGORIES = [*LABELS, "unlabelled"]
KIND_DTYPE = pd.CategoricalDtype(list(KINDS))


def trace_columns_markdown() -> str:
    """The Markdown table of :data:`TRACE_COLUMNS` (the README shows it; a test keeps the
    two equal)."""
    lines = ["| column | type | unit | meaning |", "|---|---|---|---|"]
    lines += [f"| `{c}` | {t} | {u or '-'} | {m} |" for c, (t, u, m) in TRACE_COLUMNS.items()]
    return "\n".join(lines)
