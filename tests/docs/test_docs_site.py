"""The docs site (mkdocs.yml, docs/): it builds with ``mkdocs build --strict`` (the running
interpreter's mkdocs), its generated reference names every ``bench`` command and the
Python API of saved runs, its tables come from the code, and the system Chromium shows
the landing page and the CLI reference (title, navigation, no console error), served by a
local ``http.server``.

The browser part needs ``chromium`` (Debian package; ``.ci/run`` installs it) and the
``playwright`` package (dev extra; it drives the system browser and never downloads
one), launched as tests/cli/test_browser_view.py launches it. Without them that part skips,
but fails when ``CI`` is set.
"""

from __future__ import annotations

import dataclasses
import functools
import html
import http.server
import json
import os
import re
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import CHROMIUM_ARGS, ROOT

pytestmark = pytest.mark.slow

#: every command the CLI reference must name
COMMANDS = (
    "run",
    "compare",
    "score",
    "queries",
    "check",
    "data inspect",
    "view",
    "latency",
    "tune",
    "train",
    "predictors",
    "export",
)
#: the pages opened in the browser: path below the site, a text the page must show
BROWSER_PAGES = (("", "posbench"), ("reference/cli/", "bench data inspect"))
#: the peak memories of reports/scaling.json, in the Speed page's column order
RSS_KEYS = ("main", "worker", "largest")
#: where mkdocs-material's repository facts (stars, forks) come from
GITHUB_API = "https://api.github.com/"


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site as ``mkdocs build --strict`` writes it (any warning fails the build)."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert (out / "index.html").is_file()
    return out


def page(site: Path, path: str) -> str:
    return (site / path / "index.html").read_text(encoding="utf-8")


def text(html_page: str) -> str:
    """A page's text: tags removed (a highlighted code block is one span per word)."""
    return html.unescape(re.sub(r"<[^>]+>", "", html_page))


def test_cli_reference_names_every_command(site: Path) -> None:
    cli = page(site, "reference/cli")
    for cmd in COMMANDS:
        assert f'id="bench-{cmd.replace(" ", "-")}"' in cli, cmd
        assert f"bench {cmd} [OPTIONS]" in text(cli), cmd
    # generated from the app itself: the commands' options are there
    assert "--gps-profile" in cli and "--fail-if-worse" in cli


def test_api_reference_has_the_run_api(site: Path) -> None:
    api = page(site, "reference/api")
    for ident in (
        "posbench.run",
        "posbench.score",
        "posbench.load",
        "posbench.saved_run.run.Run",
        "posbench.saved_run.run.load_run",
        "posbench.predictors.base.Predictor",
        "posbench.scenarios.drive.Drive",
        "posbench.scenarios.drive.GpsStream",
        "posbench.scenarios.loaders.load",
        "posbench.metrics.accuracy.summarize",
    ):
        assert f'id="{ident}"' in api, ident
    assert ":class:" not in api  # the docstrings' RST roles read as Markdown


def test_reference_tables_come_from_the_code(site: Path) -> None:
    from posbench.report.glossary import glossary
    from posbench.saved_run.run import results_schema
    from posbench.scenarios.consistency import Tolerances
    from posbench.scoring.schema import TRACE_COLUMNS

    traces = page(site, "reference/traces")
    assert all(f"<code>{c}</code>" in traces for c in TRACE_COLUMNS)
    thresholds = page(site, "reference/data-check-thresholds")
    for f in dataclasses.fields(Tolerances):
        assert f"<code>{f.name}</code>" in thresholds, f.name
        assert f"<code>{f.default!r}</code>" in thresholds, f.name
    schema = page(site, "reference/results-schema")
    assert all(f"<code>{k}</code>" in schema for k in results_schema()["properties"])
    terms = page(site, "reference/glossary")
    assert all(f"<strong>{t}</strong>" in terms for t, _ in glossary({}))


def test_results_come_from_the_reports(site: Path) -> None:
    results = page(site, "results")
    shown = text(results)
    reports = sorted(ROOT.glob("reports/*/results.json"))
    assert reports
    for f in reports:
        res = json.loads(f.read_text())
        name = f.parent.name
        assert f'id="{name}"' in results and f"/blob/main/reports/{name}/report.md" in results
        assert f"$ {res['command']}" in shown, name
        for p, figures in res["predictors"].items():
            mean, (lo, hi) = figures["future"]["mean_m"], figures["future"]["ci95"]["mean_m"]
            assert f"{mean:.3f} [{lo:.3f}, {hi:.3f}]" in shown, (name, p)


def test_speed_comes_from_the_scaling_report(site: Path) -> None:
    """Every run of reports/scaling.json is a row of the Speed page: its case, drive hours,
    predictors, wall time and each peak memory it measured (``-`` where it measured none)."""
    speed = page(site, "results/speed")
    rows = [
        [text(c).strip() for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", tr, re.S)]
        for tr in re.findall(r"<tr>(.*?)</tr>", speed, re.S)
    ]
    sc = json.loads((ROOT / "reports" / "scaling.json").read_text())
    runs = [r for r in sc["runs"] + sc.get("cases", []) if not r.get("skipped")]
    assert runs
    for r in runs:
        for name, wall in r["wall_s"].items():
            rss = r.get("peak_rss_mb", {}).get(name, {})
            mb = [f"{v:.0f}" if (v := rss.get(k)) is not None else "-" for k in RSS_KEYS]
            want = [f"{r['drive_hours']:.2f}", "default" if name == sc["predictors"] else name]
            want += [f"{wall:.0f}"]
            assert any([c[1], c[3], c[4], *c[7:10]] == [*want, *mb] for c in rows), (r, name)


# ---------------------------------------------------------------------------- browser
class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:  # noqa: A002
        pass


@pytest.fixture(scope="module")
def served(site: Path) -> Iterator[str]:
    """The built site on http://127.0.0.1:PORT/ (a free port the OS picks)."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)


@pytest.mark.browser
@pytest.mark.parametrize(("path", "text"), BROWSER_PAGES)
def test_pages_render_in_chromium(chromium: str, served: str, path: str, text: str) -> None:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            tab = browser.new_page(viewport={"width": 1400, "height": 900})
            errors: list[tuple[str, str]] = []
            failed: list[str] = []
            tab.on(
                "console",
                lambda m: (
                    errors.append((m.text, m.location.get("url", "")))
                    if m.type == "error"
                    else None
                ),
            )
            tab.on("pageerror", lambda e: errors.append((str(e), "")))
            tab.on("requestfailed", lambda r: failed.append(r.url))
            response = tab.goto(served + path, wait_until="load")
            assert response is not None and response.ok, path
            tab.wait_for_load_state("networkidle")
            title = tab.title()
            nav = tab.locator("nav.md-nav--primary").first
            nav_text = nav.inner_text()
            body = tab.inner_text("body")
        finally:
            browser.close()
    assert "posbench" in title, title
    for section in ("Start", "Concepts", "Guides", "Reference", "Results"):
        assert section in nav_text, (section, nav_text[:500])
    assert text in body
    # the one request that leaves the site: the theme asks GitHub for the repository's
    # stars (repo_url), which fails offline; nothing else may fail or log an error
    off_site = [u for u in failed if not u.startswith(served)]
    assert all(u.startswith(GITHUB_API) for u in off_site), failed
    assert not [u for u in failed if u.startswith(served)], failed
    assert [(msg, url) for msg, url in errors if not url.startswith(GITHUB_API)] == []
