"""posbench's child processes: they end with their parent and leave Ctrl-C to it.

posbench starts child processes in three places: the replay workers
(:func:`posbench.replay.runner.run`), the loader processes
(:func:`posbench.scenarios.loaders.iter_load_many`) and the forked jobs of a run (figures,
hashing the data: :mod:`posbench.pipeline.jobs`). Every one of them:

- **ends when its parent ends**, whatever ends the parent (``kill -9`` included):
  :func:`end_with_parent`. Without it a killed ``bench run`` left its workers behind,
  re-parented and blocked forever on a queue nobody writes to.
- **ignores Ctrl-C**: a terminal sends SIGINT to every process of the foreground group, and
  a child's own KeyboardInterrupt printed its traceback or came back as a task's error. The
  parent answers it (one line, exit 130) and ends its children (:class:`WorkerPool`).
- **is forked with Ctrl-C held** (:func:`interrupts_held`): ``os.fork`` runs the Python
  at-fork hooks (``logging``'s lock, for one), and a SIGINT handled inside one raised its
  KeyboardInterrupt there, where CPython prints "Exception ignored in ..." and drops it: the
  run went on and exited 0. Held, it is raised in the parent once the fork is done.

It lives on the data side, the lowest layer, because the loaders' pool needs it too; the
harness imports the data side, never the reverse.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from multiprocessing.context import BaseContext
from types import FrameType, TracebackType
from typing import Any, ParamSpec, TypeVar

P = ParamSpec("P")
T = TypeVar("T")

#: prctl(2) option: the signal this process gets when its parent ends (linux/prctl.h)
PR_SET_PDEATHSIG = 1
#: where the kernel cannot signal a parent's death: how often a child checks its parent [s]
PARENT_POLL_S = 1.0
#: the exit status of a child whose parent was gone before it could watch it
ORPHAN_STATUS = 1


def _parent_death_signal(sig: int) -> bool:
    """Ask the kernel (Linux ``prctl(PR_SET_PDEATHSIG)``, through libc) to send ``sig`` to
    this process when the thread that forked it ends; False where that is not available."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)  # the C library the interpreter runs on
        done = libc.prctl(PR_SET_PDEATHSIG, ctypes.c_ulong(sig), *[ctypes.c_ulong(0)] * 3)
    except (OSError, AttributeError):  # no prctl in this libc
        return False
    return bool(done == 0)


def exec_with_parent_death(parent_pid: int, sig: int = signal.SIGTERM) -> Callable[[], None]:
    """A ``preexec_fn`` for :class:`subprocess.Popen`: the program it starts gets ``sig``
    when ``parent_pid`` (this process) ends, however it ends (Linux; elsewhere nothing), and
    does not start at all if this process is already gone. The setting survives ``exec``."""

    def before_exec() -> None:
        if _parent_death_signal(sig) and os.getppid() != parent_pid:
            os._exit(ORPHAN_STATUS)

    return before_exec


