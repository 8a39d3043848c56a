"""Outage lengths side by side (results.json's ``outage_lengths``, schema 1.10): one table per
figure (FDE or ATE, in metres or % of the distance travelled since the last fix), a row per
predictor and a column per outage length, each cell with its 95 % interval. A run saved
before 1.10, or with another dropout profile, has no ``outage_lengths``: nothing here is
called then."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from posbench.tables.run_tables import ci_map, put_figure
from posbench.tables.table import Table, rows_frame

#: figure -> (table name, what it is, decimals)
FIGURES = {
    "fde_mean_m": ("outage_lengths_fde_m", "FDE [m]", 2),
    "fde_pct": ("outage_lengths_fde_pct", "FDE [% of distance]", 1),
    "ate_mean_m": ("outage_lengths_ate_m", "ATE [m]", 2),
    "ate_pct": ("outage_lengths_ate_pct", "ATE [% of distance]", 1),
}


def length_keys(res: Mapping[str, Any]) -> list[str]:
    """The length keys of the run's ``outage_lengths`` (``1s`` ... ``60s``), in order."""
    return list(res["outage_lengths"]["counts"])


def outage_length_table(res: Mapping[str, Any], figure: str = "fde_mean_m") -> Table:
    """``figure`` (a key of :data:`FIGURES`) per predictor (rows) and outage length
    (columns), with 95 % intervals and the outages it is over; a length that no drive was
    long enough for shows ``- (0)``."""
    name, what, digits = FIGURES[figure]
    sec = res["outage_lengths"]
    keys = length_keys(res)
    rows = []
    for p, by_length in sec["predictors"].items():
        row: dict[str, Any] = {"predictor": p}
        for k in keys:
            put_figure(row, k, by_length.get(k), figure)
            row[f"{k} n"] = (by_length.get(k) or {}).get("outages", 0)
        rows.append(row)
    cols = ["predictor"] + [x for k in keys for x in (k, f"{k}_lo", f"{k}_hi", f"{k} n")]
    labels = {k: f"{sec['counts'][k]['length_s']:g} s" for k in keys}
    labels["predictor"] = f"{what} after"
    return Table(
        rows_frame(rows, cols),
        name,
        labels,
        dict.fromkeys(keys, digits),
        {k: f"{k} n" for k in keys},
        title=f"{what} at the end of GPS outages, by outage length (outages)",
        ci=ci_map(keys),
    )


def outage_length_tables(res: Mapping[str, Any]) -> list[Table]:
    """Every table of :data:`FIGURES` (none without ``outage_lengths``)."""
    if not res.get("outage_lengths"):
        return []
    return [outage_length_table(res, f) for f in FIGURES]
