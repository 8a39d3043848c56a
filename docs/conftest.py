"""Runs the examples in the documentation pages (docs/**/*.md) under pytest, with sybil.

The convention every page follows:

* fenced ```` ```python ```` blocks run in order, one shared namespace per page (a block
  that starts with ``>>>`` is a doctest);
* fenced ```` ```bash ```` blocks run with ``bash`` as a script under ``set -euo pipefail``,
  with the running interpreter's venv (its ``bench`` and ``python``) first on ``PATH`` and
  the environment (``CI`` included) passed through;
* each page gets one fresh temporary working directory: bash blocks run there and python
  blocks run with it as the current directory (and first on ``sys.path``, as for
  ``python`` started there); the previous directory is restored after each block;
* ``REPO`` (the repository root, a :class:`~pathlib.Path`) is defined in every page's
  Python namespace and exported to its bash blocks, for examples that need repository
  files such as ``reports/``;
* a block preceded by ``<!-- skip: next -->`` is not run (sybil's markdown skip syntax,
  ``<!-- skip: start -->`` ... ``<!-- skip: end -->`` too);
* ```` ```text ````, ```` ```console ```` and every other language are never run;
* a setup step the reader need not see may be an HTML comment
  ``<!-- invisible-code-block: python ... -->`` (sybil's syntax): it runs like a python block.

A failing bash block fails its test with the exit status and the tail of its stdout and
stderr. Python scripts under docs/examples/ are not collected as tests.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from sybil import Example, Sybil
from sybil.parsers.markdown import CodeBlockParser, PythonCodeBlockParser, SkipParser

REPO = Path(__file__).resolve().parents[1]
#: The venv's bin folder (not resolved: a venv's python is a symlink out of the venv).
VENV_BIN = Path(sys.executable).parent
#: Seconds one bash block may run before it fails.
BASH_TIMEOUT_S = 600
#: Characters of stdout and of stderr shown when a bash block fails.
TAIL_CHARS = 3000

_WORKDIR = "__docs_workdir__"

# Helper scripts the pages point to; they are run by hand (or by a page), never as tests.
collect_ignore_glob = ["examples/*.py", "examples/**/*.py"]


def _setup(namespace: dict) -> None:
    namespace["REPO"] = REPO
    namespace[_WORKDIR] = Path(tempfile.mkdtemp(prefix="posbench-docs-"))


def _teardown(namespace: dict) -> None:
    workdir = namespace.get(_WORKDIR)
    if workdir is not None:
        shutil.rmtree(workdir, ignore_errors=True)


def _tail(text: str) -> str:
    text = text.rstrip()
    return text if len(text) <= TAIL_CHARS else "..." + text[-TAIL_CHARS:]


def _bash_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(VENV_BIN), env.get("PATH", "")])
    env["VIRTUAL_ENV"] = str(VENV_BIN.parent)
    env["REPO"] = str(REPO)
    env.setdefault("MPLBACKEND", "Agg")
    return env


def evaluate_bash(example: Example) -> str | None:
    """Run one bash block in the page's working directory; a message when it fails."""
    workdir = example.namespace[_WORKDIR]
    script = "set -euo pipefail\n" + str(example.parsed)
    try:
        done = subprocess.run(
            ["bash", "-c", script],
            cwd=workdir,
            env=_bash_env(),
            capture_output=True,
            text=True,
            timeout=BASH_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired as e:
        out = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        err = e.stderr.decode() if isinstance(e.stderr, bytes) else (e.stderr or "")
        return (
            f"bash block timed out after {BASH_TIMEOUT_S} s\n"
            f"--- stdout (tail) ---\n{_tail(out)}\n--- stderr (tail) ---\n{_tail(err)}"
        )
    if done.returncode != 0:
        return (
            f"bash block exited with status {done.returncode}\n"
            f"--- script ---\n{str(example.parsed).rstrip()}\n"
            f"--- stdout (tail) ---\n{_tail(done.stdout)}\n"
            f"--- stderr (tail) ---\n{_tail(done.stderr)}"
        )
    return None


class _InWorkdir:
    """Wraps a Python (or doctest) evaluator: run it in the page's working directory."""

    def __init__(self, evaluator):
        self.evaluator = evaluator

    def __call__(self, example: Example):
        workdir = str(example.namespace[_WORKDIR])
        before = os.getcwd()
        os.chdir(workdir)
        sys.path.insert(0, workdir)
        try:
            return self.evaluator(example)
        finally:
            os.chdir(before)
            try:
                sys.path.remove(workdir)
            except ValueError:
                pass


class PythonInWorkdirParser(PythonCodeBlockParser):
    """``python`` blocks (and doctests in them), evaluated in the page's working directory."""

    def __call__(self, document):
        for region in super().__call__(document):
            region.evaluator = _InWorkdir(region.evaluator)
            yield region


pytest_collect_file = Sybil(
    parsers=[
        PythonInWorkdirParser(),
        CodeBlockParser(language="bash", evaluator=evaluate_bash),
        SkipParser(),
    ],
    patterns=["*.md"],
    setup=_setup,
    teardown=_teardown,
    name="docs",
).pytest()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every example of the docs is ``slow``: a page's examples run in order in one namespace
    and one working directory (none can be left out alone), and most pages run whole commands,
    seconds each. They run in the full suite; ``pytest -m "not slow"``, the inner loop, runs
    none of them."""
    here = Path(__file__).resolve().parent
    for item in items:
        if item.path.resolve().is_relative_to(here):
            item.add_marker(pytest.mark.slow)