def _watch_parent(parent_pid: int, poll_s: float) -> None:
    """A daemon thread that ends this process once its parent is no longer ``parent_pid``
    (POSIX re-parents an orphan), checking every ``poll_s`` seconds."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(ORPHAN_STATUS)

    threading.Thread(target=watch, name="posbench-parent-watch", daemon=True).start()


def end_with_parent(parent_pid: int) -> None:
    """In a child process: end it when its parent process ends, however that ends. On Linux
    the kernel kills it (SIGKILL, the parent-death signal) at once; elsewhere a daemon thread
    notices within :data:`PARENT_POLL_S` seconds.

    ``parent_pid``: the parent's ``os.getpid()``, taken there before it started this child
    (by fork or spawn: a child of a fork server is the server's); a child whose parent is
    not that one any more ends now (it died before this was set: no signal will come).

    On Linux the parent is the *thread* that forked the child: fork it from a thread that
    outlives it (posbench forks from the thread that waits for the child's answers)."""
    if _parent_death_signal(signal.SIGKILL):
        if os.getppid() != parent_pid:  # it died before the signal was set: none will come
            os._exit(ORPHAN_STATUS)
        return
    if os.getppid() != parent_pid:
        os._exit(ORPHAN_STATUS)
    _watch_parent(parent_pid, PARENT_POLL_S)


def become_child(parent_pid: int) -> None:
    """First thing in a posbench child process: Ctrl-C ignored (the parent answers it) and
    the process ended with its parent ``parent_pid`` (:func:`end_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    end_with_parent(parent_pid)


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Inside, a Ctrl-C (SIGINT) is only noted; on leaving, one that came is raised (by the
    handler there was: KeyboardInterrupt). Fork inside it: a KeyboardInterrupt raised in an
    at-fork hook is printed as "Exception ignored" and lost. Outside the main thread, or with
    SIGINT ignored or not handled by Python, nothing changes."""
    before = signal.getsignal(signal.SIGINT)
    if not callable(before) or threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []

    def note(signum: int, frame: FrameType | None) -> None:
        came.append(signum)

    signal.signal(signal.SIGINT, note)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
        if came:
            signal.raise_signal(signal.SIGINT)  # to the handler there was, now


#: the start methods whose processes are children of the process that starts them (a fork
#: server's are the server's: they would end with it, and it lives as long as they do)
DIRECT = ("fork", "spawn")


def default_context() -> BaseContext:
    """How a :class:`WorkerPool` starts its workers unless told: ``fork`` where the platform
    has it (as Python did by default on Linux up to 3.13, and as posbench's loaders and jobs
    do), else ``spawn`` (macOS, Windows)."""
    return mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")


def _start_worker(
    parent_pid: int,
    initializer: Callable[..., object] | None,
    initargs: tuple[Any, ...],
) -> None:
    """A :class:`WorkerPool` worker's initializer: :func:`become_child`, then the pool's
    own ``initializer(*initargs)``."""
    become_child(parent_pid)
    if initializer is not None:
        initializer(*initargs)


class WorkerPool(ProcessPoolExecutor):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` of posbench children: each worker
    ignores Ctrl-C and ends with this process (:func:`become_child`), each is forked with
    Ctrl-C held (:meth:`submit`), and leaving its ``with`` block by an exception (an error,
    Ctrl-C, a generator closed) ends the workers at once (:meth:`kill_now`) instead of
    waiting for every task submitted, as ``ProcessPoolExecutor`` does. Leaving it normally
    waits for the tasks, as ``ProcessPoolExecutor`` does."""

    def __init__(
        self,
        max_workers: int,
        mp_context: BaseContext | None = None,
        initializer: Callable[..., object] | None = None,
        initargs: tuple[Any, ...] = (),
    ) -> None:
        ctx = mp_context if mp_context is not None else default_context()
        if ctx.get_start_method() not in DIRECT:
            raise ValueError(
                f"WorkerPool starts its workers by {' or '.join(DIRECT)}, not "
                f"{ctx.get_start_method()}: a fork server's children cannot end with this process"
            )
        super().__init__(
            max_workers,
            mp_context=ctx,
            initializer=_start_worker,
            initargs=(os.getpid(), initializer, tuple(initargs)),
        )

    def submit(self, fn: Callable[P, T], /, *args: P.args, **kwargs: P.kwargs) -> Future[T]:
        """As ``ProcessPoolExecutor.submit``, with Ctrl-C held: a submit may fork workers."""
        with interrupts_held():
            return super().submit(fn, *args, **kwargs)

    def kill_now(self) -> None:
        """End the workers now (SIGKILL), dropping their running and queued tasks.

        A worker killed while it sent a result leaves half a message in the results pipe,
        which the pool's manager thread would wait for forever (and the interpreter's exit
        for that thread): with the workers gone, this process holds the pipe's last write
        end, and closing it ends the wait (the pool is broken, as after a crash). The workers
        and that pipe are ``ProcessPoolExecutor`` internals (``_processes``,
        ``_result_queue``, ``_executor_manager_thread``: CPython 3.8 to 3.14), each read with a
        default: a version without one skips that step."""
        # shutdown() forgets all three (sets them to None): read before it
        workers = list((getattr(self, "_processes", None) or {}).values())
        results = getattr(self, "_result_queue", None)
        manager = getattr(self, "_executor_manager_thread", None)
        self.shutdown(wait=False, cancel_futures=True)
        for w in workers:
            with contextlib.suppress(ProcessLookupError, ValueError):  # gone, or closed
                w.kill()
        writer = getattr(results, "_writer", None)
        if writer is not None:
            writer.close()
        # the pool's manager thread, seeing the workers gone, closes its wake-up pipe; the
        # interpreter's exit writes to that pipe unless it is closed (CPython 3.11's
        # concurrent.futures._python_exit checks without the pool's lock): racing with the
        # close, it printed "Exception ignored ... Bad file descriptor" after Ctrl-C. Waiting
        # for the thread here (it ends at once: nothing is left to wait for) leaves no race.
        if manager is not None and manager.is_alive():
            manager.join(timeout=5.0)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc_val: BaseException | None,
        exc_tb: TracebackType | None,
    ) -> bool | None:
        if exc_type is not None:
            self.kill_now()
            return None
        return super().__exit__(exc_type, exc_val, exc_tb)
