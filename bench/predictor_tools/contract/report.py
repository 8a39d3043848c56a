"""One predictor checked against the contract: :func:`check_contract` resolves a name (or
``module:Class``) into fresh instances, runs every clause
(:func:`~posbench.predictor_tools.contract.checker.check_predictor`) and returns a
:class:`ContractReport`."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from posbench.errors import UsageError
from posbench.predictor_tools.contract.checker import ClauseResult, check_predictor
from posbench.predictor_tools.contract.inputs import Factory
from posbench.predictor_tools.contract.measure import raised_line
from posbench.predictors.base import Predictor


@dataclass
class ContractReport:
    """The contract checked on one predictor.

    Attributes:
        predictor: the name (or ``module:Class``) as given.
        gated: whether it was checked behind the GPS outlier gate, as ``bench run`` runs it.
        clauses: one result per clause, in the order they ran.
        seconds: how long the check took [s].
    """

    predictor: str
    gated: bool
    clauses: list[ClauseResult] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def passed(self) -> bool:
        """Whether every clause passed."""
        return all(c.passed for c in self.clauses)

    @property
    def failed(self) -> list[ClauseResult]:
        """The clauses that failed."""
        return [c for c in self.clauses if not c.passed]

    def to_dict(self) -> dict[str, Any]:
        """The report as ``bench check --json`` prints it for one predictor."""
        return {
            "predictor": self.predictor,
            "gated": self.gated,
            "passed": self.passed,
            "seconds": round(self.seconds, 3),
            "clauses": [c.to_dict() for c in self.clauses],
        }

    def __repr__(self) -> str:
        head = (
            f"ContractReport({self.predictor}{' behind the gate' if self.gated else ''}: "
            f"{len(self.clauses) - len(self.failed)} of {len(self.clauses)} clauses pass)"
        )
        return "\n".join([head, *(f"  FAIL {c.clause}: {c.evidence}" for c in self.failed)])


def resolve_predictor(spec: str, options: Mapping[str, Any] | None = None) -> Factory:
    """A factory of fresh predictors for ``spec``: a registered or entry-point name (or
    ``NAME@ALIAS``), built with the registry's defaults and ``options``; or ``module:Class``,
    a :class:`Predictor` subclass imported from an importable module and built with
    ``options`` (:func:`posbench.predictors.registry.resolve`). One instance is built here, so that
    a predictor that cannot be built fails now. Raises :class:`UsageError` (one line) for an
    unknown name, a missing module or class, a class that is not a Predictor, or a predictor
    that cannot be built."""
    from posbench.predictors.registry import PredictorError, create, predictor_class

    opts = dict(options or {})
    try:
        predictor_class(spec)
    except PredictorError as e:
        raise UsageError(str(e)) from None

    def factory() -> Predictor:
        return create(spec, None, **opts)

    try:
        factory()
    except Exception as e:  # noqa: BLE001 - DataError, TypeError (abstract, arguments), ...
        raise UsageError(f"{spec} cannot be created: {raised_line(e)}") from None
    return factory


def check_contract(
    spec: str,
    options: Mapping[str, Any] | None = None,
    gate: bool = True,
    clauses: Sequence[str] | None = None,
) -> ContractReport:
    """Check predictor ``spec`` (a registered name, ``NAME@ALIAS`` or ``module:Class``, built
    with ``options``) against the contract: every clause, or those named in ``clauses``;
    with ``gate`` behind the GPS outlier gate, as ``bench run`` runs it.

    Raises:
        UsageError: an unknown name or a predictor that cannot be built (one line).
    """
    from posbench.replay.gps_outliers import GatedPredictor

    factory = resolve_predictor(spec, options)
    checked = (lambda: GatedPredictor(factory())) if gate else factory
    t0 = time.perf_counter()
    results = check_predictor(checked, spec, tuple(clauses) if clauses is not None else None)
    return ContractReport(spec, gate, results, time.perf_counter() - t0)
