"""Serve a rerun recording to a browser: ports, the URL to open, the ``rerun`` web server.

``bench view FILE --web --port N`` runs rerun's own CLI (rerun-sdk 0.41)::

    rerun --web-viewer --web-viewer-port N --port N+1 --bind 127.0.0.1 --renderer webgl FILE

which serves the viewer's page over HTTP on port ``N`` and the recording over gRPC on
port ``N + 1``. Both listen on 127.0.0.1 only: from another machine, forward both ports
with ``ssh -L``. The page is told where the data is by its URL
(``?url=rerun+http://127.0.0.1:N+1/proxy``) and which renderer to use: WebGL, since
WebGPU without a GPU (a headless or remote browser, software rendering) crashes the
viewer ("createBuffer failed ... too large").

The pure parts (port checks, URL, the ``ssh`` line, the server's environment) are
functions here; :func:`serve` starts the server, waits until both ports answer and
keeps it running until Ctrl-C.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO
from urllib.parse import quote

from posbench.errors import UsageError
from posbench.scenarios.child_processes import exec_with_parent_death

#: the host both servers listen on; other machines reach it through ``ssh -L``
HOST = "127.0.0.1"
DEFAULT_WEB_PORT = 9090
#: the recording's gRPC port is the web port plus this
DATA_PORT_OFFSET = 1
#: WebGPU without a GPU crashes the viewer; WebGL runs everywhere (software too)
RENDERER = "webgl"
#: how long the server may take to open both ports [s]
READY_TIMEOUT_S = 30.0


class ServeError(Exception):
    """The rerun web server could not start or stopped on its own (one line)."""


def check_web_port(port: int, option: str = "--port") -> tuple[int, int]:
    """``(web port, data port)`` for ``--port N``: N serves the page, N+1 the recording."""
    top = 65535 - DATA_PORT_OFFSET
    if not 1 <= port <= top:
        raise UsageError(
            f"{option} must be a TCP port from 1 to {top} (the recording is "
            f"served on the next port, {option} + {DATA_PORT_OFFSET}); got {port}"
        )
    return port, port + DATA_PORT_OFFSET


def port_in_use(port: int, host: str = HOST) -> bool:
    """Whether ``host:port`` cannot be listened on now (another program holds it).

    Binds the way rerun's server does (``SO_REUSEADDR`` on POSIX), so a port that only
    has connections in TIME_WAIT counts as free.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        if os.name == "posix":
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return True
    return False


def check_ports_free(
    web_port: int,
    data_port: int,
    option: str = "--port",
    in_use: Callable[[int], bool] = port_in_use,
) -> None:
    """A :class:`UsageError` naming the first of the two ports that is taken."""
    for port, what in ((web_port, "the web viewer's page"), (data_port, "the recording")):
        if in_use(port):
            raise UsageError(
                f"port {port} ({what}) is already in use on {HOST}: pick other "
                f"ports with {option} N (uses N and N+{DATA_PORT_OFFSET})"
            )


def viewer_url(
    web_port: int, data_port: int, host: str = HOST, renderer: str | None = RENDERER
) -> str:
    """The address to open in a browser: the page on ``web_port`` reading the recording
    from rerun's gRPC proxy on ``data_port``, with the renderer forced (None: the
    browser's default, WebGPU where it has one)."""
    data = quote(f"rerun+http://{host}:{data_port}/proxy", safe="")
    url = f"http://{host}:{web_port}/?url={data}"
    return f"{url}&renderer={renderer}" if renderer else url


def ssh_forward_command(web_port: int, data_port: int, host: str) -> str:
    """The ``ssh`` line to run on your own machine to reach both ports of ``host``."""
    return f"ssh -L {web_port}:localhost:{web_port} -L {data_port}:localhost:{data_port} {host}"


def viewer_binary(exe: str) -> str:
    """The program to start for ``exe``: the rerun-sdk's ``rerun`` launcher is a Python
    script that only runs the viewer binary beside its package (``rerun_cli/rerun``) as a
    child; that binary itself is started instead, so that it is the server's one process and
    ends with ``bench`` (:func:`serve`). Any other ``exe`` as it is."""
    try:
        with open(exe, "rb") as f:
            head = f.read(4096)
    except OSError:
        return exe
    if b"rerun_cli" not in head or "RERUN_CLI_PATH" in os.environ:
        return exe
    import importlib.util

    spec = importlib.util.find_spec("rerun_cli")
    if spec is None or spec.origin is None:
        return exe
    binary = Path(spec.origin).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    return str(binary) if binary.is_file() and os.access(binary, os.X_OK) else exe


