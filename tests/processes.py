"""Watch a process and its children from a test, as ``ps`` would: read from /proc (Linux).

For the tests of the process itself (issue 40): a killed ``bench run`` leaves no child
behind, and Ctrl-C at a given moment (once its workers exist, once a file appears) ends it
with one line. :class:`Started` runs a command in a session of its own (its own process
group, like a terminal's foreground job); :meth:`Started.interrupt` sends Ctrl-C as a
terminal does. Its output goes to files, never pipes: a child left behind holding a pipe
would hang the test instead of failing it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path

#: whether this machine has /proc (Linux): where posbench forks its children
HAS_PROC = Path("/proc/self/stat").exists()


def _stat(pid: int) -> tuple[str, int] | None:
    """(state, parent pid) of process ``pid``, None when there is none."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = text[text.rindex(")") + 2 :].split()  # after "pid (comm) "
    return fields[0], int(fields[1])


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie has ended: it only waits to be reaped)."""
    st = _stat(pid)
    return st is not None and st[0] not in ("Z", "X")


def children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid``."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            st = _stat(int(entry.name))
            if st is not None and st[1] == pid and st[0] not in ("Z", "X"):
                out.append(int(entry.name))
    return sorted(out)


def descendants(pid: int) -> list[int]:
    """The live processes below ``pid``: its children, theirs, and so on."""
    out, todo = [], children(pid)
    while todo:
        p = todo.pop()
        out.append(p)
        todo += children(p)
    return sorted(out)


class Started:
    """``args`` running in a new session in ``folder``, stdout and stderr into files there."""

    def __init__(self, args: Sequence[str], folder: Path, env: dict[str, str] | None = None):
        self._out, self._err = folder / "stdout.txt", folder / "stderr.txt"
        with open(self._out, "wb") as out, open(self._err, "wb") as err:
            self.proc = subprocess.Popen(
                list(args),
                cwd=folder,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=err,
                start_new_session=True,
            )
        self.pid = self.proc.pid

    def stdout(self) -> str:
        return self._out.read_text(errors="backslashreplace")

    def stderr(self) -> str:
        return self._err.read_text(errors="backslashreplace")

    def wait(self, timeout_s: float = 120) -> int:
        """The exit status (negative: the signal that ended it)."""
        return self.proc.wait(timeout_s)

    def children(self) -> list[int]:
        return children(self.pid)

    def wait_until(self, ready: Callable[[], bool], what: str, timeout_s: float = 120) -> None:
        """Poll ``ready`` every 10 ms until it holds; fails if the process ends first or it
        takes longer than ``timeout_s`` seconds."""
        deadline = time.monotonic() + timeout_s
        while not ready():
            if self.proc.poll() is not None:
                raise AssertionError(
                    f"ended (status {self.proc.returncode}) before {what}: {self.stderr()[-2000:]}"
                )
            if time.monotonic() > deadline:
                raise AssertionError(f"not {what} after {timeout_s} s")
            time.sleep(0.01)

    def descendants(self) -> list[int]:
        return descendants(self.pid)

    def wait_for_children(self, n: int, timeout_s: float = 120) -> list[int]:
        """Its children once it has ``n`` of them."""
        self.wait_until(lambda: len(self.children()) >= n, f"{n} child processes", timeout_s)
        return self.children()

    def wait_for_descendants(self, n: int, timeout_s: float = 120) -> list[int]:
        """The processes below it once there are ``n`` of them."""
        self.wait_until(lambda: len(self.descendants()) >= n, f"{n} processes below", timeout_s)
        return self.descendants()

    def interrupt(self, group: bool = True) -> None:
        """Ctrl-C: SIGINT to its whole process group as a terminal sends it (``group``), or
        to the process alone (``kill -INT PID``)."""
        if group:
            os.killpg(self.pid, signal.SIGINT)
        else:
            os.kill(self.pid, signal.SIGINT)

    def kill_and_watch(self, pids: Sequence[int], within_s: float) -> list[int]:
        """SIGKILL the process; those of ``pids`` still alive ``within_s`` seconds later
        (killed then, so that a failing test leaves nothing behind either)."""
        self.proc.kill()
        self.proc.wait()
        deadline = time.monotonic() + within_s
        while any(alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.05)
        left = [p for p in pids if alive(p)]
        for p in left:
            os.kill(p, signal.SIGKILL)
        return left

    def end(self) -> None:
        """Kill whatever is left of its process group (after a test, pass or fail)."""
        try:
            os.killpg(self.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self.proc.wait()
