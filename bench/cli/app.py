"""The ``bench`` command line: the Typer app, its one error wrapper and its entry point.

Each command lives in its own module of :mod:`posbench.cli` and calls the library (the
pipelines, the comparison, the contract check); what commands share is
:mod:`posbench.cli.options` (option types), :mod:`posbench.cli.terminal` (output) and
:mod:`posbench.cli.config_file` (``--config``). Bad user input - a bad value, a file that
cannot be read, and also a command-line syntax error (unknown option, missing value, not a
number) - prints one line ``error: ...`` on stderr naming what is wrong and exits with
status 2, whatever command and whatever process it happened in.
"""

from __future__ import annotations

import functools
import importlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperArgument

import posbench.blas_threads  # noqa: F401  (before numpy: one OpenBLAS thread)
import posbench.cli.check as check
import posbench.cli.compare as compare
import posbench.cli.export as export
import posbench.cli.inspect as inspect
import posbench.cli.latency as latency
import posbench.cli.predictors as predictors
import posbench.cli.queries as queries
import posbench.cli.run as run
import posbench.cli.score as score
import posbench.cli.train as train
import posbench.cli.tune as tune
import posbench.cli.view as view
from posbench.cli import INTERRUPTED
from posbench.cli.options import WORKER_DIED
from posbench.cli.terminal import NORMAL, fail, set_verbosity, warn


def _argument_type(self: TyperArgument, ctx: Any) -> str | None:
    """Help shows an argument's placeholder (``PATH``, ``FILE``) without Typer's type tag
    (``<list[Path]>``) beside it; arguments without a placeholder keep the tag. (``ctx``:
    the click context, ``click.Context`` or the one of typer's vendored click, by version.)"""
    return None if self.metavar else TyperArgument.display_type(self, ctx)


# typer has no hook for this: the method is replaced (for mypy, assigning to a method, and
# a function taking a TyperArgument where the method takes any typer parameter)
TyperArgument.display_type_rich = _argument_type  # type: ignore[method-assign, assignment]  # patch
app = typer.Typer(
    help="posbench: benchmark real-time vehicle position predictors on your drives.\n\n"
    "Start with `bench run` (built-in synthetic drives, no data needed), then point it at "
    "your recordings: `bench run --data PATH -p lstm,kf`. Every command takes -q/-v and "
    "--config FILE.toml.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)
data_app = typer.Typer(
    help="Look at recordings before benchmarking them.", no_args_is_help=True, rich_markup_mode=None
)
app.add_typer(data_app, name="data")


def version_string() -> str:
    """``posbench X.Y.Z`` from the installed package's metadata."""
    from importlib.metadata import PackageNotFoundError, version

    from posbench.naming import DISTRIBUTION

    try:
        return f"posbench {version(DISTRIBUTION)}"
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "posbench (version unknown: not installed)"


def _show_version(value: bool) -> None:
    if value:
        print(version_string())
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            callback=_show_version,
            is_eager=True,
            help="Print the posbench version and exit.",
        ),
    ] = False,
) -> None:
    pass


def user_errors() -> tuple[type[BaseException], ...]:
    """The exceptions that are a user's mistake or a limit of their machine, never a bug:
    each becomes one line ``error: ...`` and exit status 2."""
    from posbench.errors import UsageError
    from posbench.predictors.registry import PredictorError
    from posbench.recording.web import ServeError
    from posbench.replay.executors import ExecutorError
    from posbench.scenarios.errors import DataError

    return DataError, UsageError, ExecutorError, ServeError, PredictorError


