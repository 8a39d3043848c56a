"""The ``bench`` command line: the Typer app and its entry point.

Each command lives in its own module under :mod:`bench.commands`; what they share
(consoles, the one-line error, option types) is in :mod:`bench.commands.common`.
Bad user input prints one line naming what is wrong and exits with status 2.
"""

from __future__ import annotations

import sys

import typer

from bench.commands import inspect, latency, predictors, run, train, tune, view
from bench.commands.common import err_console

app = typer.Typer(
    help="posbench: benchmark real-time vehicle position predictors on your drives.\n\n"
         "Start with `bench run` (built-in synthetic drives, no data needed), then point it at "
         "your recordings: `bench run --data PATH... --predictors lstm,kf`.",
    no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
    rich_markup_mode=None)
data_app = typer.Typer(help="Look at recordings before benchmarking them.", no_args_is_help=True,
                       rich_markup_mode=None)
app.add_typer(data_app, name="data")

app.command("run")(run.run)
data_app.command("inspect")(inspect.inspect)
app.command("view")(view.view)
app.command("predictors")(predictors.list_predictors)
app.command("train")(train.train)
app.command("latency")(latency.latency)
app.command("tune")(tune.tune)

MULTI_VALUE_OPTIONS = ("--data", "--topic", "--model")


def _normalise_argv(argv: list[str]) -> list[str]:
    """Let multi-value options take several values after one flag (``--data a b``)."""
    out: list[str] = []
    current: str | None = None
    for a in argv:
        if a.startswith("-"):
            current = a if a in MULTI_VALUE_OPTIONS else None
            out.append(a)
            continue
        if current is not None and out and out[-1] != current:
            out.append(current)
        out.append(a)
    return out


def main() -> None:
    """Console-script entry point."""
    argv = _normalise_argv(sys.argv[1:])
    try:
        app(args=argv, prog_name="bench")
    except KeyboardInterrupt:
        err_console.print("interrupted")
        sys.exit(130)


if __name__ == "__main__":
    main()
