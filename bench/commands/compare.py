"""`bench compare`: saved runs side by side, and an accuracy regression gate for CI."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from bench.commands.common import DataError, UsageError, console, err_console, fail

FORMATS = ("md", "csv", "latex")
SCOPES = ("all", "dataset", "route", "drive")


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
             "data set), drive.")] = "all,dataset",
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
) -> None:
    """Compare saved runs: one figure per predictor, data set, route type and drive, aligned.

    The first run is the reference: every later run gets a paired difference (later - first,
    over the drives both scored) with its 95 % cluster-bootstrap CI; `*` marks a CI that
    excludes 0. Runs with different configurations are flagged (notes on stderr).

    Examples:

      bench compare old-run new-run

      bench compare a b c --metric now.p95_m --format csv --out cmp

      bench compare main-run pr-run --fail-if-worse 'lstm:future.mean_m:5%'
    """
    from bench.compare import Gate, Metric, check_gates, config_differences, run_labels
    from bench.options import check_choice, check_out_dir
    from bench.saved_run import load_run

    try:
        m = Metric.parse(metric)
        check_choice(fmt, FORMATS, "--format")
        scopes = [s.strip() for s in scope.split(",") if s.strip()]
        for s in scopes:
            check_choice(s, SCOPES, "--scope")
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
        checks = check_gates(loaded[0], loaded[1], gates, seed) if gates else []
    except (UsageError, DataError) as e:
        raise fail(str(e)) from None
    for line in diffs:
        err_console.print(f"note: runs differ in {line}", highlight=False, soft_wrap=True,
                          markup=False)
    _print(table, frame, fmt)
    if out is not None:
        _write(out, table, frame, loaded, labels, m, fmt)
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
    from bench.compare_views import comparison_table

    names = {"route": "route type"}
    return comparison_table(runs, labels, metric, [names.get(s, s) for s in scopes], seed)


def _print(table, frame, fmt: str) -> None:
    from bench.terminal import print_table

    if fmt == "csv":
        print(frame.to_csv(index=False), end="")
    elif fmt == "latex":
        print(table.latex(), end="")
    else:
        keys = 4 if "group" in table.frame.columns else 3
        print_table(console, table.header(), table.cells(), title=table.title, key_columns=keys,
                    left_columns=keys)


def _write(out: Path, table, frame, runs, labels, metric, fmt: str) -> None:
    from bench.compare_views import comparison_figure
    from bench.plots import save_figure

    out.mkdir(parents=True, exist_ok=True)
    written = []
    if fmt == "md":
        path = out / "comparison.md"
        path.write_text(f"# {table.title}\n\n{table.markdown()}\n")
    elif fmt == "csv":
        path = out / "comparison.csv"
        frame.to_csv(path, index=False)
    else:
        path = out / "comparison.tex"
        path.write_text(table.latex())
    written.append(path)
    import matplotlib.pyplot as plt

    fig = comparison_figure(runs, labels, metric)
    written += save_figure(fig, out, "comparison", ("png",))
    plt.close(fig)
    console.print("written: " + ", ".join(str(p) for p in written), highlight=False,
                  soft_wrap=True, markup=False)


