"""The moment the paper's figures show of a drive, chosen and recorded while the drive is
replayed (:mod:`posbench.predictor_tools.paper_figures` draws them from these records, with no
second replay).

The moment is the fix whose reference course changes most over the following second (above
2 m/s), chosen from the drive's future queries alone (their reference positions, speeds and
labels are known before any predictor runs); the figures show the drive with the most turn or
roundabout queries. At that fix, ``lstm``'s own step is recorded: its resampled inputs, its
prediction and its current-position answers between the fix and the prediction. Positions
[m, ENU], times [s].
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from posbench.figures.style import TURN_LABELS
from posbench.replay.prepare import Queries

#: the predictor whose step the paper's figures show (the paper's system)
PAPER_PREDICTOR = "lstm"
#: the fewest future queries with a reference a drive needs for a moment
MIN_QUERIES = 20
#: the course change is taken over this many future queries (fixes)
COURSE_SPAN = 5
#: the slowest reference speed [m/s] at which a course change counts
MIN_SPEED_MPS = 2.0
#: current-position answers recorded between the fix and the prediction (both included)
NOW_POINTS = 5


def turn_queries(future: Queries) -> int:
    """How many of the future queries are labelled turn or roundabout."""
    return int(np.isin(future.label.astype(str), TURN_LABELS).sum())


def moment_fix(future: Queries) -> int | None:
    """The index of the future query (= of the fix it follows) whose reference course changes
    most over the next :data:`COURSE_SPAN` queries at more than :data:`MIN_SPEED_MPS`; the
    course is the direction between neighbouring queries' reference points (a fix apart).
    None with fewer than :data:`MIN_QUERIES` queries with a reference."""
    ok = np.flatnonzero(np.isfinite(future.ref_xy[:, 0]))
    rows = ok[np.argsort(future.t_issue[ok], kind="stable")]
    if rows.size < MIN_QUERIES:
        return None
    ref = future.ref_xy[rows]
    course = np.unwrap(np.arctan2(np.gradient(ref[:, 1]), np.gradient(ref[:, 0])))
    n = COURSE_SPAN
    change = np.abs(course[n:] - course[:-n])
    change[~(future.speed_mps[rows][:-n] > MIN_SPEED_MPS)] = 0
    return int(rows[int(np.argmax(change)) + n // 2])


def moment_probe(
    predictor: Any, future: Queries, horizon_s: float
) -> tuple[tuple[int, Callable[[], None]] | None, dict[str, Any]]:
    """The probe that records ``predictor``'s step at the drive's moment
    (:func:`~posbench.replay.loop.replay`'s ``probe``; None: no moment), and the record it
    fills: ``turns`` (:func:`turn_queries`) always; once the probe ran on a network step at
    that fix, ``t_fix``, ``grid`` (8, 2) the resampled inputs, ``pred`` (2,) the prediction
    ``horizon_s`` ahead, ``now_t`` and ``now_xy`` the current-position answers between the
    fix and the prediction. ``predictor``: the ``lstm`` (its ``last_step`` seam; one
    registered under that name without it records no step)."""
    record: dict[str, Any] = {"turns": turn_queries(future)}
    i = moment_fix(future)
    last_step = getattr(predictor, "last_step", None)
    if i is None or last_step is None:
        return None, record
    t_fix = float(future.t_issue[i])

    def probe() -> None:
        step = last_step()
        if step is None or step.t_fix != t_fix or step.bridged:
            return  # no network step on this fix (start-up, a restart, a fix gated out)
        ts = np.linspace(t_fix, t_fix + horizon_s, NOW_POINTS)
        record.update(
            t_fix=t_fix,
            grid=np.array(step.grid),
            pred=np.array(step.pred),
            now_t=ts,
            now_xy=np.array([predictor.position_at(t) for t in ts], dtype=float),
        )

    return (i, probe), record
