"""Running the contract: :data:`CLAUSES`, each clause of
:mod:`posbench.predictor_tools.contract.clauses` with its id and one-line description in the
order they run, and :func:`check_predictor`, which runs them on a predictor and gives each
one's :class:`ClauseResult`, a predictor's exception failing the clause it was raised in."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from posbench.predictor_tools.contract.clauses import (
    clause_covariance_psd,
    clause_deterministic,
    clause_finite_after_first_fix,
    clause_nan_before_first_fix,
    clause_no_look_ahead,
    clause_picklable,
    clause_query_order,
    clause_reset,
    clause_straight_line,
)
from posbench.predictor_tools.contract.inputs import (
    HORIZON_S,
    LINE_BOUND_M,
    LINE_SPEED,
    STAND_BOUND_M,
    Factory,
    Inputs,
    inputs,
)
from posbench.predictor_tools.contract.measure import raised_line


@dataclass(frozen=True)
class ClauseResult:
    """The outcome of one clause for one predictor.

    Attributes:
        clause: the clause's id (``reset``, ``no_look_ahead``, ...).
        description: what the clause requires, one line.
        passed: whether the predictor obeyed it.
        evidence: the numbers that decided it, one line.
    """

    clause: str
    description: str
    passed: bool
    evidence: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "clause": self.clause,
            "description": self.description,
            "passed": self.passed,
            "evidence": self.evidence,
        }


#: every clause: id, one-line description, function (its docstring says what it proves)
CLAUSES: tuple[tuple[str, str, Callable[[Factory, Inputs], tuple[bool, str]]], ...] = (
    (
        "reset",
        "reset() forgets the drive: a second replay gives the first one's answers",
        clause_reset,
    ),
    (
        "nan_before_first_fix",
        "(nan, nan) before the first fix, also after IMU and speed samples",
        clause_nan_before_first_fix,
    ),
    (
        "no_look_ahead",
        "an answer depends only on observations stamped up to its issue time",
        clause_no_look_ahead,
    ),
    (
        "finite_after_first_fix",
        "every answer from the first fix on is finite",
        clause_finite_after_first_fix,
    ),
    (
        "straight_line",
        f"within {LINE_BOUND_M:g} m on a {LINE_SPEED:g} m/s line "
        f"({HORIZON_S:g} s ahead), within {STAND_BOUND_M:g} m at standstill",
        clause_straight_line,
    ),
    (
        "query_order",
        "out-of-order and repeated queries: finite, same time gives same answer",
        clause_query_order,
    ),
    (
        "picklable",
        "pickled fresh and mid-drive, the copy answers like the original",
        clause_picklable,
    ),
    (
        "deterministic",
        "two fresh instances give the same answers on the same drive",
        clause_deterministic,
    ),
    (
        "covariance_psd",
        "covariance_at(t), if reported, is symmetric positive semi-definite",
        clause_covariance_psd,
    ),
)
#: the clause ids, in the order they run
CLAUSE_IDS: tuple[str, ...] = tuple(c for c, _, _ in CLAUSES)


def check_predictor(
    factory: Factory, name: str, clauses: tuple[str, ...] | None = None
) -> list[ClauseResult]:
    """Run the contract's clauses (all, or those named in ``clauses``) on the predictors that
    ``factory`` builds; ``name`` only words errors. Never raises for the predictor's faults:
    an exception inside a clause fails that clause with what was raised and where."""
    inp = inputs()
    out = []
    for cid, text, fn in CLAUSES:
        if clauses is not None and cid not in clauses:
            continue
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore", RuntimeWarning)
                passed, evidence = fn(factory, inp)
        except Exception as e:  # noqa: BLE001 - the predictor's fault is the clause's failure
            passed, evidence = False, f"{name} {raised_line(e)}"
        out.append(ClauseResult(cid, text, bool(passed), evidence))
    return out