def command(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` with the one error wrapper every command has: a user error (:func:`user_errors`)
    is one line on stderr and exit 2; a dead worker process too (:data:`WORKER_DIED`);
    Ctrl-C is exit 130, its line printed by :func:`main`."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from concurrent.futures.process import BrokenProcessPool

        try:
            return fn(*args, **kwargs)
        except KeyboardInterrupt:  # first: typer would take it, silently, as exit 130
            raise typer.Exit(INTERRUPTED) from None
        except user_errors() as e:
            raise fail(str(e)) from None
        except BrokenProcessPool:
            raise fail(WORKER_DIED) from None

    return wrapper


for name, fn in (
    ("run", run.run),
    ("queries", queries.queries),
    ("score", score.score),
    ("view", view.view),
    ("predictors", predictors.list_predictors),
    ("train", train.train),
    ("latency", latency.latency),
    ("tune", tune.tune),
    ("check", check.check),
    ("compare", compare.compare),
    ("export", export.export),
):
    app.command(name)(command(fn))
data_app.command("inspect")(command(inspect.inspect))


# ------------------------------------------------------------- last release's spellings
#: options that took several values after one flag in the last release (``--data a b``)
GREEDY = {"--data": "-d", "--topic": None, "--model": None, "--set": None}
#: commands whose own arguments never follow ``--data`` (it took every word after it)
NO_ARGUMENTS = ("run", "queries", "train", "latency")


def _subcommand(argv: list[str]) -> tuple[str | None, int]:
    """The (sub)command ``argv`` calls (``run``, ``data inspect``) and where its options
    start."""
    for i, a in enumerate(argv):
        if a.startswith("-"):
            continue
        if a == "data" and i + 1 < len(argv) and argv[i + 1] == "inspect":
            return "data inspect", i + 2
        return a, i + 1
    return None, len(argv)


def upgrade_argv(argv: list[str]) -> list[str]:
    """``argv`` with the last release's spellings rewritten, one notice each on stderr:
    several values after one ``--data`` (commands without arguments of their own) or after
    one ``--topic``/``--model``/``--set`` (values holding ``=``) become repeated options;
    ``bench score ... -q DIR`` (an existing folder) becomes ``--queries DIR``."""
    cmd, start = _subcommand(argv)
    if cmd is None:
        return argv
    out, current, noted = list(argv[:start]), None, set()
    i = start
    while i < len(argv):
        a = argv[i]
        if a == "--":
            out += argv[i:]
            break
        if cmd == "score" and a == "-q" and i + 1 < len(argv) and Path(argv[i + 1]).is_dir():
            warn(
                "-q DIR is deprecated in bench score: -q is --quiet now, use --queries DIR "
                "(the old spelling goes in the next release)"
            )
            out += ["--queries", argv[i + 1]]
            i += 2
            continue
        if a.startswith("-"):
            flag = next((f for f, short in GREEDY.items() if a in (f, short)), None)
            current, taken = (flag, 0) if flag else (None, 0)
            out.append(a)
            i += 1
            continue
        if current is not None:
            taken += 1
            more = cmd in NO_ARGUMENTS if current == "--data" else "=" in a
            if taken > 1 and more:
                if current not in noted:
                    noted.add(current)
                    warn(
                        f"several values after one {current} are deprecated: repeat it "
                        f"({current} A {current} B; the old spelling goes in the next "
                        f"release)"
                    )
                out += [current, a]
                i += 1
                continue
            if taken > 1:
                current = None
        out.append(a)
        i += 1
    return out


# ------------------------------------------------------------------------ entry point
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
ABORTS: tuple[type[BaseException], ...] = (typer.Abort, *_click_errors("Abort"))


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
    """Run ``bench`` on ``argv`` (default: ``sys.argv[1:]``) and exit with its status (0 ok,
    1 a check or gate failed, 2 user error, 130 interrupted: one line ``error: interrupted``).
    The process around it is :func:`posbench.cli.main`.
    Each call starts at normal loudness: an earlier call's ``-q`` or ``-v`` does not carry over."""
    set_verbosity(NORMAL)
    args = upgrade_argv(sys.argv[1:] if argv is None else argv)
    try:
        rv = app(args=args, prog_name="bench", standalone_mode=False)
    except NO_ARGS as e:  # `bench` or `bench data` alone: their help
        ctx = getattr(e, "ctx", None)  # click's NoArgsIsHelpError always has its context
        print(ctx.get_help() if ctx is not None else str(e))
        rv = 0
    except CLICK_ERRORS as e:  # unknown option, missing value, not a number, no such command
        fail(usage_line(e, args))
        rv = 2
    except ABORTS:
        fail("aborted")
        sys.exit(INTERRUPTED)
    except KeyboardInterrupt:  # outside a command (older typer lets it through)
        rv = INTERRUPTED
    if rv == INTERRUPTED:  # Ctrl-C: typer turns it into this status, without a word
        fail("interrupted")
    sys.exit(rv if isinstance(rv, int) else 0)  # typer.Exit(n) comes back as n; None: 0


if __name__ == "__main__":
    main()
