"""Sections of report.md that a run has only sometimes, each as Markdown lines (none when
the run has no such section): the sanity check against constant velocity, where answers
scored by ``bench score`` came from, the repeats over seeds and the GPS outlier gate."""

from __future__ import annotations

from typing import Any

from posbench.tables.breakdown_tables import gate_drive_table, gate_table
from posbench.tables.stat_tables import seeds_table


def sanity_report_lines(res: dict[str, Any]) -> list[str]:
    """The sanity check against constant velocity (results.json ``sanity``): a heading and
    one line per predictor that loses to cv on a data set, or one line that none does."""
    from posbench.report.notes import sanity_lines

    section = res.get("sanity")
    if not section or not section.get("checked"):
        return []
    lines = sanity_lines(res)
    if not lines:
        return [
            "Sanity check: no predictor loses to constant velocity (`cv`) on any data set "
            "(paired 95 % CI of the difference in mean error above 0).",
            "",
        ]
    return [
        "### Implausible results",
        "",
        "A predictor that loses to constant velocity (`cv`, the last two fixes extrapolated) "
        "on the same queries, with the paired 95 % interval of the difference above 0:",
        "",
        *[f"- {line}" for line in lines],
        "",
    ]


def answers_lines(res: dict[str, Any]) -> list[str]:
    """For answers scored by ``bench score``: where they came from, how many queries they
    left unanswered, and what posbench could not check."""
    a = res.get("answers")
    if not a:
        return []
    missing = a["queries"] - a["answered"]
    return [
        f"Answers produced outside posbench (`{a['file']}`), scored against the queries "
        f"folder `{a['queries_folder']}`: {a['answered']} of {a['queries']} queries answered"
        + (
            f", {missing} without an answer (scored as `missing`; per drive in the drive "
            f"notes of results.json)"
            if missing
            else ""
        )
        + ". posbench cannot check such answers for look-ahead (use of inputs stamped after "
        "the query's t_issue), as it does for a predictor it replays; latency is what the "
        "file's `latency_us` column gives (`-`: none given).",
        "",
    ]


def seeds_lines(res: dict[str, Any]) -> list[str]:
    """The "Repeated over seeds" section (runs with --seeds)."""
    seeds = res.get("seeds")
    if not seeds:
        return []
    listed = ", ".join(str(s) for s in seeds["seeds"])
    return [
        f"## Repeated over {len(seeds['seeds'])} seeds ({listed})",
        "",
        f"The same drives and predictors replayed with each seed's GPS noise and dropouts. "
        f"Every other figure, interval, table and plot of this report, and traces.parquet, "
        f"are from seed {seeds['traces_seed']}; results.json keeps each seed's headline "
        f"figures (`seeds.runs`). Beside seed {seeds['traces_seed']}'s mean and its 95 % "
        f"interval (other drives), the spread over seeds (other random draws):",
        "",
        seeds_table(res).markdown(),
        "",
    ]


def gate_lines(res: dict[str, Any]) -> list[str]:
    """The "GPS outlier gate" section: fixes rejected per predictor, and per drive."""
    gate = res.get("gate")
    if not gate:
        return []
    lines = ["## GPS outlier gate: fixes rejected per predictor", ""]
    if not gate.get("enabled"):
        if res.get("answers"):
            return lines + [
                "None: answers scored by `bench score` come from a system that got "
                "every fed fix; any gating is its own.",
                "",
            ]
        return lines + ["Off (`--no-gate`): every fix reached the predictors, as in the paper.", ""]
    lines += [
        "A fix implying impossible motion (speed > 60 m/s, or a miss of the constant-velocity "
        "prediction beyond 15 m/s^2 of acceleration plus 4 sigma of fix noise; a repeated "
        "stale fix while moving) is dropped before the predictor and bridged like a "
        "missing fix. Scores still use the ungated reference.",
        "",
    ]
    lines += [gate_table(res).markdown(), ""]
    per_drive = gate_drive_table(res)
    if not per_drive.frame.empty:
        lines += [per_drive.markdown(), ""]
    return lines
