"""How a pipeline tells its caller what it is doing.

The pipelines (:mod:`posbench.pipeline.run`, :mod:`posbench.pipeline.score`) never print:
they call a :class:`Reporter`. The base class is silent (a notebook calling
:func:`posbench.run` gets its :class:`~posbench.saved_run.run.Run` and no output);
:class:`RichReporter` draws spinners and progress bars on a rich console and prints the
lines as loud as its level says (the command line's ``-q``/``-v``, ``progress=True`` of the
Python API).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

#: ``line`` levels: a warning (shown even when quiet), a normal line, a detail (verbose only);
#: a reporter's level is the loudest it shows (WARNING: quiet, INFO: normal, DETAIL: verbose)
WARNING, INFO, DETAIL = -1, 0, 1


class Reporter:
    """Silent: every phase and step happens, nothing is shown."""

    @contextmanager
    def phase(self, text: str) -> Iterator[Callable[[str], None]]:
        """A phase of unknown length (loading drives, writing a file): yields a function
        that replaces the phase's text (e.g. with the drive just loaded)."""
        yield lambda _text: None

    @contextmanager
    def steps(self, text: str, total: int) -> Iterator[Callable[[str], None]]:
        """``total`` steps (drives replayed, drives scored): yields a function called once
        per finished step with its name."""
        yield lambda _name: None

    def line(self, text: str, level: int = INFO) -> None:
        """One line of text at ``level`` (:data:`WARNING`, :data:`INFO`, :data:`DETAIL`)."""


#: the reporter of a call that gives none
SILENT = Reporter()


class RichReporter(Reporter):
    """Progress on a rich console: spinners and bars unless quiet (``level`` WARNING), the
    lines up to ``level``, and at DETAIL one line per finished step with the time so far.

    Args:
        console: a ``rich.console.Console``; None: a new one on stdout.
        level: the loudest line shown (:data:`WARNING`, :data:`INFO`, :data:`DETAIL`).
    """

    def __init__(self, console: Any = None, level: int = INFO) -> None:
        if console is None:
            from rich.console import Console

            console = Console()
        self.console, self.level = console, level

    @contextmanager
    def phase(self, text: str) -> Iterator[Callable[[str], None]]:
        if self.level <= WARNING:
            yield lambda _text: None
            return
        with self.console.status(text) as status:
            yield status.update

    @contextmanager
    def steps(self, text: str, total: int) -> Iterator[Callable[[str], None]]:
        if self.level <= WARNING:
            yield lambda _name: None
            return
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
        )

        t0 = time.perf_counter()
        count = [0]
        with Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[last]}"),
            console=self.console,
        ) as prog:
            task = prog.add_task(text, total=total, last="")

            def done(name: str) -> None:
                count[0] += 1
                prog.update(task, advance=1, last=name)
                if self.level >= DETAIL:
                    prog.console.print(
                        f"  {name} done ({count[0]}/{total}, {time.perf_counter() - t0:.1f} s)",
                        highlight=False,
                        markup=False,
                    )

            yield done

    def line(self, text: str, level: int = INFO) -> None:
        if level <= max(self.level, WARNING):
            self.console.print(text, highlight=False, markup=False)
