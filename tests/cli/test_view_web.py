"""``bench view FILE --web``: the pure parts (ports, URL, ssh line, server environment) and
the command's behaviour against a stand-in ``rerun`` (a small Python server that opens the
two ports it is given), so no browser and no real viewer are needed here. The real viewer
in a real browser is tests/cli/test_browser_view.py."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import ROOT, assert_one_error_line, bench

from posbench.errors import UsageError
from posbench.recording import web as rerun_web

pytestmark = pytest.mark.serial  # serves free ports, read within deadlines


def free_port_pair() -> int:
    """A port N with N and N+1 both free on 127.0.0.1 (the OS picks N)."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind((rerun_web.HOST, 0))
            n = s.getsockname()[1]
        if n < 65535 and not rerun_web.port_in_use(n) and not rerun_web.port_in_use(n + 1):
            return n
    raise RuntimeError("no two consecutive free ports found")


# ------------------------------------------------------------------ pure parts
def test_web_port_and_data_port():
    assert rerun_web.check_web_port(9090) == (9090, 9091)
    assert rerun_web.check_web_port(65534) == (65534, 65535)
    for bad in (0, -1, 65535, 70000):
        with pytest.raises(UsageError, match=f"--port must be a TCP port from 1 to 65534.*{bad}"):
            rerun_web.check_web_port(bad)


def test_viewer_url_is_what_rerun_prints_with_webgl():
    # rerun 0.41 prints http://127.0.0.1:9090?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9876%2Fproxy
    assert rerun_web.viewer_url(9090, 9091) == (
        "http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9091%2Fproxy&renderer=webgl"
    )
    assert rerun_web.viewer_url(8000, 8001, renderer=None).endswith("%3A8001%2Fproxy")


def test_ssh_line_forwards_both_ports():
    assert rerun_web.ssh_forward_command(9090, 9091, "gpu-box") == (
        "ssh -L 9090:localhost:9090 -L 9091:localhost:9091 gpu-box"
    )


def test_server_command_listens_locally_with_webgl(tmp_path):
    cmd = rerun_web.server_command("rerun", tmp_path / "a.rrd", 9090, 9091)
    assert cmd[0] == "rerun" and cmd[-1] == str(tmp_path / "a.rrd")
    pairs = dict(zip(cmd[1:-1], cmd[2:-1], strict=False))
    assert pairs["--web-viewer-port"] == "9090" and pairs["--port"] == "9091"
    assert pairs["--bind"] == "127.0.0.1" and pairs["--renderer"] == "webgl"
    assert "--web-viewer" in cmd


def test_server_env_turns_analytics_and_the_browser_off():
    env = rerun_web.server_env({"PATH": "/bin", "HOME": "/h"})
    assert env == {"PATH": "/bin", "HOME": "/h", "CI": "1", "BROWSER": "true"}
    assert rerun_web.server_env({"CI": "true"})["CI"] == "true"  # a CI's own value stays


def test_port_in_use_sees_a_listening_socket():
    n = free_port_pair()
    assert not rerun_web.port_in_use(n)
    with socket.socket() as s:
        s.bind((rerun_web.HOST, n))
        s.listen()
        assert rerun_web.port_in_use(n)
    assert not rerun_web.port_in_use(n)


def test_check_ports_free_names_the_taken_port():
    rerun_web.check_ports_free(9090, 9091, in_use=lambda p: False)
    with pytest.raises(UsageError, match=r"port 9091 \(the recording\) is already in use"):
        rerun_web.check_ports_free(9090, 9091, in_use=lambda p: p == 9091)
    with pytest.raises(UsageError, match=r"port 9090 \(the web viewer's page\).*--port N"):
        rerun_web.check_ports_free(9090, 9091, in_use=lambda p: True)


