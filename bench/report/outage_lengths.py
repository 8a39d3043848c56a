"""The report's section on outage lengths side by side (results.json's ``outage_lengths``,
schema 1.10): how the outages were cut and how many each length has, what the figures mean,
the curve and the tables (:mod:`posbench.tables.outage_lengths`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from posbench.figures.outage_lengths import NAME as FIGURE
from posbench.naming import plural
from posbench.tables.outage_lengths import FIGURES, outage_length_table

#: what the figures are, in one paragraph
OUTAGE_LENGTHS_NOTE = (
    "Per outage: FDE = current-position (now) error of its last query, just before the fix "
    "returns; ATE = root mean square of the now-error over its queries; % of distance = "
    "100 x sum of FDE (or ATE) / sum of the distance driven since the last fix (the "
    "reference's path length from the last fix before the outage to its last query), over "
    "the outages of one length. Every outage starts from a predictor that had fixes until "
    "then: these are errors after L seconds without GPS, not KITTI's t_rel (drift of an "
    "odometry over 100-800 m stretches; see the Concepts page *Outage lengths*). "
    "Intervals: 95 %, cluster bootstrap over drives."
)


def figure_file(plots: Sequence[str]) -> str | None:
    """The outage curve's file among the report's ``plots``, if drawn."""
    return next((p for p in plots if p.rsplit("/", 1)[-1].split(".")[0] == FIGURE), None)


def counts_line(res: dict[str, Any]) -> str:
    """How the outages were cut and how many each length has (and on how many drives)."""
    sec = res["outage_lengths"]
    parts = [
        f"{c['length_s']:g} s: {c['outages']} ({plural(c['drives'], 'drive')})"
        for c in sec["counts"].values()
    ]
    none = [f"{c['length_s']:g} s" for c in sec["counts"].values() if not c["outages"]]
    line = (
        f"Outages cut at {', '.join(f'{x:g}' for x in sec['lengths_s'])} s (dropout profile "
        f"`{sec['profile']}`): on each drive the longest lengths first, each while the drive "
        f"still had room for it after >= 10 s of reception, so a short drive gets only short "
        f"outages and a length that no drive had room for is left out. Outages per length "
        f"over {plural(sec['drives'], 'drive')}: {'; '.join(parts)}."
    )
    if none:
        line += f" No drive was long enough for: {', '.join(none)}."
    return line


def outage_length_lines(res: dict[str, Any], plots: Sequence[str] = ()) -> list[str]:
    """The section (empty without ``outage_lengths``): heading, counts, note, the curve when
    drawn (``plots``: the report's figure files), and a table per figure."""
    if not res.get("outage_lengths"):
        return []
    lines = ["## GPS outages by length", "", counts_line(res), "", OUTAGE_LENGTHS_NOTE, ""]
    fig = figure_file(plots)
    if fig is not None:
        lines += [f"![{fig}]({fig})", ""]
    for f, (_, what, _) in FIGURES.items():
        lines += [
            f"{what}, mean over outages [95 % CI] (outages):",
            "",
            outage_length_table(res, f).markdown(),
            "",
        ]
    return lines
