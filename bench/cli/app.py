"""The ``bench`` command line: the Typer app and its entry point.

Each command lives in its own module under :mod:`posbench.commands`; what they share
(consoles, the one-line error, option types) is in :mod:`posbench.cli.common`.
Bad user input - a bad value, and also a command-line syntax error (unknown option,
missing value, not a number) - prints one line ``error: ...`` on stderr naming what
is wrong and exits with status 2.
"""

from __future__ import annotations

import importlib
import sys
from typing import Annotated

import typer

import posbench.blas_threads  # noqa: F401  (before numpy: one OpenBLAS thread)
from posbench.cli import (
    check,
    compare,
    inspect,
    latency,
    predictors,
    queries,
    run,
    score,
    train,
    tune,
    view,
)
from posbench.cli.common import fail


def _argument_type(self: typer.core.TyperArgument, ctx: object) -> str | None:
    """Help shows an argument's placeholder (``PATH``, ``FILE``) without Typer's type tag
    (``<list[Path]>``) beside it; arguments without a placeholder keep the tag."""
    return None if self.metavar else typer.core.TyperArgument.display_type(self, ctx)


typer.core.TyperArgument.display_type_rich = _argument_type  # typer has no hook for this


app = typer.Typer(
    help="posbench: benchmark real-time vehicle position predictors on your drives.\n\n"
         "Start with `bench run` (built-in synthetic drives, no data needed), then point it at "
         "your recordings: `bench run --data PATH... --predictors lstm,kf`.",
    no_args_is_help=True, add_completion=True, pretty_exceptions_enable=False,
    rich_markup_mode=None)


data_app = typer.Typer(help="Look at recordings before benchmarking them.", no_args_is_help=True,
                       rich_markup_mode=None)


app.add_typer(data_app, name="data")


def version_string() -> str:
    """``posbench X.Y.Z`` from the installed package's metadata."""
    from importlib.metadata import PackageNotFoundError, version

    from posbench import DISTRIBUTION

    try:
        return f"posbench {version(DISTRIBUTION)}"
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "posbench (version unknown: not installed)"


def _show_version(value: bool) -> None:
    if value:
        print(version_string())
        raise typer.Exit(0)


@app.callback()
def _root(version: Annotated[bool, typer.Option(
        "--version", callback=_show_version, is_eager=True,
        help="Print the posbench version and exit.")] = False) -> None:
    pass


app.command("run")(run.run)


app.command("queries")(queries.queries)


app.command("score")(score.score)


data_app.command("inspect")(inspect.inspect)


app.command("view")(view.view)


app.command("predictors")(predictors.list_predictors)


app.command("train")(train.train)


app.command("latency")(latency.latency)


app.command("tune")(tune.tune)


app.command("check")(check.check)


app.command("compare")(compare.compare)


MULTI_VALUE_OPTIONS = ("--data", "--topic", "--model", "--set")


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


def _click_errors(name: str) -> tuple[type[BaseException], ...]:
    """Click's exception class ``name``, and its twin in the copy of click that newer typer
    versions vendor (``typer._click``): a command-line error can be either."""
    out: list[type[BaseException]] = []
    for module in ("click.exceptions", "typer._click.exceptions"):
        try:
            cls = getattr(importlib.import_module(module), name, None)
        except ImportError:
            continue
        if isinstance(cls, type) and cls not in out:
            out.append(cls)
    return tuple(out)


NO_ARGS = _click_errors("NoArgsIsHelpError")


USAGE_ERRORS = _click_errors("UsageError")


CLICK_ERRORS = _click_errors("ClickException")


ABORTS = (typer.Abort, *_click_errors("Abort"))


def command_path(args: list[str]) -> str:
    """The (sub)command that ``args`` call, e.g. ``bench data inspect``."""
    cmd, path = typer.main.get_command(app), ["bench"]
    for a in args:
        sub = getattr(cmd, "commands", {}).get(a)
        if sub is not None:
            cmd = sub
            path.append(a)
        elif not a.startswith("-"):
            break
    return " ".join(path)


def usage_line(e: BaseException, args: list[str]) -> str:
    """A click error as one line; a usage error points at its command's ``--help``."""
    fmt = getattr(e, "format_message", None)
    msg = " ".join((fmt() if callable(fmt) else str(e)).split())
    if isinstance(e, USAGE_ERRORS):
        ctx = getattr(e, "ctx", None)
        msg += f" (see `{ctx.command_path if ctx is not None else command_path(args)} --help`)"
    return msg


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: run ``bench`` on ``argv`` (default: ``sys.argv[1:]``) and
    exit with its status (0 ok, 2 user error, 130 interrupted)."""
    args = _normalise_argv(sys.argv[1:] if argv is None else argv)
    try:
        rv = app(args=args, prog_name="bench", standalone_mode=False)
    except NO_ARGS as e:  # `bench` or `bench data` alone: their help
        print(e.ctx.get_help())
        rv = 0
    except CLICK_ERRORS as e:  # unknown option, missing value, not a number, no such command
        fail(usage_line(e, args))
        rv = 2
    except ABORTS:
        fail("aborted")
        rv = 130
    except KeyboardInterrupt:
        fail("interrupted")
        rv = 130
    sys.exit(rv if isinstance(rv, int) else 0)  # typer.Exit(n) comes back as n; None: 0


if __name__ == "__main__":
    main()
