"""The predictor contract as runnable checks: what any :class:`~posbench.predictors.base.Predictor`
must do for ``bench run`` to score it fairly, checked on small deterministic drives.

:func:`check_contract` builds a predictor and runs every clause on it, returning a
:class:`ContractReport` (what ``bench check`` prints and :func:`posbench.check` returns):
one :class:`ClauseResult` per clause, each with the numbers that decided it. A clause never
raises: an exception from the predictor fails that clause and names where it was raised.

The inputs (built once per process, deterministic):

- the **drive**: the first built-in synthetic drive
  (``posbench.scenarios.synthetic.default_drives()[0]``), its first :data:`DRIVE_S` seconds
  (straight, turn, roundabout, straight, a stop) with its own recorded fixes
  (irregular 0.1-0.6 s, noisy, one dropout) and 50 Hz IMU / speed, replayed as the runner
  does (:func:`posbench.replay.loop.replay`: a "future" query :data:`HORIZON_S` after every
  fix, a "now" query every 0.05 s);
- a **straight line**: 15 m/s on a heading of 0.5 rad, IMU and speed at 50 Hz from t = 0,
  exact fixes at 5 Hz from t = 1 s;
- a **standstill**: the same streams for a car that does not move.

Comparisons of answers are exact up to :data:`SAME_M` (1e-9 m); two NaN answers are equal,
a NaN and a number are not. Every clause except ``reset`` builds fresh instances from the
factory (and calls ``reset()`` first, as the runner does), so one broken behaviour fails one
clause. The comparisons assume nothing about accuracy, only about sameness: a predictor
that draws random numbers without a fixed seed fails them all.

Units: seconds, metres (local ENU).
"""

from posbench.predictor_tools.contract.checker import (
    CLAUSE_IDS,
    CLAUSES,
    ClauseResult,
    check_predictor,
)
from posbench.predictor_tools.contract.report import (
    ContractReport,
    check_contract,
    resolve_predictor,
)

__all__ = [
    "CLAUSES",
    "CLAUSE_IDS",
    "ClauseResult",
    "ContractReport",
    "check_contract",
    "check_predictor",
    "resolve_predictor",
]