# ------------------------------------------------------------------ the command
FAKE_SERVER = """#!{python}
# stands in for `rerun --web-viewer`: listens on the two ports it is given, notes its
# environment, serves until terminated
import json, os, signal, socket, sys, time
args = sys.argv[1:]
ports = [int(args[args.index(o) + 1]) for o in ("--web-viewer-port", "--port")]
with open({note!r}, "w") as f:
    json.dump({{"argv": args, "CI": os.environ.get("CI"),
               "BROWSER": os.environ.get("BROWSER"), "pid": os.getpid()}}, f)
mode = {mode!r}
if mode == "fail":
    print("Error: Failed to create server: Address already in use (os error 98)",
          file=sys.stderr)
    sys.exit(1)
socks = []
for p in ports:
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("127.0.0.1", p))
    s.listen()
    socks.append(s)
if mode == "crash":
    time.sleep(1)
    print("thread 'main' panicked: out of memory", file=sys.stderr)
    sys.exit(101)
while True:
    time.sleep(0.2)
"""


def fake_rerun(tmp_path: Path, mode: str = "serve") -> tuple[dict[str, str], Path]:
    """A PATH with a stand-in ``rerun`` first, and the file where it writes its argv."""
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir(exist_ok=True)
    note = tmp_path / "rerun-started.json"
    exe = fake_bin / "rerun"
    exe.write_text(FAKE_SERVER.format(python=sys.executable, note=str(note), mode=mode))
    exe.chmod(0o755)
    return {"PATH": f"{fake_bin}{os.pathsep}{os.environ['PATH']}"}, note