def server_command(exe: str, recording: Path, web_port: int, data_port: int) -> list[str]:
    """The ``rerun`` command line that serves ``recording`` (see the module docstring)."""
    return [
        exe,
        "--web-viewer",
        "--web-viewer-port",
        str(web_port),
        "--port",
        str(data_port),
        "--bind",
        HOST,
        "--renderer",
        RENDERER,
        str(recording),
    ]


def server_env(base: Mapping[str, str]) -> dict[str, str]:
    """``base`` with what keeps the rerun CLI quiet and local.

    * ``CI=1``: rerun 0.41's CLI collects usage analytics (files under ``~/.config/rerun``
      and ``~/.local/share/rerun``, a welcome banner on stderr) unless it runs on CI
      ("Analytics disabled on CI" in its debug log); there is no environment switch
      of its own (``RERUN_ANALYTICS=0`` is ignored) and ``rerun analytics disable``
      would change the user's settings for every program.
    * ``BROWSER=true``: ``--web-viewer`` opens the URL in a browser itself, through
      ``$BROWSER`` on Linux; on a remote machine that starts a browser nobody sees.
      ``bench view`` prints the URL instead.
    """
    return {**base, "CI": base.get("CI") or "1", "BROWSER": "true"}


def _last_line(log: IO[bytes]) -> str:
    """The last non-empty line of rerun's log, without terminal colours (max 200 chars)."""
    import re

    log.flush()
    log.seek(0)
    text = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", log.read().decode("utf-8", "replace"))
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1][:200] if lines else ""


def _listening(port: int, host: str = HOST) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.5)
        return s.connect_ex((host, port)) == 0


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """End the server's process group (the ``rerun`` launcher script and the viewer binary
    it starts): SIGTERM, then SIGKILL after 5 s."""
    if os.name != "posix":  # no process groups: the launcher only
        proc.terminate()
        proc.wait()
        return
    for sig in (signal.SIGTERM, signal.SIGKILL):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(5.0)
        except subprocess.TimeoutExpired:
            continue
    try:  # the launcher may be gone while the binary it started still runs
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _raise_keyboard_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def serve(
    exe: str,
    recording: Path,
    web_port: int,
    data_port: int,
    on_ready: Callable[[], None],
    ready_timeout_s: float = READY_TIMEOUT_S,
) -> None:
    """Run rerun's web server on ``recording`` until Ctrl-C (or SIGTERM/SIGHUP), then stop
    it and return. ``on_ready`` is called once both ports answer.

    Raises :class:`ServeError` when the server does not come up within
    ``ready_timeout_s`` seconds or exits on its own (its last log line is quoted).
    """
    handlers = {}
    for name in ("SIGTERM", "SIGHUP"):  # stop the server too, not just this process
        sig = getattr(signal, name, None)  # no SIGHUP on Windows
        if sig is not None:
            handlers[sig] = signal.signal(sig, _raise_keyboard_interrupt)
    try:
        with tempfile.TemporaryFile() as log:
            proc = subprocess.Popen(
                server_command(viewer_binary(exe), recording, web_port, data_port),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
                env=server_env(os.environ),
                start_new_session=True,
                # the server ends with this process however it ends (a kill -9 included)
                preexec_fn=exec_with_parent_death(os.getpid()) if os.name == "posix" else None,
            )
            try:
                _wait_ready(proc, log, (web_port, data_port), ready_timeout_s)
                on_ready()
                status = proc.wait()
                why = _last_line(log)
                raise ServeError(
                    f"the rerun web server stopped with status {status}"
                    + (f": {why}" if why else "")
                )
            except KeyboardInterrupt:
                return
            finally:
                _stop(proc)
    finally:
        for sig, old in handlers.items():
            signal.signal(sig, old)


def _wait_ready(
    proc: subprocess.Popen[bytes], log: IO[bytes], ports: tuple[int, ...], timeout_s: float
) -> None:
    deadline = time.monotonic() + timeout_s
    while not all(_listening(p) for p in ports):
        if proc.poll() is not None:
            why = _last_line(log)
            raise ServeError(
                f"the rerun web server exited with status {proc.returncode}"
                + (f": {why}" if why else "")
            )
        if time.monotonic() > deadline:
            raise ServeError(
                f"the rerun web server did not open ports "
                f"{', '.join(map(str, ports))} within {timeout_s:g} s"
            )
        time.sleep(0.1)
