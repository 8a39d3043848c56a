"""The ``bench`` command line: the Typer app (:mod:`posbench.cli.app`), one module per
command, the option types they share (:mod:`posbench.cli.options`), ``--config`` files
(:mod:`posbench.cli.config_file`) and the terminal output (:mod:`posbench.cli.terminal`).

:func:`main` is the process (the ``bench`` console script, ``python -m posbench``): it owns
Ctrl-C. This module imports nothing heavy, so that its handler is in place before the
command line's imports start."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from types import FrameType
from typing import Any

#: the exit status of a command that Ctrl-C (SIGINT) ended
INTERRUPTED = 130
#: what a process that Ctrl-C ended prints, the one line on stderr
INTERRUPTED_LINE = "error: interrupted"


class Interrupted(KeyboardInterrupt):
    """Ctrl-C as this process raises it: a KeyboardInterrupt (caught as one everywhere) of
    its own type, because CPython remembers a plain KeyboardInterrupt that escaped code run
    by ``exec`` of a string (a dataclass being made, for one) and, under ``python -m``, ends
    the process by SIGINT at exit, whatever status it was given (checked: -2, not 130)."""


class _Interrupts:
    """What this process knows of Ctrl-C (SIGINT): whether one came while the command ran
    (``seen``), whether one was dropped by something that could not raise it (``lost``: a
    finalizer, an at-fork hook; Python prints those as "Exception ignored"), whether the
    command is still running, and whether the one line was printed."""

    seen = False
    lost = False
    running = True
    said = False


def _on_interrupt(signum: int, frame: FrameType | None) -> None:
    """The SIGINT handler of the process: :class:`Interrupted` while the command runs; once it
    has ended (the interpreter exits: threads joined, atexit), the one line unless it is out
    already, and the process ends at once with status 130."""
    _Interrupts.seen = True
    if _Interrupts.running:
        raise Interrupted
    if not _Interrupts.said:
        _say_interrupted()
    for stream in (sys.stdout, sys.stderr):  # what was printed before still goes out
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a stream half-written or closed: ending anyway
            pass
    os._exit(INTERRUPTED)


def _say_interrupted() -> None:
    """The one line, written straight to stderr (no console needed, nothing imported)."""
    _Interrupts.said = True
    try:
        os.write(2, f"{INTERRUPTED_LINE}\n".encode())
    except OSError:  # stderr closed: the status says it
        pass


def _quiet_interrupts(previous: Callable[[Any], object]) -> Callable[[Any], object]:
    """``sys.unraisablehook`` that keeps a dropped KeyboardInterrupt quiet (noted in
    :class:`_Interrupts`, reported by :func:`main` as the one line) and hands every other
    unraisable exception to ``previous``."""

    def hook(unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            _Interrupts.lost = True
            return
        previous(unraisable)

    return hook


def main(argv: list[str] | None = None) -> None:
    """The ``bench`` console script (:func:`posbench.cli.app.main` as a process).

    Ctrl-C at any moment, while the command line is imported too, ends the process with one
    line ``error: interrupted`` on stderr and status 130, never a traceback: the command's
    own handling prints it; an interrupt dropped on the way (by a finalizer) or turned into
    another error (an import of a C extension, interrupted, raises ImportError) is reported
    here when the command ends; one after it has ended (the interpreter exiting) ends the
    process at once. With SIGINT ignored (a background job), it stays ignored.

    Arrow allocates through the C library's malloc in ``bench``'s processes (unless
    ``ARROW_DEFAULT_MEMORY_POOL`` says otherwise): its default pool (mimalloc) keeps what a
    run's aggregation frees, reading one predictor's traces after another; measured on 8 drive
    hours of the corpus, the main process's peak fell 968 -> 805 MB at the same wall time."""
    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_interrupt)
        sys.unraisablehook = _quiet_interrupts(sys.unraisablehook)
    status: str | int | None = 0
    other_form = False
    try:
        from posbench.cli.app import main as app_main

        app_main(argv)
    except SystemExit as e:
        status = e.code
    except BaseException:  # a bug's traceback, or an interrupt in another form
        if not _Interrupts.seen:
            raise
        other_form = True
    finally:
        _Interrupts.running = False
    if status == INTERRUPTED:  # app.main printed the line
        _Interrupts.said = True
    elif _Interrupts.lost or other_form:
        _say_interrupted()
        status = INTERRUPTED
    sys.exit(status)
