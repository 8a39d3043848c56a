"""The accuracy gate of ``bench compare --fail-if-worse``: NEW fails when one of its figures
is worse than OLD's by more than a tolerance and the paired CI of NEW - OLD
(:func:`posbench.comparison.paired.paired_difference`) is above 0."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from posbench.comparison.align import Metric
from posbench.comparison.paired import PairedDifference, paired_difference
from posbench.errors import UsageError
from posbench.saved_run.run import Run


@dataclass(frozen=True)
class Gate:
    """``PREDICTOR:KIND.STAT:TOL``: the NEW run fails when its figure is worse (larger) than
    the OLD run's by more than the tolerance **and** the paired CI of NEW - OLD excludes 0.

    ``tolerance`` is a fraction of the OLD figure when ``relative`` (``5%``), else metres
    (``0.01m``)."""

    predictor: str
    metric: Metric
    tolerance: float
    relative: bool
    text: str

    @classmethod
    def parse(cls, text: str) -> Gate:
        option = f"--fail-if-worse {text!r}"
        parts = text.strip().split(":")
        if len(parts) != 3 or not all(p.strip() for p in parts):
            raise UsageError(
                f"{option}: expected PREDICTOR:KIND.STAT:TOLERANCE, e.g. "
                f"'lstm:future.mean_m:5%' or 'kf:now.p95_m:0.01m'"
            )
        pred, metric, tol = (p.strip() for p in parts)
        m = re.fullmatch(r"([0-9]*\.?[0-9]+)\s*(%|m)", tol)
        if not m:
            raise UsageError(
                f"{option}: tolerance {tol!r} must be a percentage (5%) or metres (0.01m)"
            )
        value = float(m.group(1))
        relative = m.group(2) == "%"
        return cls(
            pred,
            Metric.parse(metric, option),
            value / 100 if relative else value,
            relative,
            text.strip(),
        )

    def limit(self, old: float) -> float:
        """The largest NEW figure that passes, given the OLD one [m]."""
        return old * (1 + self.tolerance) if self.relative else old + self.tolerance


@dataclass(frozen=True)
class GateCheck:
    """One gate's outcome: passed or not, with the figures behind it."""

    gate: Gate
    paired: PairedDifference
    limit: float

    @property
    def failed(self) -> bool:
        """NEW beyond the limit and the paired CI of NEW - OLD entirely above 0."""
        return bool(self.paired.new > self.limit and self.paired.lo > 0)

    def line(self) -> str:
        p = self.paired
        verdict = "FAILED" if self.failed else "passed"
        return (
            f"{verdict}: {self.gate.predictor} {self.gate.metric} {p.new:.4f} m (NEW) vs "
            f"{p.old:.4f} m (OLD), limit {self.limit:.4f} m; NEW - OLD {p.diff:+.4f} m, "
            f"95 % CI [{p.lo:+.4f}, {p.hi:+.4f}] over {p.drives} shared drives"
        )


def check_gates(old: Run, new: Run, gates: Sequence[Gate], seed: int = 0) -> list[GateCheck]:
    """Each gate checked on NEW against OLD (a :class:`UsageError` when a gate names a
    predictor one of the runs lacks or the runs share no scored drive)."""
    out = []
    for g in gates:
        for run, which in ((old, "OLD"), (new, "NEW")):
            if g.predictor not in run.predictors:
                raise UsageError(
                    f"--fail-if-worse {g.text!r}: the {which} run has no predictor "
                    f"{g.predictor!r} (it has {', '.join(run.predictors)})"
                )
        paired = paired_difference(old, new, g.predictor, g.metric, seed)
        if paired is None:
            raise UsageError(f"--fail-if-worse {g.text!r}: the runs share no scored drive")
        out.append(GateCheck(g, paired, g.limit(paired.old)))
    return out
