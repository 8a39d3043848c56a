"""The documentation's examples are collected and run: at least 5 executable blocks in docs/,
and one on each page the docs promise an example that runs (issue 30).

The blocks are found as docs/conftest.py finds them (sybil's markdown lexers): fenced
``python`` and ``bash`` blocks, less those a ``<!-- skip: next -->`` (or a
``skip: start`` ... ``skip: end`` range) turns off. This test counts them; pytest runs them
through docs/conftest.py (``pytest docs``)."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import ROOT
from sybil import Document
from sybil.parsers.markdown.lexers import DirectiveInHTMLCommentLexer, FencedCodeBlockLexer

DOCS = ROOT / "docs"
RUN_LANGUAGES = ("python", "bash")


def executable_blocks(page: Path) -> list[tuple[str, str]]:
    """(language, source) of each block of ``page`` that pytest runs, in page order."""
    doc = Document(page.read_text(encoding="utf-8"), str(page))
    events = []
    for region in FencedCodeBlockLexer(language=r".+")(doc):
        if region.lexemes["language"] in RUN_LANGUAGES:
            events.append(
                (region.start, "block", (region.lexemes["language"], region.lexemes["source"]))
            )
    for region in DirectiveInHTMLCommentLexer("skip")(doc):
        events.append((region.start, "skip", region.lexemes["arguments"].split()[0]))
    blocks, skip_next, skipping = [], False, False
    for _, what, value in sorted(events, key=lambda e: e[0]):
        if what == "skip":
            if value == "next":
                skip_next = True
            elif value == "start":
                skipping = True
            elif value == "end":
                skipping = False
            continue
        if skip_next or skipping:
            skip_next = False
            continue
        blocks.append(value)
    return blocks


def all_pages() -> dict[str, list[tuple[str, str]]]:
    return {
        p.relative_to(DOCS).as_posix(): executable_blocks(p) for p in sorted(DOCS.rglob("*.md"))
    }


def test_the_parser_follows_the_skip_convention(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text(
        "```python\nx = 1\n```\n\n<!-- skip: next -->\n\n```bash\nexit 1\n```\n\n"
        "```text\nnot run\n```\n\n```console\n$ not run\n```\n\n<!-- skip: start -->\n\n"
        "```python\nraise SystemExit\n```\n\n<!-- skip: end -->\n\n```bash\necho ok\n```\n"
    )
    assert executable_blocks(page) == [("python", "x = 1\n"), ("bash", "echo ok\n")]


def test_at_least_five_examples_run() -> None:
    n = sum(len(b) for b in all_pages().values())
    assert n >= 5, f"only {n} executable examples in docs/"


@pytest.mark.parametrize(
    "page",
    [
        "start/first-run.md",
        "start/your-data.md",
        "guides/own-predictor.md",
        "guides/offline-scoring.md",
        "guides/compare-and-ci.md",
        "guides/csv-format.md",
        "guides/tuning.md",
    ],
)
def test_page_has_an_example_that_runs(page: str) -> None:
    path = DOCS / page
    assert path.is_file(), f"docs/{page} is missing"
    assert executable_blocks(path), f"docs/{page} has no python or bash block that runs"


def test_the_plugin_example_runs_a_predictor_of_ones_own_and_checks_it() -> None:
    text = "\n".join(src for _, src in executable_blocks(DOCS / "guides/own-predictor.md"))
    assert "Predictor" in text and "bench run" in text and "bench check" in text


def test_offline_scoring_runs_queries_score_and_export() -> None:
    text = "\n".join(src for _, src in executable_blocks(DOCS / "guides/offline-scoring.md"))
    for command in ("bench queries", "bench score", "bench export"):
        assert command in text, f"guides/offline-scoring.md runs no `{command}`"


def test_some_page_loads_a_run_in_python() -> None:
    pages = [
        p
        for p, blocks in all_pages().items()
        if any(lang == "python" and "posbench.load(" in src for lang, src in blocks)
    ]
    assert pages, "no executable python block in docs/ calls posbench.load(...)"
