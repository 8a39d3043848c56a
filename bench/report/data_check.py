"""The data consistency check as people read it: a table per drive and stream (``bench data
inspect``), the lines at the top of ``bench run``'s terminal and the section at the top of
report.md, from the ``consistency`` key of results.json
(:mod:`posbench.pipeline.data_check` makes it; the checks themselves are
:mod:`posbench.scenarios.consistency`, pure, on a Drive).
"""

from __future__ import annotations

from typing import Any

from posbench.scenarios.consistency import (
    FAIL,
    NA,
    STREAMS,
    WARN,
    Check,
    worst,
)
from posbench.scenarios.text import fixed

#: the figures shown in a table cell, per stream: (name, text around the figure, decimals,
#: sign: "+" always signed)
_CELL: dict[str, tuple[tuple[str, str, int, str], ...]] = {
    "imu.yaw_rate": (
        ("scale", "x{}", 2, ""),
        ("corr", "r {}", 2, ""),
        ("lag_s", "{} s", 2, "+"),
    ),
    "imu.ax": (
        ("scale", "x{}", 2, ""),
        ("corr", "r {}", 2, ""),
        ("bias_mps2", "{} m/s²", 2, "+"),
    ),
    "imu.yaw": (("offset_deg", "{}°", 1, "+"), ("spread_deg", "sd {}°", 1, "")),
    "speed": (("scale", "x{}", 3, ""),),
    "gps": (
        ("scatter_m", "{} m", 2, ""),
        ("stated_m", "/ {} m", 2, ""),
        ("truth_offset_m", "off {} m", 1, ""),
    ),
    "truth": (
        ("offset_m", "{} m", 2, ""),
        ("rms_m", "rms {} m", 2, ""),
        ("rotation_deg", "{}°", 2, "+"),
        ("scale", "x{}", 3, ""),
    ),
}


def cell(c: Check) -> str:
    """One table cell: the verdict and the stream's main figures (a huge one in scientific
    notation, :func:`~posbench.scenarios.text.fixed`)."""
    if c.verdict == NA:
        return NA
    figs = [
        text.format(fixed(c.figures[k], decimals, sign))
        for k, text, decimals, sign in _CELL[c.stream]
        if c.figures.get(k) is not None and c.figures[k] == c.figures[k]
    ]
    return " ".join([c.verdict, *figs])


def table_rows(drives: dict[str, dict[str, Any]]) -> tuple[list[str], list[list[str]]]:
    """Header and cells of the consistency table from results.json's ``drives`` mapping
    (drive -> stream -> {verdict, reason, figures})."""
    header = ["drive", *STREAMS, "worst"]
    rows = []
    for d, streams in drives.items():
        checks = [Check(**streams[s]) for s in STREAMS if s in streams]
        rows.append([d, *(cell(c) for c in checks), worst([c.verdict for c in checks])])
    return header, rows


def flagged(
    drives: dict[str, dict[str, Any]], verdicts: tuple[str, ...] = (FAIL, WARN)
) -> list[tuple[str, str, str, str]]:
    """(verdict, drive, stream, reason) of every check with one of ``verdicts``, fails first."""
    out = [
        (c["verdict"], d, s, c["reason"])
        for d, streams in drives.items()
        for s, c in streams.items()
        if c["verdict"] in verdicts
    ]
    return sorted(out, key=lambda r: verdicts.index(r[0]))


def summary_lines(section: dict[str, Any]) -> list[str]:
    """Plain lines for the terminal: every failure, the warnings counted (first few named),
    and the predictors that used a failing stream."""
    found = flagged(section["drives"])
    fails = [r for r in found if r[0] == FAIL]
    warns = [r for r in found if r[0] == WARN]
    lines = [f"data check FAIL {d}: {s}: {why}" for _, d, s, why in fails]
    if warns:
        shown = "; ".join(f"{d}: {s}: {why}" for _, d, s, why in warns[:3])
        more = f" (+{len(warns) - 3} more in report.md)" if len(warns) > 3 else ""
        lines.append(
            f"data check: {len(warns)} warning{'s' if len(warns) != 1 else ''}: {shown}{more}"
        )
    for p, hits in section.get("affected_predictors", {}).items():
        lines.append(
            f"data check: {p} used a failing stream ({'; '.join(hits)}): its figures "
            "on those drives are not valid"
        )
    return lines


def report_lines(res: dict[str, Any]) -> list[str]:
    """The Markdown section at the top of report.md (empty when no check failed or warned)."""
    section = res.get("consistency")
    if not section:
        return []
    found = flagged(section["drives"])
    if not found:
        return [
            "Data consistency check: every stream of every drive passed or could not be "
            "judged (n/a); see `bench data inspect`.",
            "",
        ]
    lines = [
        "## Data consistency check",
        "",
        "Each IMU and speed stream was compared with the truth's motion where the drive "
        "has a truth (else with what the GPS fixes imply), and the GPS with the truth "
        "relative to the accuracy the fixes state; a `fail` means figures computed from "
        "that stream are not valid.",
        "",
    ]
    lines += [f"- **{v}** `{d}` {s}: {why}" for v, d, s, why in found]
    aff = section.get("affected_predictors", {})
    if aff:
        lines += [
            "",
            "Predictors that used a failing stream (their figures on those drives are not valid):",
            "",
        ]
        lines += [f"- `{p}`: " + "; ".join(hits) for p, hits in aff.items()]
    return lines + [""]
