"""What tests share: where the source lives (:data:`ROOT`, :func:`module_name`), what a test
needs from the machine (:func:`missing`), ``bench`` as a user runs it (:func:`bench`,
:func:`assert_one_error_line`, :func:`snapshot`), and processes watched as ``ps`` sees them
(:class:`Started`, :func:`alive`, :func:`descendants`: tests of kills and Ctrl-C).

``bench`` runs in this process by default: the command line's own entry point,
``posbench.cli.app.main``, on fresh standard streams, environment, working directory,
``sys.argv``, ``sys.path``, warning filters and console widths, as a new process would have
them, all put back afterwards. Pass ``process=True`` where the test is about the process
itself: worker processes writing to the terminal, signals, what gets imported, the console
script, a plugin's import path or entry points (modules imported once stay imported).
"""

from __future__ import annotations

import io
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, NoReturn

import pytest

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"

# ------------------------------------------------------------------ the source tree
#: source folder -> the installed package it becomes (pyproject.toml's package-dir map)
FOLDERS = {
    "bench": "posbench",
    "predictors": "posbench.predictors",
    "scenarios": "posbench.scenarios",
    "metrics": "posbench.metrics",
}


def module_name(path: Path) -> str:
    """The installed module of a source file: ``bench/config.py`` -> ``posbench.config``,
    ``predictors/lstm/__init__.py`` -> ``posbench.predictors.lstm``."""
    parts = path.resolve().relative_to(ROOT).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join((FOLDERS[parts[0]], *parts[1:]))


def source_files() -> list[Path]:
    """Every Python file of the installed packages, in a stable order."""
    return [f for folder in FOLDERS for f in sorted((ROOT / folder).rglob("*.py"))]


# ------------------------------------------------------------- what a test needs
#: Chromium flags for the browser tests: no sandbox (CI runs as root), WebGL through ANGLE on
#: SwiftShader (no GPU)
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-dev-shm-usage",
]


def missing(what: str) -> NoReturn:
    """Skip the test for want of ``what`` (data, a tool, a browser), or fail it when ``CI`` is
    set: ``.ci/run`` installs everything, so there every test must run."""
    if os.environ.get("CI"):
        pytest.fail(f"{what} (CI is set: this test must run)")
    pytest.skip(what)


def chromium_executable() -> str:
    """The system Chromium (Debian's package, which ``.ci/run`` installs) with playwright
    importable to drive it, or :func:`missing`."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        missing("no chromium on PATH (.ci/run installs it)")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing("the playwright package is not installed (the dev extra has it)")
    return exe


# ------------------------------------------------------------------------- bench
#: the warning filters a new Python process starts with (no -W, no PYTHONWARNINGS)
_PROCESS_WARNING_FILTERS = (
    ("default", DeprecationWarning, "__main__"),
    ("ignore", DeprecationWarning, ""),
    ("ignore", PendingDeprecationWarning, ""),
    ("ignore", ImportWarning, ""),
    ("ignore", ResourceWarning, ""),
)
#: how Python prints a warning, saved before any test replaces it (pytest records them)
_SHOW_WARNING = warnings._showwarnmsg_impl  # type: ignore[attr-defined]


def bench(
    *args: object,
    cwd: Path | str | None = None,
    env: Mapping[str, str | None] | None = None,
    columns: int | None = 80,
    process: bool = False,
    timeout: float = 600,
) -> subprocess.CompletedProcess[str]:
    """``bench ARGS`` as a user runs it: its exit status, stdout and stderr.

    ``columns``: the terminal width (``COLUMNS``); None for output piped without one.
    ``env``: variables to set (None: unset) on top of this process's environment.
    ``process``: run ``python -m posbench`` in a new process (``timeout`` [s] applies there
    only) instead of in this one; see the module's docstring for when.
    """
    argv = [str(a) for a in args]
    environ: dict[str, str | None] = {"COLUMNS": None if columns is None else str(columns)}
    environ.update(env or {})
    if process:
        full = {**os.environ, **environ}
        return subprocess.run(
            [sys.executable, "-m", "posbench", *argv],
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=timeout,
            env={k: v for k, v in full.items() if v is not None},
        )
    from posbench.cli.app import main

    with _as_a_new_process(argv, cwd, environ) as (out, err):
        try:
            main(argv)
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except BaseException:  # what Python prints when a process dies of an exception
            sys.stderr.write(traceback.format_exc())
            code = 1
    return subprocess.CompletedProcess(["bench", *argv], code, _read(out), _read(err))


def _read(f: IO[bytes]) -> str:
    f.seek(0)
    return f.read().decode("utf-8", errors="backslashreplace")


@contextmanager
def _as_a_new_process(
    argv: list[str], cwd: Path | str | None, environ: Mapping[str, str | None]
) -> Iterator[tuple[IO[bytes], IO[bytes]]]:
    """Standard streams (empty stdin; stdout and stderr into two files, at the descriptors 1
    and 2, so that worker processes, C libraries and warnings write there as they would to a
    terminal), environment, working directory, ``sys.argv``, ``sys.path``, warning filters
    and the consoles' widths as a new ``bench`` process would have them; all restored on exit."""
    from posbench.cli import terminal

    out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
    saved_streams = sys.stdin, sys.stdout, sys.stderr
    saved_argv, saved_path, saved_cwd = sys.argv, list(sys.path), os.getcwd()
    saved_env = dict(os.environ)
    consoles = (terminal.console, terminal.err_console)
    saved_widths = [c._width for c in consoles]  # rich reads COLUMNS once, at construction
    saved_verbosity = terminal.verbosity()
    for stream in saved_streams[1:]:
        stream.flush()
    saved_fds = os.dup(1), os.dup(2)
    try:
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        for k, v in environ.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        columns = os.environ.get("COLUMNS", "")
        for c in consoles:
            c._width = int(columns) if columns.isdigit() else None
        sys.stdin = io.TextIOWrapper(io.BytesIO(b""), encoding="utf-8")
        sys.stdout = _unbuffered_text(1, "strict")
        sys.stderr = _unbuffered_text(2, "backslashreplace")
        sys.argv = ["bench", *argv]
        if cwd is not None:
            os.chdir(cwd)
        terminal.set_verbosity(terminal.NORMAL)
        with warnings.catch_warnings():
            warnings.resetwarnings()
            for action, category, module in reversed(_PROCESS_WARNING_FILTERS):
                warnings.filterwarnings(action, category=category, module=module)
            warnings._showwarnmsg_impl = _SHOW_WARNING  # type: ignore[attr-defined]
            warnings.showwarning = warnings._showwarning_orig  # type: ignore[attr-defined]
            yield out, err
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        sys.stdin, sys.stdout, sys.stderr = saved_streams
        os.dup2(saved_fds[0], 1)
        os.dup2(saved_fds[1], 2)
        for fd in saved_fds:
            os.close(fd)
        sys.argv, sys.path[:] = saved_argv, saved_path
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
        for c, w in zip(consoles, saved_widths, strict=True):
            c._width = w
        terminal.set_verbosity(saved_verbosity)


