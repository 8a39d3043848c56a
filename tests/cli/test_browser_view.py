"""A recording of ``bench run --rerun`` opened in rerun's web viewer in a real browser.

``bench run`` writes a short synthetic drive (cv and kf) to an .rrd file; ``bench view
FILE --web --port N`` serves it (two free ports); the system Chromium, driven by
playwright with software WebGL (SwiftShader; ``renderer=webgl`` is in the printed URL),
opens the printed URL. The viewer draws everything on one canvas (no DOM text, no
accessibility tree), so what it has loaded is asked from the viewer itself through the
handle its page exposes (``window._handle``):

* ``viewer_state()`` (the Viewer Control API's state) must name the drive - the viewer
  has the recording open and its blueprint's views;
* ``save_recording()`` (the active recording as the viewer holds it, RRD bytes) is read
  back with rerun's own reader: its entities must include every predictor's and be
  the file's entities for that recording.

Then: no "Rerun has crashed" in the page, ``has_panicked()`` false, and a screenshot
(1600x1000) that is not blank, saved under the test's tmp dir and, when
``POSBENCH_SCREENSHOT_DIR`` is set, there too (for the README). ``bench view`` is then
stopped with SIGINT (Ctrl-C) and must exit 0 and leave no process and no open port.

Needs ``chromium`` (Debian package; ``.ci/run`` installs it) and the ``playwright``
package (dev extra; it drives the system browser and never downloads one). Without
them the test skips, but fails when ``CI`` is set.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import CHROMIUM_ARGS, bench
from test_view_web import ROOT, free_port_pair, read_until

from posbench.recording import web as rerun_web

# serial: a software-WebGL browser and a server on free ports, within deadlines
pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.serial]

PREDICTORS = ("cv", "kf")
VIEWPORT = {"width": 1600, "height": 1000}
#: how long the viewer may take to start and load the recording [s]
LOAD_TIMEOUT_S = 90
SCREENSHOT_NAME = "rerun-web-viewer.png"

#: true once the viewer has started and its state names ``needle`` (or it has panicked)
LOADED_JS = """(needle) => {
    const h = window._handle;
    if (h === undefined) return false;
    if (h.has_panicked()) return true;
    return new TextDecoder("latin1").decode(h.viewer_state()).includes(needle);
}"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """A 20 s synthetic drive through cv and kf as an .rrd file; and its drive names."""
    d = tmp_path_factory.mktemp("browser")
    rrd = d / "run.rrd"
    r = bench(
        "run",
        "-p",
        ",".join(PREDICTORS),
        "--synthetic-duration",
        "20",
        "--workers",
        "1",
        "--drive-plots",
        "0",
        "--out",
        str(d / "out"),
        "--rerun",
        str(rrd),
        cwd=d,
    )
    assert r.returncode == 0, r.stderr
    drives = [x["name"] for x in json.loads((d / "out" / "results.json").read_text())["drives"]]
    assert rrd.is_file() and drives
    return rrd, drives


def descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    status = Path(f"/proc/{pid}/status")
    return not (status.exists() and "\nState:\tZ" in status.read_text())


def entity_paths(rrd: Path, recording_id: str | None = None) -> tuple[str, set[str]]:
    """A recording's id and its entity paths (the only recording, or ``recording_id``)."""
    import rerun as rr

    reader = rr.chunk.RrdReader(rrd)
    recs = reader.recordings()
    rec = (
        recs[0] if recording_id is None else next(r for r in recs if r.recording_id == recording_id)
    )
    return rec.recording_id, {c.entity_path for c in reader.stream(store=rec).to_chunks()}


def stable_screenshot(page, path: Path, timeout_s: float = 20.0) -> bool:
    """Screenshot ``page`` into ``path`` once two consecutive shots 1 s apart are equal
    (True), or the last one after ``timeout_s`` (False)."""
    last, deadline = b"", time.monotonic() + timeout_s
    while True:
        shot = page.screenshot()
        if shot == last or time.monotonic() > deadline:
            path.write_bytes(shot)
            return shot == last
        last = shot
        time.sleep(1.0)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_recording_renders_in_rerun_web_viewer(chromium, recording, tmp_path):
    from PIL import Image
    from playwright.sync_api import sync_playwright

    rrd, drives = recording
    t0 = time.monotonic()
    n = free_port_pair()
    env = {
        **os.environ,
        "COLUMNS": "200",
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    }
    server = subprocess.Popen(
        [sys.executable, "-m", "posbench", "view", str(rrd), "--web", "--port", str(n)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )
    spawned: set[int] = set()
    try:
        url = read_until(server, "open: ", timeout_s=60)[-1].removeprefix("open: ")
        assert url == rerun_web.viewer_url(n, n + 1) and "renderer=webgl" in url
        spawned = descendants(server.pid)
        assert spawned, "bench view started no server process"
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport=VIEWPORT)
                errors: list[str] = []
                page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
                page.goto(url)
                page.wait_for_function(
                    LOADED_JS, arg=drives[0], polling=500, timeout=LOAD_TIMEOUT_S * 1000
                )
                loaded_s = time.monotonic() - t0
                shot = tmp_path / SCREENSHOT_NAME
                stable = stable_screenshot(page, shot)
                panicked = page.evaluate("window._handle.has_panicked()")
                text = page.inner_text("body")
                state = bytes(page.evaluate("Array.from(window._handle.viewer_state())"))
                (tmp_path / "viewer.rrd").write_bytes(
                    bytes(page.evaluate("Array.from(window._handle.save_recording())"))
                )
            finally:
                browser.close()
        print(
            f"viewer loaded the recording {loaded_s:.1f} s after `bench view` started; "
            f"screenshot {'stable' if stable else 'still changing'}: {shot}"
        )
        if os.environ.get("POSBENCH_SCREENSHOT_DIR"):
            out = Path(os.environ["POSBENCH_SCREENSHOT_DIR"])
            out.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(shot, out / SCREENSHOT_NAME)

        # the viewer did not crash
        assert not panicked, text[:1000]
        assert "Rerun has crashed" not in text
        assert not any("Rerun has crashed" in e for e in errors), errors
        # it has the recording open, under the drive's name, with every predictor's entities
        assert drives[0].encode() in state
        rec_id, viewer_entities = entity_paths(tmp_path / "viewer.rrd")
        _, file_entities = entity_paths(rrd, rec_id)
        assert viewer_entities >= file_entities - {"/__properties"}
        for p in PREDICTORS:
            assert any(re.search(rf"/{p}(/|$)", e) for e in viewer_entities), (p, viewer_entities)
        # and drew something: a full-size screenshot with more than a handful of colours
        with Image.open(shot) as img:
            assert img.size == (VIEWPORT["width"], VIEWPORT["height"])
            assert len(img.convert("RGB").getcolors(maxcolors=1 << 20) or []) > 100

        # Ctrl-C: exit 0, the server gone, the ports free
        server.send_signal(signal.SIGINT)
        out_text, err = server.communicate(timeout=30)
        assert server.returncode == 0 and err == "", err
        assert out_text.strip().endswith("stopped")
        assert not any(alive(p) for p in spawned)
        assert not rerun_web.port_in_use(n) and not rerun_web.port_in_use(n + 1)
    finally:  # after a failure: stop bench view as a user would, then by force
        if server.poll() is None:
            spawned |= descendants(server.pid)
            server.terminate()
            try:
                server.wait(15)
            except subprocess.TimeoutExpired:
                pass
        for pid in [server.pid, *spawned]:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
        server.communicate()
