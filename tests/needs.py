"""What a test needs from the machine (data, a tool, a browser): where it is missing the test
is skipped on a developer's machine and fails where ``CI`` is set (``.ci/run`` installs
everything, so there every test must run)."""

from __future__ import annotations

import os
import shutil
from typing import NoReturn

import pytest

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
    """Skip the test for want of ``what``, or fail it when ``CI`` is set."""
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
