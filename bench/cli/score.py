"""``bench score``: score answers produced elsewhere against a ``bench queries`` folder
(:mod:`posbench.pipeline.score` does the work)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.options import (
    ConfigOpt,
    DrivePlotsOpt,
    OldFormatOpt,
    PlotFormatOpt,
    QuietOpt,
    TableFormatOpt,
    VerboseOpt,
    WideOpt,
    command_line,
    renamed,
)


def score(
    answers: Annotated[
        Path,
        typer.Argument(
            metavar="ANSWERS",
            show_default=False,
            help="CSV or Parquet file: one row per answer, columns drive, kind (future|now), "
            "t_query [s], x, y [m], optional latency_us [us]. Or a TUM file (.tum): the now "
            "answers of one drive, lines `t_query x y z qx qy qz qw`.",
        ),
    ],
    queries: Annotated[
        Path,
        typer.Option(
            "--queries",
            metavar="DIR",
            show_default=False,
            help="The folder `bench queries` wrote (its key/ holds the references).",
        ),
    ],
    name: Annotated[
        str, typer.Option(metavar="NAME", help="Name of the system under test in the report.")
    ] = "answers",
    out: Annotated[Path, typer.Option("--out", "-o", metavar="DIR", help="Output folder.")] = Path(
        "bench-out"
    ),
    table_format: TableFormatOpt = "md,csv,latex",
    plot_format: PlotFormatOpt = "png",
    drive_plots: DrivePlotsOpt = "20",
    wide: WideOpt = False,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    old_format: OldFormatOpt = None,
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

    A TUM file (name ending .tum; `t_query x y z qx qy qz qw` per line, whitespace-separated,
    # comments; z and the quaternion are ignored) answers the now queries of one drive, its
    other queries counted as missing: the drive a `# drive: NAME` line names, else the drive
    id the file name starts with (ID.tum, ID.mynode.now.tum). Its timestamps are t_query as
    in queries.csv (seconds from the drive's first input sample, not Unix time). `bench
    export RUN_DIR --format tum` writes such files from a saved run (DRIVE.PREDICTOR.now.tum).

    Example: bench score answers.csv --queries bench-queries --name mynode --out mynode-run
    """
    from posbench.checks import parse_drive_plots, parse_plot_formats
    from posbench.cli.summary import print_run_summary
    from posbench.cli.terminal import reporter
    from posbench.pipeline.score import check_score_options, score_answers_file
    from posbench.report.table_files import parse_report_formats

    if old_format is not None:
        renamed("--format", "--table-format", "bench score")
        table_format = old_format
    check_score_options(answers, queries, name, out)
    published = score_answers_file(
        answers,
        queries,
        name,
        out,
        command_line(),
        plot_formats=parse_plot_formats(plot_format),
        drive_plots=parse_drive_plots(drive_plots),
        table_formats=parse_report_formats(table_format, "--table-format"),
        reporter=reporter(),
    )
    print_run_summary(published, wide=wide)
