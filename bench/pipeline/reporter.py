"""How a pipeline tells its caller what it is doing.

The pipelines (:mod:`posbench.pipeline.run`, :mod:`posbench.pipeline.score`) never print:
they call a :class:`Reporter`. The base class is silent (a notebook calling
:func:`posbench.run` gets its :class:`~posbench.saved_run.run.Run` and no output); the
command line passes one that draws spinners and progress bars and prints the lines
(:class:`posbench.cli.terminal.ConsoleReporter`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

#: ``line`` levels: a warning (shown even when quiet), a normal line, a detail (verbose only)
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
