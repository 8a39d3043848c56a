"""Fixtures every test folder shares (what tests share besides fixtures is in
:mod:`helpers`). Tests that need ``../shared`` use :func:`shared_dir`: they skip on a machine
without it, but fail when the ``CI`` environment variable is set."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

# A pytest-xdist worker starts with COLUMNS=80 and LINES=24 in its environment whatever the
# command's own were; the tests read COLUMNS as a user's terminal sets it, so each worker
# takes the values the controller started with (before anything builds a console from them).
_TERMINAL = ("COLUMNS", "LINES")
if "PYTEST_XDIST_WORKER" in os.environ:
    for _name in _TERMINAL:
        _value = os.environ.get(f"POSBENCH_TESTS_{_name}", "")
        if _value:
            os.environ[_name] = _value
        else:
            os.environ.pop(_name, None)
else:
    for _name in _TERMINAL:
        os.environ[f"POSBENCH_TESTS_{_name}"] = os.environ.get(_name, "")

import pytest  # noqa: E402
from helpers import ROOT, bench, chromium_executable, missing  # noqa: E402

SHARED = ROOT.parent / "shared"


def _need(path: Path) -> Path:
    if not path.exists():
        missing(f"shared data not found at {path}")
    return path


@pytest.fixture(scope="session")
def cv_kf_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``bench run -p cv,kf --plot-format none`` on the built-in drives, once per session: a
    saved run folder (no figures) that tests read (copy it before changing anything in it)."""
    out = tmp_path_factory.mktemp("cv-kf-run") / "old"
    r = bench("run", "-p", "cv,kf", "--out", str(out), "--plot-format", "none", timeout=300)
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="session")
def default_run(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[subprocess.CompletedProcess[str], dict, Path]:
    """``bench run`` as it comes: no option but --out, at a terminal 100 columns wide (as
    issue 49 measures its first screen), once per session: what it printed, its results.json
    and its folder (copy it before changing anything in it). The first screen's tests read
    what it printed, the golden test, the default report's and the paper figures' its files."""
    out = tmp_path_factory.mktemp("default-run") / "o"
    r = bench("run", "--out", out, columns=100)
    assert r.returncode == 0, r.stderr
    return r, json.loads((out / "results.json").read_text()), out


@pytest.fixture(scope="session")
def chromium() -> str:
    """The system Chromium's executable, for the browser tests
    (:func:`helpers.chromium_executable`)."""
    return chromium_executable()


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` relative to the project root."""
    return _need(SHARED)


@pytest.fixture(scope="session")
def kitti_dir(shared_dir: Path) -> Path:
    return _need(shared_dir / "data" / "kitti_raw")


@pytest.fixture(scope="session")
def comma_dir(shared_dir: Path) -> Path:
    return _need(shared_dir / "data" / "comma2k19")


@pytest.fixture(scope="session")
def aslan_dir(shared_dir: Path) -> Path:
    return _need(shared_dir / "data" / "aslan")


@pytest.fixture(scope="session")
def filter_parity_drives(aslan_dir: Path, kitti_dir: Path, comma_dir: Path) -> list:
    """One drive of each shared data set, loaded once for the filters' reference tests:
    aslan (IMU, no speed), KITTI (IMU with yaw, speed, stated accuracy), comma2k19 (IMU
    without yaw, CAN speed). Read only: a test must not change them."""
    from posbench.scenarios.loaders import load

    return [
        load(aslan_dir / "aslan-20220409115940.pickle")[0],
        load(kitti_dir / "2011_09_26" / "2011_09_26_drive_0005_sync")[0],
        load(comma_dir)[0],
    ]


@pytest.fixture(scope="session")
def authors_models_dir(shared_dir: Path) -> Path:
    return _need(shared_dir / "models" / "authors")
