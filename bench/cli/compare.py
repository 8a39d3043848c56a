"""``bench compare``: saved runs side by side, and an accuracy regression gate for CI
(:func:`posbench.comparison.comparison.compare_runs` does the work)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from posbench.cli.options import ConfigOpt, OldFormatOpt, QuietOpt, VerboseOpt, renamed

if TYPE_CHECKING:
    import pandas as pd

    from posbench.comparison.comparison import Comparison
    from posbench.tables.table import Table

#: how the tables are printed and written
FORMATS = ("md", "csv", "latex")
#: the tables' leading name columns (repeated when a wide table is split)
KEY_COLUMNS = ("scope", "dataset", "group", "predictor", "kind")


def compare(
    runs: Annotated[
        list[Path],
        typer.Argument(
            metavar="RUN_DIR...",
            help="Folders written by `bench run` (or their results.json). With --fail-if-worse: "
            "exactly two, OLD then NEW.",
        ),
    ],
    metric: Annotated[
        str,
        typer.Option(
            metavar="KIND.STAT",
            help="The figure to compare: KIND future|now, STAT mean_m|median_m|rmse_m|p95_m|max_m.",
        ),
    ] = "future.mean_m",
    table_format: Annotated[
        str,
        typer.Option(
            "--table-format",
            metavar="md|csv|latex",
            help="How the table is printed and written (comparison.md / .csv / .tex).",
        ),
    ] = "md",
    scope: Annotated[
        list[str] | None,
        typer.Option(
            metavar="SCOPES",
            help="Rows to show, comma-separated or repeated: all (whole run), dataset, route "
            "(route type per data set; over all data sets in the uncertainty table), drive "
            "(error table only), since-fix (time since the last fix bins; uncertainty table "
            "only). Default: all,dataset.",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            metavar="DIR",
            help="Also write the table and comparison.png (bars per predictor, 95 % CI whiskers) "
            "into DIR.",
        ),
    ] = None,
    fail_if_worse: Annotated[
        list[str] | None,
        typer.Option(
            "--fail-if-worse",
            metavar="PRED:KIND.STAT:TOL",
            help="Gate (repeatable): exit 1 when NEW is worse than OLD by more than TOL (5% or "
            "0.01m) AND the paired 95 % CI of NEW - OLD (cluster bootstrap over shared drives) "
            "is above 0. Example: 'lstm:future.mean_m:5%'.",
        ),
    ] = None,
    allow_config_change: Annotated[
        bool,
        typer.Option(
            "--allow-config-change",
            help="Gate runs whose configurations differ (horizon, GPS profile, data, ...); "
            "by default that is an error.",
        ),
    ] = False,
    allow_failed: Annotated[
        bool,
        typer.Option(
            "--allow-failed",
            help="Also compare runs that failed or were interrupted (results.json status "
            "failed or interrupted: the run's command exited non-zero, its figures are not a "
            "whole run's); each is named in a note. By default such a run is an error.",
        ),
    ] = False,
    bootstrap_seed: Annotated[
        int,
        typer.Option(
            "--bootstrap-seed",
            metavar="INT",
            help="Seed of the paired bootstrap (not a run's --seed: that draws GPS noise).",
        ),
    ] = 0,
    uncertainty: Annotated[
        bool,
        typer.Option(
            "--uncertainty",
            help="Also compare the reported uncertainty (results.json `uncertainty`, schema 1.4), "
            "in a second table: per predictor that reports covariance and kind, mean NEES "
            "(2 = honest) [95 % CI over drives, whole run only], coverage of the 95 % "
            "ellipse, sharpness (median 95 % ellipse area, m^2), log-likelihood [nats], "
            "verdict, n. A predictor reporting none reads 'no uncertainty'; a run saved "
            "before schema 1.4 reads 'pre-1.4 run' (with a note). CSV: a second block "
            "after an empty line; --out also writes uncertainty_comparison.{md,csv,tex}.",
        ),
    ] = False,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    old_format: OldFormatOpt = None,
    old_seed: Annotated[int | None, typer.Option("--seed", hidden=True)] = None,
) -> None:
    """Compare saved runs: one figure per predictor, data set, route type and drive, aligned.

    The first run is the reference: every later run gets a paired difference (later - first,
    over the drives both scored) with its 95 % cluster-bootstrap CI; `*` marks a CI that
    excludes 0. Runs with different configurations are flagged (notes on stderr). A run that
    failed or was interrupted is refused unless --allow-failed. Exit status 1 when a gate
    fails.

    Examples:

      bench compare old-run new-run

      bench compare a b c --metric now.p95_m --table-format csv --out cmp

      bench compare main-run pr-run --fail-if-worse 'lstm:future.mean_m:5%'

      bench compare old-run new-run --uncertainty --scope all,dataset,since-fix
    """
    from posbench.checks import check_choice, check_out_dir
    from posbench.cli.terminal import console, err_console
    from posbench.comparison.comparison import compare_runs

    if old_format is not None:
        renamed("--format", "--table-format", "bench compare")
        table_format = old_format
    if old_seed is not None:
        renamed("--seed", "--bootstrap-seed", "bench compare")
        bootstrap_seed = old_seed
    check_choice(table_format, FORMATS, "--table-format")
    if out is not None:
        check_out_dir(out)
    scopes = [
        s.strip() for text in (scope or ["all,dataset"]) for s in text.split(",") if s.strip()
    ]
    result = compare_runs(
        runs,
        metric,
        scopes,
        bootstrap_seed,
        fail_if_worse or [],
        uncertainty,
        allow_config_change,
        allow_failed,
    )
    for line in result.differences:
        err_console.print(
            f"note: runs differ in {line}", highlight=False, soft_wrap=True, markup=False
        )
    for line in result.notes:
        err_console.print(f"note: {line}", highlight=False, soft_wrap=True, markup=False)
    _print(result.table, result.frame, table_format)
    if result.uncertainty is not None:
        if table_format == "csv" and not result.table.frame.empty:
            print()  # the second CSV block
        _print(*result.uncertainty, table_format)
    if out is not None:
        _write(out, result, table_format)
    for c in result.gates:
        console.print(c.line(), highlight=False, soft_wrap=True, markup=False)
    if not result.passed:
        failed = sum(c.failed for c in result.gates)
        err_console.print(
            f"accuracy gate failed: {failed} of {len(result.gates)} "
            f"(NEW {result.labels[1]} vs OLD {result.labels[0]})",
            highlight=False,
            markup=False,
        )
        raise typer.Exit(1)


def _print(table: Table, frame: pd.DataFrame, fmt: str) -> None:
    from posbench.cli.terminal import console, print_table

    if table.frame.empty:
        return
    if fmt == "csv":
        print(frame.to_csv(index=False), end="")
    elif fmt == "latex":
        print(table.latex(), end="")
    else:
        keys = sum(c in KEY_COLUMNS for c in table.frame.columns)
        print_table(
            console,
            table.header(),
            table.cells(),
            title=table.title,
            key_columns=keys,
            left_columns=keys,
        )


def _write_table(out: Path, stem: str, table: Table, frame: pd.DataFrame, fmt: str) -> Path:
    if fmt == "md":
        path = out / f"{stem}.md"
        path.write_text(f"# {table.title}\n\n{table.markdown()}\n")
    elif fmt == "csv":
        path = out / f"{stem}.csv"
        frame.to_csv(path, index=False)
    else:
        path = out / f"{stem}.tex"
        path.write_text(table.latex())
    return path


def _write(out: Path, result: Comparison, fmt: str) -> None:
    import matplotlib.pyplot as plt

    from posbench.cli.terminal import say
    from posbench.figures.style import save_figure

    out.mkdir(parents=True, exist_ok=True)
    written = [_write_table(out, "comparison", result.table, result.frame, fmt)]
    if result.uncertainty is not None:
        written.append(_write_table(out, "uncertainty_comparison", *result.uncertainty, fmt))
    fig = result.figure()
    written += save_figure(fig, out, "comparison", ("png",))
    plt.close(fig)
    say("written: " + ", ".join(str(p) for p in written))
