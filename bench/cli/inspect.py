"""``bench data inspect``: what is in each recording, and whether its streams agree."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from posbench.cli.options import (
    ConfigOpt,
    ProjectionOpt,
    QuietOpt,
    StrictOpt,
    TopicOpt,
    VerboseOpt,
    parse_topics,
)
from posbench.cli.terminal import console, print_table
from posbench.scenarios.text import fixed

HEADER = (
    "drive",
    "format",
    "dur [s]",
    "dist [m]",
    "fixes",
    "fix dt p5/p50/p95/max [ms]",
    "IMU [Hz]",
    "speed [m/s]",
    "stopped",
    "str/turn/rbt/stop [%]",
    "truth (acc.)",
    "scored fixes",
    "warn.",
)
#: the bag roles in the order inspect lists them
ROLES = ("gps", "truth", "imu", "speed")


def scored_fixes(drive: Any) -> str:
    """Which GPS fixes a run scores by default (:class:`~posbench.scenarios.drive.Drive`):
    the drive's own receiver against its truth, fixes simulated from the truth, or its own
    fixes against themselves when it has no truth."""
    if drive.truth is None:
        return "own (no truth)"
    return "simulated from truth" if drive.fixes_from_truth else "own receiver"


def topic_lines(extra: dict[str, Any]) -> list[str]:
    """One line per bag topic: role (``-`` for none), topic, message type and why, from the
    loader's ``meta.extra["topics"]`` / ``["unused_topics"]``; [] for other formats."""
    roles = extra.get("topics")
    if not isinstance(roles, dict) or not all(isinstance(v, dict) for v in roles.values()):
        return []
    rows = [
        (r, roles[r]["topic"], roles[r]["type"], roles[r].get("why", ""))
        for r in (*ROLES, *sorted(set(roles) - set(ROLES)))
        if r in roles
    ]
    rows += [
        ("-", t, v["type"], v.get("why", ""))
        for t, v in sorted((extra.get("unused_topics") or {}).items())
    ]
    w = [max(len(str(r[i])) for r in rows) for i in range(3)]
    return [f"{r[0]:<{w[0]}}  {r[1]:<{w[1]}}  {r[2]:<{w[2]}}  ({r[3]})" for r in rows]


def inspect_rows(summaries: list[dict[str, Any]]) -> tuple[tuple[str, ...], list[list[str]]]:
    """Header and cell strings of the inspect table, one row per drive summary
    (:func:`posbench.scenarios.summary.summarize_drive`: seconds, metres, m/s, Hz); the
    "scored fixes" column where the summaries hold ``scored_fixes`` (:func:`scored_fixes`,
    added by ``bench data inspect``)."""
    scored = bool(summaries) and all("scored_fixes" in r for r in summaries)
    out = []
    for r in summaries:
        q = r["gps_interval_ms"]
        acc = r["truth_median_accuracy_m"]
        stated = f" ({fixed(acc, 2)} m)" if acc is not None else ""
        truth = ("yes" + stated) if r["has_truth"] else "no"
        out.append(
            [
                r["name"],
                r["format"],
                fixed(r["duration_s"], 1),
                fixed(r["distance_m"], 0),
                str(r["gps_count"]),
                "/".join(fixed(q[k], 0) for k in ("p5", "p50", "p95", "max")),
                f"{r['imu_rate_hz']:.0f}",
                f"{fixed(r['speed_mps']['min'], 1)}-{fixed(r['speed_mps']['max'], 1)}",
                f"{100 * r['fraction_stopped']:.0f}%",
                "/".join(f"{100 * v:.0f}" for v in r["label_shares"].values()),
                truth,
                *([r["scored_fixes"]] if scored else []),
                str(len(r["warnings"])),
            ]
        )
    return (HEADER if scored else tuple(h for h in HEADER if h != "scored fixes")), out


def inspect(
    paths: Annotated[
        list[Path] | None,
        typer.Argument(
            metavar="PATH", help="Recordings or folders (default: the built-in synthetic drives)."
        ),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print a JSON list, one object per drive.")
    ] = False,
    topic: TopicOpt = None,
    projection: ProjectionOpt = "enu",
    strict: StrictOpt = False,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """Show what is in each drive: duration, distance, fix intervals, IMU rate, speeds, truth,
    and whether its streams agree with each other (the data consistency check)."""
    from posbench.cli.terminal import reporter
    from posbench.pipeline.data_check import check_drives, strict_error
    from posbench.pipeline.drives import load_drives
    from posbench.scenarios.remote import local_paths
    from posbench.scenarios.summary import summarize_drive

    topics = parse_topics(topic) or None
    with local_paths(paths) as local:  # fsspec URLs (file://, s3://, ...) read as bench run does
        drives = load_drives(local, projection, topics, reporter=reporter())
    checks = check_drives(drives)
    rows = [summarize_drive(d) for d in drives]
    for r, d in zip(rows, drives, strict=True):
        r["scored_fixes"] = scored_fixes(d)
        lines = topic_lines(d.meta.extra)
        if lines:
            r["topics"] = d.meta.extra["topics"]
            r["unused_topics"] = d.meta.extra.get("unused_topics", {})
            r["topic_lines"] = lines
    if as_json:
        for r, d in zip(rows, drives, strict=True):
            r["consistency"] = checks[d.name].to_dict()
            r.pop("topic_lines", None)
        print(json.dumps(rows, indent=2, default=float))
    else:
        print_inspect(rows, checks)
    err = strict_error(checks) if strict else None
    if err is not None:
        raise err


def print_inspect(rows: list[dict[str, Any]], checks: dict[str, Any]) -> None:
    """The inspect table, the consistency table and the warnings, on the console."""
    from posbench.report.data_check import flagged, table_rows

    header, cells = inspect_rows(rows)
    print_table(
        console,
        header,
        cells,
        title=f"{len(rows)} drive{'' if len(rows) == 1 else 's'}",
        key_columns=1,
        left_columns=2,
    )
    from rich.markup import escape

    for r in rows:
        if r.get("topic_lines"):
            console.print(
                f"{r['name']}: bag topics (role, topic, type, why)", markup=False, highlight=False
            )
            for line in r["topic_lines"]:
                console.print(f"  {line}", markup=False, highlight=False, soft_wrap=True)
    for r in rows:
        for w in r["warnings"]:
            console.print(f"[yellow]warning[/] {escape(r['name'])}: {escape(w)}", highlight=False)
    section = {d: c.to_dict() for d, c in checks.items()}
    check_header, check_cells = table_rows(section)
    print_table(
        console,
        check_header,
        check_cells,
        key_columns=1,
        left_columns=len(check_header),
        title="data consistency: each stream against the truth's motion, else what "
        "the GPS fixes imply (pass / warn / fail / n/a)",
    )
    for verdict, d, s, why in flagged(section, ("fail", "warn", "n/a")):
        console.print(f"{verdict} {escape(d)}: {s}: {escape(why)}", highlight=False)
