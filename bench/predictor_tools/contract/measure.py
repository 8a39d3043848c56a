"""What the contract's clauses measure with: a replay's answers in one array
(:func:`run_replay`), distances [m] between two sets of answers, evidence text, and the one
line that says what a predictor raised and where (:func:`raised_line`). Units: seconds,
metres (local ENU)."""

from __future__ import annotations

import math
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posbench.predictor_tools.contract.inputs import HORIZON_S, Factory
from posbench.predictors.base import Predictor
from posbench.replay.loop import replay
from posbench.replay.prepare import PreparedDrive

#: the contract's own code (this module, the clauses and the checker that runs them): a
#: frame there is never where a predictor failed
_OWN_FILES = frozenset(
    str(Path(__file__).with_name(name)) for name in ("measure.py", "clauses.py", "checker.py")
)


@dataclass(frozen=True)
class Answers:
    """A replay's answers in one array: query time [s], issue time [s], x, y [m]."""

    t_query: np.ndarray
    t_issue: np.ndarray
    xy: np.ndarray  # (N, 2)

    def __len__(self) -> int:
        return int(self.t_query.size)


def run_replay(factory: Factory, prep: PreparedDrive, pred: Predictor | None = None) -> Answers:
    """Replay ``prep`` through a fresh predictor (or ``pred``) with
    :func:`posbench.replay.loop.replay`; future answers first, then the now answers."""
    p = factory() if pred is None else pred
    res = replay(p, prep, HORIZON_S)
    return Answers(
        np.concatenate([prep.future.t_query, prep.now.t_query]),
        np.concatenate([prep.future.t_issue, prep.now.t_issue]),
        np.concatenate([res.future_xy, res.now_xy]).astype(float),
    )


def differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance [m] between answers row by row: 0 where the rows are equal (NaN equal to NaN),
    inf where they differ and one holds a NaN or an inf."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    with np.errstate(invalid="ignore", over="ignore"):
        d: np.ndarray = np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1])
        same = np.all((a == b) | (np.isnan(a) & np.isnan(b)), axis=1)
    d[same] = 0.0
    d[~np.isfinite(d)] = np.inf
    return d


def metres(x: float) -> str:
    """A distance for evidence lines: ``0 m``, ``3.2e-12 m``, ``0.412 m``, or ``inf m (a NaN
    or inf on one side)``."""
    if x == 0.0:
        return "0 m"
    if not math.isfinite(x):
        return "inf m (a NaN or inf on one side)"
    return f"{x:.3g} m" if x < 1e-3 else f"{x:.3f} m"


def xy_text(p: tuple[float, float] | np.ndarray) -> str:
    """A position [m] for evidence lines: ``(1.234, -0.500)``."""
    return f"({float(p[0]):.3f}, {float(p[1]):.3f})"


def raised_line(e: BaseException) -> str:
    """``raised TypeError: msg (file.py:12)``, one line."""
    text = str(e).strip().splitlines()
    msg = f"raised {type(e).__name__}" + (f": {text[0][:200]}" if text else "")
    # where: the innermost frame outside the contract's own code (pickle, numpy in C leave none)
    tb = [f for f in traceback.extract_tb(e.__traceback__) if f.filename not in _OWN_FILES]
    if tb:
        msg += f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})"
    return msg
