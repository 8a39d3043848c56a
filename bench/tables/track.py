"""The "where the error points" table: along- and cross-track errors per predictor and kind
(results.json ``track_errors``, :mod:`posbench.aggregation.track`), with the report's note."""

from __future__ import annotations

from typing import Any

import pandas as pd

from posbench.scoring.schema import KINDS
from posbench.tables.table import Table, as_float

#: the report's paragraph under the table
TRACK_NOTE = (
    "Each answer's error in the reference's heading frame (direction of travel from the "
    "reference 0.1 s before and after the query): `along` + = ahead, - = lagging behind; "
    "`cross` + = left, - = right of the direction of travel (a mean far from 0 is a side "
    "bias); `inward` = cross-track toward the inside of the turn while the reference turns "
    "at >= 0.05 rad/s (+ = cuts corners, - = runs wide; n = turning queries). Queries with "
    "the reference slower than 0.5 m/s have no heading: counted as `standstill`, not in "
    "these figures."
)


def track_table(res: dict[str, Any]) -> Table:
    """ "Where the error points": per predictor and kind, mean along, p95 |along|, mean
    cross, p95 |cross|, mean inward in turns [m], queries and standstill queries."""
    rows = []
    for name, kinds in res.get("track_errors", {}).get("predictors", {}).items():
        for k in KINDS:
            s = kinds[k]
            rows.append(
                {
                    "predictor": name,
                    "kind": k,
                    **{
                        c: as_float(s[c])
                        for c in (
                            "along_mean_m",
                            "along_p95_abs_m",
                            "cross_mean_m",
                            "cross_p95_abs_m",
                            "inward_mean_m",
                        )
                    },
                    "turning": s["turning"],
                    "n": s["count"],
                    "standstill": s["standstill"],
                }
            )
    labels = {
        "along_mean_m": "mean along [m]",
        "along_p95_abs_m": "p95 abs along [m]",
        "cross_mean_m": "mean cross [m]",
        "cross_p95_abs_m": "p95 abs cross [m]",
        "inward_mean_m": "mean inward, turns [m]",
    }
    cols = ["predictor", "kind", *labels, "turning", "n", "standstill"]
    frame = pd.DataFrame(rows, columns=cols)
    return Table(
        frame,
        "track_errors",
        labels,
        counts={"inward_mean_m": "turning"},
        title="Where the error points",
    )
