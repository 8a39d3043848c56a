"""Tuning on your own drives into your own file (``bench tune --out``, ``bench run
--tuning``); the package's tuning is never written; runs name the tuning each baseline
used and mark its development drives; implausible results (a predictor losing to cv) are
listed under ``sanity``."""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

import pytest
from helpers import ROOT
from helpers import bench as run_bench

from posbench.predictors.registry import TUNED_FILE

HOLD = '''
import math
from posbench.predictors.base import Predictor


class HoldLast(Predictor):
    """A deliberately weak plugin: it holds the last fix."""

    name = "hold"

    def __init__(self):
        self.reset()

    def reset(self):
        self.p = (math.nan, math.nan)

    def observe_gps(self, t, x, y, sigma=None):
        self.p = (x, y)

    def observe_imu(self, t, ax, ay, yaw, yaw_rate):
        pass

    def observe_speed(self, t, v):
        pass

    def position_at(self, t):
        return self.p
'''


def bench(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """``bench ARGS`` in this process, from ``cwd`` (the repository root), output piped."""
    return run_bench(*args, cwd=cwd, columns=None)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.slow
def test_tune_out_round_trip_leaves_the_package_tuning_alone(tmp_path, comma_dir):
    before = sha256(TUNED_FILE)
    mine = tmp_path / "my-tuning.json"
    r = bench(
        "tune",
        "kf",
        "--gps-profile",
        "native",
        "--calibrate-only",
        "--data",
        str(comma_dir),
        "--out",
        str(mine),
        "--workers",
        "1",
    )
    assert r.returncode == 0, r.stderr
    assert sha256(TUNED_FILE) == before
    entry = json.loads(mine.read_text())["kf"]["native"]
    assert entry["params"]["cov_scale"] > 0 and entry["drives"] and "bench tune kf" in entry["how"]
    out = tmp_path / "run"
    r = bench(
        "run",
        "-p",
        "cv,kf",
        "--data",
        str(comma_dir),
        "--gps-profile",
        "native",
        "--tuning",
        str(mine),
        "--out",
        str(out),
        "--workers",
        "1",
        "--plot-format",
        "none",
    )
    assert r.returncode == 0, r.stderr
    assert sha256(TUNED_FILE) == before
    res = json.loads((out / "results.json").read_text())
    t = res["tuning"]["kf"]
    assert t["file"] == str(mine) and t["sha256"] == sha256(mine) and not t["built_in"]
    assert t["conditions"]["native"]["params"] == entry["params"]
    assert res["tuning"]["cv"]["built_in"]  # cv is not in the file: the package's tuning
    # the tuning's drives are marked like a learned model's training drives
    assert res["training_drives"]["kf"] == entry["drives"]
    assert res["drives"][0]["trained_on"] == ["kf"]
    report = (out / "report.md").read_text()
    # each tuning file named once, with its hash and the baselines that use it
    assert f"`{mine}`, sha256 {sha256(mine)[:12]} (`kf`)" in report
    assert "kf was tuned on" in report and "bundled" not in report
    # bench predictors shows the values a run would use
    r = bench("predictors", "kf", "--tuning", str(mine))
    assert r.returncode == 0 and "under GPS condition native" in r.stdout
    assert f"cov_scale={entry['params']['cov_scale']!r}" in r.stdout.replace("\n", "")


def test_tune_refuses_to_write_the_package_tuning(tmp_path):
    r = bench("tune", "cv", "--calibrate-only", "--out", str(TUNED_FILE))
    assert r.returncode == 2 and r.stderr.startswith("error: --out")
    assert "built-in tuning" in r.stderr


def test_a_bad_tuning_file_is_one_error_line(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"kf": {"rtk": {"params": {"nosuch": 1}}}}')
    r = bench("run", "-p", "kf", "--tuning", str(bad), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert r.stderr.startswith(f"error: --tuning {bad}: kf (rtk)") and "nosuch" in r.stderr
    bad.write_text("[1, 2]")
    r = bench("run", "-p", "kf", "--tuning", str(bad), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and r.stderr.startswith("error: --tuning: tuning file")


@pytest.mark.slow
def test_sanity_names_a_plugin_that_loses_to_cv(tmp_path):
    (tmp_path / "hold.py").write_text(HOLD)
    out = tmp_path / "run"
    r = bench(
        "run",
        "-p",
        "cv,kf,hold:HoldLast",
        "--out",
        str(out),
        "--workers",
        "1",
        "--plot-format",
        "none",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    res = json.loads((out / "results.json").read_text())
    losses = res["sanity"]["losses"]
    assert res["sanity"]["checked"] and {x["predictor"] for x in losses} == {"hold:HoldLast"}
    fut = next(x for x in losses if x["kind"] == "future")
    assert fut["dataset"] == "synthetic" and fut["diff_m"] > 0 and fut["ci95"][0] > 0
    assert fut["queries"] == res["predictors"]["cv"]["future"]["count"]
    line = next(x for x in r.stderr.splitlines() if "loses to constant velocity" in x)
    assert line.startswith(
        "warning: hold:HoldLast loses to constant velocity on synthetic: future +"
    )
    assert (
        "hold:HoldLast loses to constant velocity on synthetic" in (out / "report.md").read_text()
    )
