"""Implausible results named, not hidden: predictors that lose to constant velocity.

A filter or learned model that predicts worse than extrapolating the last two fixes has a
defect on that data (an input trusted more than it deserves, noise tuned on other
sensors) or is not doing its job; its win over any other method proves nothing. Per data
set and query kind, each predictor is compared with ``cv`` on the queries both answered
(the run's paired bootstrap); a loss counts when the whole 95 % interval of its mean
error minus cv's lies above 0.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from posbench.aggregation.intervals import Statistics
from posbench.aggregation.paired_sums import drive_indices, group_entry, paired_sums, rereader
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet

#: the predictor every other is checked against
REFERENCE = "cv"


def sanity_section(
    traces: TraceSet,
    predictors: Sequence[str],
    datasets: Sequence[str],
    stats: Statistics,
) -> dict[str, Any]:
    """``{"reference": "cv", "checked": bool, "losses": [...]}``; each loss: dataset,
    predictor, kind, ``diff_m`` (its mean error minus cv's [m], > 0), ``ci95``, ``queries``.
    ``checked`` is False (no losses listed) when cv is not in the run."""
    out: dict[str, Any] = {"reference": REFERENCE, "checked": False, "losses": []}
    if REFERENCE not in predictors or traces.empty:
        return out
    out["checked"] = True
    for name in predictors:
        if name == REFERENCE:
            continue
        sums = paired_sums(traces, name, REFERENCE)
        if not sums.drives:
            continue
        again = rereader(traces, name, REFERENCE, sums)
        for ds in datasets:
            keep = drive_indices(sums, dataset=ds)
            for i, kind in enumerate(KINDS):
                e = group_entry(sums, keep, i, 0, again, stats)
                lo = e["ci95"][0] if e.get("ci95") else None
                if e["queries"] and lo is not None and np.isfinite(lo) and lo > 0.0:
                    out["losses"].append(
                        {
                            "dataset": ds,
                            "predictor": name,
                            "kind": kind,
                            "diff_m": e["diff_m"],
                            "ci95": list(e["ci95"]),
                            "queries": e["queries"],
                        }
                    )
    return out