def start_view(rrd: Path, port: int, env: dict[str, str]) -> subprocess.Popen:
    base = {
        **os.environ,
        "COLUMNS": "200",
        **env,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    }
    return subprocess.Popen(
        [sys.executable, "-m", "posbench", "view", str(rrd), "--web", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=base,
        cwd=ROOT,
    )


def cleanup(proc: subprocess.Popen, note: Path | None = None) -> None:
    """After a failed test: stop ``bench view`` the way a user would (SIGTERM, so that it
    stops its server), then by force, and the stand-in server if it is still there."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
    proc.communicate()
    if note is not None and note.exists():
        import json

        try:
            os.kill(json.loads(note.read_text())["pid"], signal.SIGKILL)
        except (ProcessLookupError, ValueError, KeyError):
            pass


def read_until(proc: subprocess.Popen, prefix: str, timeout_s: float = 60.0) -> list[str]:
    """stdout lines up to and including the first that starts with ``prefix`` (read by a
    thread, so a silent process cannot block the test past ``timeout_s``)."""
    import queue
    import threading

    q: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        for line in proc.stdout:
            q.put(line.rstrip("\n"))
            if line.startswith(prefix):
                return
        q.put("")  # end of output

    threading.Thread(target=pump, daemon=True).start()
    lines, deadline = [], time.monotonic() + timeout_s
    while (left := deadline - time.monotonic()) > 0:
        try:
            line = q.get(timeout=left)
        except queue.Empty:
            break
        if line == "" and proc.poll() is not None:
            break
        lines.append(line)
        if line.startswith(prefix):
            return lines
    raise AssertionError(
        f"no {prefix!r} line in {lines}; stderr: "
        f"{proc.stderr.read() if proc.poll() is not None else '(running)'}"
    )


def test_web_serves_prints_the_url_and_stops_cleanly_on_ctrl_c(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    env, note = fake_rerun(tmp_path)
    n = free_port_pair()
    proc = start_view(rrd, n, env)
    try:
        lines = read_until(proc, "from another machine")
        assert lines[0].startswith(f"serving {rrd} with rerun's web viewer"), lines
        assert f"open: {rerun_web.viewer_url(n, n + 1)}" in lines
        assert any("renderer=webgl works without a GPU" in ln for ln in lines)
        assert f"ssh -L {n}:localhost:{n} -L {n + 1}:localhost:{n + 1} " in lines[-1]
        import json

        started = json.loads(note.read_text())
        assert started["argv"] == rerun_web.server_command("x", rrd, n, n + 1)[1:]
        assert started["CI"] and started["BROWSER"] == "true"
        assert rerun_web.port_in_use(n) and rerun_web.port_in_use(n + 1)
        proc.send_signal(signal.SIGINT)  # what Ctrl-C sends
        out, err = proc.communicate(timeout=30)
    finally:
        cleanup(proc, note)
    assert proc.returncode == 0, err
    assert err == "" and out.strip().endswith("stopped")
    with pytest.raises(ProcessLookupError):  # the server went with it
        os.kill(started["pid"], 0)
    assert not rerun_web.port_in_use(n) and not rerun_web.port_in_use(n + 1)


def serving(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    """`bench view --web` on a stand-in recording and server, started and serving (its
    URL printed); the stand-in's note file (its pid under ``pid``)."""
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    env, note = fake_rerun(tmp_path)
    proc = start_view(rrd, free_port_pair(), env)
    try:
        read_until(proc, "open: ")
    except BaseException:
        cleanup(proc, note)
        raise
    return proc, note


def server_pid(note: Path) -> int:
    import json

    return int(json.loads(note.read_text())["pid"])


def test_web_stops_the_server_on_sigterm_too(tmp_path):
    proc, note = serving(tmp_path)
    try:
        pid = server_pid(note)
        proc.terminate()
        out, err = proc.communicate(timeout=30)
    finally:
        cleanup(proc, note)
    assert proc.returncode == 0 and err == "", err
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_web_port_in_use_is_one_error_line(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    env, note = fake_rerun(tmp_path)
    n = free_port_pair()
    with socket.socket() as s:
        s.bind((rerun_web.HOST, n + 1))
        s.listen()
        r = bench("view", str(rrd), "--web", "--port", str(n), env=env)
    assert_one_error_line(r, f"port {n + 1} (the recording) is already in use", "--port N")
    assert not note.exists()  # the server was not started


def test_web_server_that_fails_to_start_is_one_error_line(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    env, _ = fake_rerun(tmp_path, mode="fail")
    r = bench("view", str(rrd), "--web", "--port", str(free_port_pair()), env=env)
    assert_one_error_line(r, "the rerun web server exited with status 1", "Address already in use")


def test_web_server_that_dies_while_serving_is_one_error_line(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    env, _ = fake_rerun(tmp_path, mode="crash")
    r = bench("view", str(rrd), "--web", "--port", str(free_port_pair()), env=env)
    assert_one_error_line(r, "the rerun web server stopped with status 101", "panicked")
    assert "open: " in r.stdout  # it did come up before it died


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--port", "9090"], "--port is the web viewer's port: use it with --web"),
        (["--web", "--port", "0"], "--port must be a TCP port from 1 to 65534"),
        (["--web", "--port", "65535"], "--port must be a TCP port from 1 to 65534"),
        (["--web", "--port", "x"], "--port"),
    ],
)
def test_bad_port_options_are_one_error_line(tmp_path, args, needle):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    env, note = fake_rerun(tmp_path)
    r = bench("view", str(rrd), *args, env=env)
    assert_one_error_line(r, needle)
    assert not note.exists()


def test_web_on_a_missing_file_is_one_error_line(tmp_path):
    env, note = fake_rerun(tmp_path)
    r = bench("view", str(tmp_path / "nope.rrd"), "--web", env=env)
    assert_one_error_line(r, f"{tmp_path / 'nope.rrd'}: no such file")
    assert not note.exists()


def test_web_server_ends_with_bench_view_killed_by_force(tmp_path):
    """`kill -9` of `bench view --web` (no handler runs) still ends the server: the kernel
    sends it SIGTERM when its parent dies (issue 49)."""
    proc, note = serving(tmp_path)
    try:
        pid = server_pid(note)
        os.kill(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=30)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            try:  # reap it if it is ours (it is not: it was bench view's child)
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass
            time.sleep(0.1)
        else:
            raise AssertionError("the web server outlived bench view")
    finally:
        cleanup(proc, note)


def test_the_sdk_launcher_is_replaced_by_its_viewer_binary(tmp_path):
    plain = tmp_path / "rerun"
    plain.write_text("#!/bin/sh\nexec sleep 1\n")
    assert rerun_web.viewer_binary(str(plain)) == str(plain)
    assert rerun_web.viewer_binary(str(tmp_path / "missing")) == str(tmp_path / "missing")
    import importlib.util

    if importlib.util.find_spec("rerun_cli") is None:
        return  # the viz extra is not installed: nothing to replace
    launcher = tmp_path / "rerun-sdk"
    launcher.write_text("#!/usr/bin/python\nfrom rerun_cli.__main__ import main\nmain()\n")
    got = Path(rerun_web.viewer_binary(str(launcher)))
    assert got.name in ("rerun", "rerun.exe") and got.parent.name == "rerun_cli"