def _unbuffered_text(fd: int, errors: str) -> io.TextIOWrapper:
    """Text on descriptor ``fd``, every write passed straight through (a forked worker
    inherits no unwritten buffer to write a second time)."""
    raw = io.FileIO(fd, "w", closefd=False)
    return io.TextIOWrapper(raw, encoding="utf-8", errors=errors, write_through=True)


def assert_one_error_line(r: subprocess.CompletedProcess[str], *needles: str) -> str:
    """``r`` failed as a user mistake should: exit 2, no traceback, stderr exactly one line
    ``error: ...`` holding every one of ``needles``; the line."""
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stdout + r.stderr, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].strip(), r.stderr
    assert lines[0].startswith("error: "), lines[0]
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``folder`` with its size and modification time [ns]."""
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
    }


# ------------------------------------------------ processes, as ps sees them (Linux)
# Watch a process and its children from a test, as ``ps`` would: read from /proc (Linux).
#
# For the tests of the process itself (issue 40): a killed ``bench run`` leaves no child
# behind, and Ctrl-C at a given moment (once its workers exist, once a file appears) ends it
# with one line. :class:`Started` runs a command in a session of its own (its own process
# group, like a terminal's foreground job); :meth:`Started.interrupt` sends Ctrl-C as a
# terminal does. Its output goes to files, never pipes: a child left behind holding a pipe
# would hang the test instead of failing it.

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


def without_timings(x: Any, nan_as_null: bool = False) -> Any:
    """results.json (or part of it) without the measured timings (keys ending ``_us``), which
    differ from run to run; ``nan_as_null``: NaN as None, as a saved results.json holds it."""
    if nan_as_null and isinstance(x, float) and x != x:
        return None
    if isinstance(x, dict):
        return {k: without_timings(v, nan_as_null) for k, v in x.items() if not k.endswith("_us")}
    if isinstance(x, list):
        return [without_timings(v, nan_as_null) for v in x]
    return x


def copy_model(src: Path, dst: Path, with_core: bool = True) -> Path:
    """A copy of the model folder ``src`` (model.onnx, model.json and, with ``with_core``,
    model.core.npz) in the new folder ``dst``; returns ``dst``."""
    dst.mkdir()
    for name in ("model.onnx", "model.json") + (("model.core.npz",) if with_core else ()):
        shutil.copy(src / name, dst / name)
    return dst
