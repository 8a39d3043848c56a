"""`bench score`: score answers produced elsewhere against a `bench queries` folder."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from posbench.checks import check_out_dir
from posbench.cli.common import (
    DataError,
    DrivePlotsOpt,
    PlotFormatOpt,
    ReportFormatOpt,
    UsageError,
    command_line,
    console,
    fail,
)
from posbench.report.markdown import parse_report_formats

if TYPE_CHECKING:
    from posbench.offline.answers import Scored


#: what --name may be: it names the predictor in every table, file name and results key
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+@-]*$")


def score(
    answers: Annotated[Path, typer.Argument(
        metavar="ANSWERS", show_default=False,
        help="CSV or Parquet file: one row per answer, columns drive, kind (future|now), "
             "t_query [s], x, y [m], optional latency_us [us].")],
    queries: Annotated[Path, typer.Option(
        "--queries", "-q", metavar="DIR", show_default=False,
        help="The folder `bench queries` wrote (its key/ holds the references).")],
    name: Annotated[str, typer.Option(
        metavar="NAME", help="Name of the system under test in the report.")] = "answers",
    out: Annotated[Path, typer.Option("--out", "-o", metavar="DIR", help="Output folder.")
                   ] = Path("bench-out"),
    report_format: ReportFormatOpt = "md,csv,latex",
    plot_format: PlotFormatOpt = "png",
    drive_plots: DrivePlotsOpt = "20",
) -> None:
    """Score answers produced elsewhere exactly as `bench run` scores a predictor: the same
    report.md, results.json (config of the queries folder), traces.parquet, tables and plots.

    An answer matches the query of its drive and kind whose t_query is within 1e-6 s of its
    own: write times with at least 9 decimals (Python's repr of the float is exact). x, y are
    metres in the drive's local ENU frame, as in the inputs. A query without an answer is
    counted as missing (never dropped); an answer to no query, two answers to one query, a drive
    not in the queries folder, an empty or non-finite cell are errors naming the file and line.
    Answers from outside cannot be checked for look-ahead (use of inputs after t_issue); a
    predictor run by `bench run` can.

    Example: bench score answers.csv --queries bench-queries --name mynode --out mynode-run
    """
    from posbench.cli.run import drive_plot_limit, plot_formats

    try:
        if not NAME_PATTERN.match(name):
            raise UsageError(f"--name {name!r}: use letters, digits and _ . + @ - (starting with "
                             f"a letter or digit)")
        formats = plot_formats(plot_format)
        table_formats = parse_report_formats(report_format)
        n_drive_plots = drive_plot_limit(drive_plots)
        if not answers.is_file():
            raise UsageError(f"ANSWERS {answers}: no such file")
        if not queries.is_dir():
            raise UsageError(f"--queries {queries}: no such folder (give the folder `bench "
                             f"queries` wrote)")
        check_out_dir(out)
        _score(answers, queries, name, out, formats, n_drive_plots, table_formats)
    except (DataError, UsageError) as e:
        raise fail(str(e)) from None


def _score(answers_path: Path, queries_dir: Path, name: str, out: Path,
           formats: tuple[str, ...], drive_plots: int | None,
           table_formats: tuple[str, ...] = ("csv", "latex")) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from posbench.cli.run import plural, publish
    from posbench.offline.answers import read_answers, score_answers
    from posbench.offline.queries_folder import read_queries
    from posbench.pipeline.results import build_results
    from posbench.saved_run.provenance import tree_hash
    from posbench.scoring.records import all_traces

    with console.status("reading the queries folder and the answers..."):
        folder = read_queries(queries_dir)
        answers = read_answers(answers_path)
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), TextColumn("{task.fields[last]}"), console=console) as prog:
        n = sum(d["skipped"] is None for d in folder.drives)
        task = prog.add_task(f"scoring {plural(n, 'drive')}", total=n, last="")
        scored = score_answers(folder, answers, name,
                               on_done=lambda d: prog.update(task, advance=1, last=d))
    ids = {d["name"]: d["id"] for d in folder.drives}
    console.print(answers_line(answers_path, scored, answers.ignored, ids), highlight=False)
    cfg = folder.config(name)
    data = [*folder.manifest["data"], tree_hash(answers_path)]
    traces = all_traces(scored.runs)
    res = build_results(scored.runs, cfg, data, command_line(), traces=traces, models={})
    res["answers"] = {"file": str(answers_path), "queries_folder": str(queries_dir),
                      "queries": scored.queries, "answered": scored.answered,
                      "unanswered": scored.unanswered, "look_ahead_checked": False}
    publish(res, traces, scored.runs, out, formats, drive_plots, table_formats=table_formats)


def answers_line(path: Path, scored: Scored, ignored: list[str],
                 ids: dict[str, str] | None = None) -> str:
    """One line: how many queries were answered, and which were not (counted as missing),
    naming drives as the answers file does (``ids``: drive name -> id)."""
    ids = ids or {}
    text = f"{path}: {scored.answered} answers to {scored.queries} queries"
    if scored.missing:
        per = sorted(scored.unanswered.items(), key=lambda kv: -sum(kv[1].values()))
        fut = sum(m["future"] for m in scored.unanswered.values())
        shown = ", ".join(f"{ids.get(d, d)} {sum(m.values())}" for d, m in per[:5])
        more = f", {len(per) - 5} more drives" if len(per) > 5 else ""
        text += (f"; {scored.missing} queries without an answer (future {fut}, now "
                 f"{scored.missing - fut}; {shown}{more}): scored as missing")
    else:
        text += "; every query answered"
    if ignored:
        text += f" (ignored columns: {', '.join(ignored)})"
    return text
