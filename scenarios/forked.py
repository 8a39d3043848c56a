"""Work done in forked child processes that inherit this one's memory: :class:`Job` (one
call, started now, its value asked later) and :func:`forked_map` (one call per item, a few
at a time, values in order). A run's figures are drawn this way
(:mod:`posbench.pipeline.jobs`) and its predictors' figures combined
(:func:`posbench.aggregation.aggregate.aggregate`); it lives on the data side, beside
:mod:`posbench.scenarios.child_processes`, so that every layer may use it.

A child reads what it needs from what this process holds without a copy (a trace set in
memory, or the paths of its parts on disk) and sends back only its value, pickled. Where
``fork`` is not available (macOS and Windows start processes by ``spawn``, which would
pickle the inputs), or when a child dies, the call is made in this process when its value
is asked for: slower, never different. A child ends with this process however it ends,
ignores Ctrl-C (this process answers it) and is forked with Ctrl-C held
(:mod:`posbench.scenarios.child_processes`); this process interrupted while it waits for a
child's answer ends that child.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any, Generic, TypeVar

from posbench.scenarios.child_processes import become_child, interrupts_held

T = TypeVar("T")
#: how much nicer than the parent a child runs: on a machine with fewer free cores than
#: processes, the parent (which aggregates, the longest chain of work) keeps a core and the
#: children share what is left, instead of every process getting an equal slice
CHILD_NICENESS = 5


def _child(
    conn: Any, fn: Callable[..., Any], args: tuple[Any, ...], parent_pid: int, nice: int
) -> None:
    """In the child of ``parent_pid``: run ``fn(*args)`` ``nice`` steps nicer than the
    parent, send ``(True, value)`` or ``(False, exception)``."""
    become_child(parent_pid)
    try:
        if nice:
            os.nice(nice)
    except OSError:  # not allowed here: run at the parent's priority
        pass
    try:
        value: tuple[bool, Any] = (True, fn(*args))
    except BaseException as e:  # noqa: BLE001 - everything goes back to the parent
        value = (False, e)
    try:
        conn.send(value)
    except (pickle.PicklingError, TypeError, AttributeError):  # an exception that won't pickle
        conn.send((False, RuntimeError(f"{type(value[1]).__name__}: {value[1]}")))
    finally:
        conn.close()


def can_fork() -> bool:
    """Whether this platform starts processes by ``fork`` (Linux)."""
    return "fork" in mp.get_all_start_methods()


class Job(Generic[T]):
    """``fn(*args)`` started now in a forked child process; :meth:`result` waits for it.

    Without fork (or with ``background=False``) nothing starts until :meth:`result`, which
    then calls ``fn`` here. If the child dies without an answer (killed, out of memory),
    :meth:`result` calls ``fn`` here too. An exception ``fn`` raised in the child is raised
    again by :meth:`result`; :meth:`result` interrupted (Ctrl-C) kills the child, as
    :meth:`cancel` does. ``nice``: how much nicer than this process the child runs."""

    def __init__(
        self,
        fn: Callable[..., T],
        *args: Any,
        background: bool = True,
        nice: int = CHILD_NICENESS,
    ) -> None:
        self._fn, self._args = fn, args
        self._proc: Any = None
        self._conn: Any = None
        if background and can_fork():
            ctx = mp.get_context("fork")
            recv, send = ctx.Pipe(duplex=False)
            self._proc = ctx.Process(
                target=_child, args=(send, fn, args, os.getpid(), nice), daemon=True
            )
            with interrupts_held():
                self._proc.start()
            send.close()
            self._conn = recv

    def result(self) -> T:
        """The value of ``fn(*args)`` (waits for the child). Ask once."""
        if self._proc is None:
            return self._fn(*self._args)
        proc, self._proc = self._proc, None
        try:
            answer = self._conn.recv()
        except EOFError:  # the child died before answering
            answer = None
        except BaseException:  # interrupted while waiting: its answer is not wanted any more
            proc.kill()
            raise
        finally:
            self._conn.close()
            proc.join()
        if answer is None:
            return self._fn(*self._args)
        ok, value = answer
        if not ok:
            raise value
        returned: T = value  # what fn returned in the child, unpickled
        return returned

    def cancel(self) -> None:
        """End the child now, if it is still running; its value is not wanted."""
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.join()
            self._conn.close()


def forked_map(
    fn: Callable[[Any], T], items: Iterable[Any], workers: int = 2, nice: int = 0
) -> list[T]:
    """``[fn(item) for item in items]``, each call in a forked child (:class:`Job`), at most
    ``workers`` at a time, the values in the order of ``items``; with one worker or no fork,
    in this process (a single item still gets its child: what it allocates goes back to the
    system when the child ends). ``nice``: as :class:`Job` (0: the parent's priority, for work
    the parent waits on). An exception of one call is raised here once the calls before it
    are done, and ends the children still running."""
    todo = list(items)
    if workers <= 1 or not todo or not can_fork():
        return [fn(x) for x in todo]
    running: deque[Job[T]] = deque()
    out: list[T] = []
    try:
        for x in todo:
            if len(running) >= workers:
                out.append(running.popleft().result())
            running.append(Job(fn, x, nice=nice))
        while running:
            out.append(running.popleft().result())
    finally:
        for job in running:  # an error or Ctrl-C above: their values are not wanted
            job.cancel()
    return out
