"""``bench score`` as a library function: answers produced elsewhere, scored against a
``bench queries`` folder exactly as ``bench run`` scores a predictor it replays."""

from __future__ import annotations

import re
from pathlib import Path

from posbench.errors import UsageError
from posbench.naming import plural
from posbench.offline.answer_scoring import Scored
from posbench.pipeline.publish import Published
from posbench.pipeline.reporter import SILENT, Reporter
from posbench.report.table_files import TABLE_FORMATS

#: what a scored system may be called: it names the predictor in every table, file and key
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+@-]*$")


def check_score_options(answers: Path, queries: Path, name: str, out: Path | None) -> None:
    """The checks of ``bench score``'s paths and name, before anything is read.

    Raises:
        UsageError: a name that cannot name a predictor, a missing file or folder, an output
            folder that cannot be written.
    """
    from posbench.checks import check_out_dir

    if not NAME_PATTERN.match(name):
        raise UsageError(
            f"--name {name!r}: use letters, digits and _ . + @ - (starting with a letter or digit)"
        )
    if not answers.is_file():
        raise UsageError(f"ANSWERS {answers}: no such file")
    if not queries.is_dir():
        raise UsageError(
            f"--queries {queries}: no such folder (give the folder `bench queries` wrote)"
        )
    if out is not None:
        check_out_dir(out)


def score_answers_file(
    answers: Path,
    queries: Path,
    name: str,
    out: Path | None,
    command: str,
    *,
    plot_formats: tuple[str, ...] = ("png",),
    drive_plots: int | None = 20,
    table_formats: tuple[str, ...] = TABLE_FORMATS,
    reporter: Reporter = SILENT,
) -> Published:
    """Score the answers file ``answers`` as predictor ``name`` against the queries folder
    ``queries`` and publish the run (into ``out``, or in memory with None): the same
    report.md, results.json (config of the queries folder), traces and figures as
    ``bench run``. ``command`` is recorded in results.json.

    Raises:
        DataError: a queries folder or answers file that cannot be read, or answers that do
            not match the queries (the file and row named).
    """
    from posbench.offline.answer_scoring import score_answers
    from posbench.offline.answers import read_answers
    from posbench.offline.queries_folder import read_queries
    from posbench.pipeline.publish import OutputWriter, publish
    from posbench.pipeline.results import build_results
    from posbench.saved_run.provenance import tree_hash
    from posbench.scoring.records import all_traces

    with reporter.phase("reading the queries folder and the answers..."):
        folder = read_queries(queries)
        read = read_answers(answers)
    n = sum(d["skipped"] is None for d in folder.drives)
    with reporter.steps(f"scoring {plural(n, 'drive')}", n) as done:
        scored = score_answers(folder, read, name, on_done=done)
    ids = {d["name"]: d["id"] for d in folder.drives}
    reporter.line(answers_line(answers, scored, read.ignored, ids))
    cfg = folder.config(name)
    data = [*folder.manifest["data"], tree_hash(answers)]
    traces = all_traces(scored.runs)
    res = build_results(scored.runs, cfg, data, command, traces=traces, models={})
    res["answers"] = {
        "file": str(answers),
        "queries_folder": str(queries),
        "queries": scored.queries,
        "answered": scored.answered,
        "unanswered": scored.unanswered,
        "look_ahead_checked": False,
    }
    writer = (
        OutputWriter(out, tuple(plot_formats), drive_plots, tuple(table_formats))
        if out is not None
        else None
    )
    return publish(res, traces, scored.runs, writer, reporter)


def answers_line(
    path: Path, scored: Scored, ignored: list[str], ids: dict[str, str] | None = None
) -> str:
    """One line: how many queries were answered, and which were not (counted as missing),
    naming drives as the answers file does (``ids``: drive name -> id)."""
    ids = ids or {}
    text = f"{path}: {scored.answered} answers to {scored.queries} queries"
    if scored.missing:
        per = sorted(scored.unanswered.items(), key=lambda kv: -sum(kv[1].values()))
        fut = sum(m["future"] for m in scored.unanswered.values())
        shown = ", ".join(f"{ids.get(d, d)} {sum(m.values())}" for d, m in per[:5])
        more = f", {len(per) - 5} more drives" if len(per) > 5 else ""
        text += (
            f"; {scored.missing} queries without an answer (future {fut}, now "
            f"{scored.missing - fut}; {shown}{more}): scored as missing"
        )
    else:
        text += "; every query answered"
    if ignored:
        text += f" (ignored columns: {', '.join(ignored)})"
    return text
