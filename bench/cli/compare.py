"""`bench compare`: saved runs side by side, and an accuracy regression gate for CI."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.common import DataError, UsageError, console, err_console, fail

FORMATS = ("md", "csv", "latex")


SCOPES = ("all", "dataset", "route", "drive", "since-fix")


#: the tables' leading name columns (repeated when a wide table is split)
KEY_COLUMNS = ("scope", "dataset", "group", "predictor", "kind")


#: --scope names -> row scopes of the tables
SCOPE_ROWS = {"route": "route type", "since-fix": "since fix"}


def compare(
    runs: Annotated[list[Path], typer.Argument(
        metavar="RUN_DIR...",
        help="Folders written by `bench run` (or their results.json). With --fail-if-worse: "
             "exactly two, OLD then NEW.")],
    metric: Annotated[str, typer.Option(
        metavar="KIND.STAT",
        help="The figure to compare: KIND future|now, STAT mean_m|median_m|rmse_m|p95_m|max_m.")
    ] = "future.mean_m",
    fmt: Annotated[str, typer.Option(
        "--format", metavar="md|csv|latex",
        help="How the table is printed and written (comparison.md / .csv / .tex).")] = "md",
    scope: Annotated[str, typer.Option(
        metavar="SCOPES",
        help="Comma-separated rows to show: all (whole run), dataset, route (route type per "
             "data set; over all data sets in the uncertainty table), drive (error table "
             "only), since-fix (time since the last fix bins; uncertainty table only).")
    ] = "all,dataset",
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", metavar="DIR",
        help="Also write the table and comparison.png (bars per predictor, 95 % CI whiskers) "
             "into DIR.")] = None,
    fail_if_worse: Annotated[list[str] | None, typer.Option(
        "--fail-if-worse", metavar="PRED:KIND.STAT:TOL",
        help="Gate (repeatable): exit 1 when NEW is worse than OLD by more than TOL (5% or "
             "0.01m) AND the paired 95 % CI of NEW - OLD (cluster bootstrap over shared drives) "
             "is above 0. Example: 'lstm:future.mean_m:5%'.")] = None,
    allow_config_change: Annotated[bool, typer.Option(
        "--allow-config-change",
        help="Gate runs whose configurations differ (horizon, GPS profile, data, ...); "
             "by default that is an error.")] = False,
    seed: Annotated[int, typer.Option(metavar="INT", help="Seed of the paired bootstrap.")] = 0,
    uncertainty: Annotated[bool, typer.Option(
        "--uncertainty",
        help="Also compare the reported uncertainty (results.json `uncertainty`, schema 1.4), "
             "in a second table: per predictor that reports covariance and kind, mean NEES "
             "(2 = honest) [95 % CI over drives, whole run only], coverage of the 95 % "
             "ellipse, sharpness (median 95 % ellipse area, m^2), log-likelihood [nats], "
             "verdict, n. A predictor reporting none reads 'no uncertainty'; a run saved "
             "before schema 1.4 reads 'pre-1.4 run' (with a note). CSV: a second block "
             "after an empty line; --out also writes uncertainty_comparison.{md,csv,tex}.")
    ] = False,
) -> None:
    """Compare saved runs: one figure per predictor, data set, route type and drive, aligned.

    The first run is the reference: every later run gets a paired difference (later - first,
    over the drives both scored) with its 95 % cluster-bootstrap CI; `*` marks a CI that
    excludes 0. Runs with different configurations are flagged (notes on stderr).

    Examples:

      bench compare old-run new-run

      bench compare a b c --metric now.p95_m --format csv --out cmp

      bench compare main-run pr-run --fail-if-worse 'lstm:future.mean_m:5%'

      bench compare old-run new-run --uncertainty --scope all,dataset,since-fix
    """
    from posbench.checks import check_choice, check_out_dir
    from posbench.comparison.align import Metric, config_differences, run_labels
    from posbench.comparison.gates import Gate, check_gates
    from posbench.saved_run.run import load_run

    try:
        m = Metric.parse(metric)
        check_choice(fmt, FORMATS, "--format")
        scopes = [s.strip() for s in scope.split(",") if s.strip()]
        for s in scopes:
            check_choice(s, SCOPES, "--scope")
        if "since-fix" in scopes and not uncertainty:
            raise UsageError("--scope since-fix: rows of the uncertainty table only; add "
                             "--uncertainty")
        gates = [Gate.parse(g) for g in fail_if_worse or []]
        if gates and len(runs) != 2:
            raise UsageError(f"--fail-if-worse compares exactly two runs (OLD NEW); got {len(runs)}")
        if out is not None:
            check_out_dir(out)
        loaded = [load_run(r) for r in runs]
        labels = run_labels(loaded)
        diffs = config_differences(loaded, labels)
        if gates and diffs and not allow_config_change:
            raise UsageError("the runs' configurations differ (" + "; ".join(diffs) +
                             "): their figures are not comparable; re-run one, or pass "
                             "--allow-config-change")
        table, frame = _table(loaded, labels, m, scopes, seed)
        extra = _uncertainty(loaded, labels, scopes) if uncertainty else None
        checks = check_gates(loaded[0], loaded[1], gates, seed) if gates else []
    except (UsageError, DataError) as e:
        raise fail(str(e)) from None
    for line in diffs:
        err_console.print(f"note: runs differ in {line}", highlight=False, soft_wrap=True,
                          markup=False)
    if extra is not None:
        for line in extra[2]:
            err_console.print(f"note: {line}", highlight=False, soft_wrap=True, markup=False)
    _print(table, frame, fmt)
    if extra is not None:
        if fmt == "csv" and not table.frame.empty:
            print()  # the second CSV block
        _print(extra[0], extra[1], fmt)
    if out is not None:
        _write(out, table, frame, loaded, labels, m, fmt, extra)
    if checks:
        failed = [c for c in checks if c.failed]
        for c in checks:
            console.print(c.line(), highlight=False, soft_wrap=True, markup=False)
        if failed:
            err_console.print(f"accuracy gate failed: {len(failed)} of {len(checks)} "
                              f"(NEW {labels[1]} vs OLD {labels[0]})", highlight=False,
                              markup=False)
            raise typer.Exit(1)


def _table(runs, labels, metric, scopes, seed):
    from posbench.comparison.views import comparison_table

    return comparison_table(runs, labels, metric, [SCOPE_ROWS.get(s, s) for s in scopes], seed)


def _uncertainty(runs, labels, scopes):
    """(table, frame, notes) of the uncertainty comparison."""
    from posbench.comparison.uncertainty import missing_notes, uncertainty_comparison

    table, frame = uncertainty_comparison(runs, labels, [SCOPE_ROWS.get(s, s) for s in scopes])
    notes = missing_notes(runs, labels)
    if frame.empty:
        notes.append("no run has uncertainty figures to compare")
    return table, frame, notes


def _print(table, frame, fmt: str) -> None:
    from posbench.cli.terminal import print_table

    if table.frame.empty:
        return
    if fmt == "csv":
        print(frame.to_csv(index=False), end="")
    elif fmt == "latex":
        print(table.latex(), end="")
    else:
        keys = sum(c in KEY_COLUMNS for c in table.frame.columns)
        print_table(console, table.header(), table.cells(), title=table.title, key_columns=keys,
                    left_columns=keys)


def _write_table(out: Path, stem: str, table, frame, fmt: str) -> Path:
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


def _write(out: Path, table, frame, runs, labels, metric, fmt: str, extra=None) -> None:
    from posbench.comparison.views import comparison_figure
    from posbench.figures.style import save_figure

    out.mkdir(parents=True, exist_ok=True)
    written = [_write_table(out, "comparison", table, frame, fmt)]
    if extra is not None:
        written.append(_write_table(out, "uncertainty_comparison", extra[0], extra[1], fmt))
    import matplotlib.pyplot as plt

    fig = comparison_figure(runs, labels, metric)
    written += save_figure(fig, out, "comparison", ("png",))
    plt.close(fig)
    console.print("written: " + ", ".join(str(p) for p in written), highlight=False,
                  soft_wrap=True, markup=False)
