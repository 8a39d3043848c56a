"""A run records what it did: an option that cannot apply to any drive is one error line;
one that misses some drives is one note per option, and results.json counts the drives by
the GPS condition actually fed and scored (issue 49, part 3)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench


def _csv(path: Path, truth: bool, seconds: float = 40.0) -> Path:
    """A straight 10 m/s drive: fixes at 5 Hz, IMU at 50 Hz, a truth at 20 Hz if asked."""
    rows = ["stream,t,x,y,ax,ay"]
    for t in np.arange(0.0, seconds, 0.2):
        rows.append(f"gps,{t:.3f},{10 * t:.3f},{0.01 * np.sin(t):.4f},,")
    for t in np.arange(0.0, seconds, 0.02):
        rows.append(f"imu,{t:.3f},,,0.0,0.0")
    if truth:
        for t in np.arange(0.0, seconds, 0.05):
            rows.append(f"truth,{t:.3f},{10 * t:.3f},0.0,,")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("profile", ["consumer", "rtk", "none"])
def test_a_drawn_profile_on_a_drive_without_truth_is_refused(tmp_path, profile):
    data = _csv(tmp_path / "bag.csv", truth=False)
    r = bench(
        "run",
        "--data",
        data,
        "-p",
        "cv",
        "--gps-profile",
        profile,
        "--out",
        tmp_path / "o",
        cwd=tmp_path,
    )
    assert_one_error_line(
        r, f"--gps-profile {profile} draws fixes from each drive's truth", "holds fixes and IMU"
    )
    assert not (tmp_path / "o").exists()


def test_latency_on_own_fixes_only_is_refused(tmp_path):
    data = _csv(tmp_path / "bag.csv", truth=False)
    r = bench("run", "--data", data, "-p", "cv", "--gps-latency", "0.1", cwd=tmp_path)
    assert_one_error_line(r, "--gps-latency 0.1 delays fixes drawn from a truth")


def test_a_mixed_run_notes_the_drives_missed_and_records_what_was_scored(tmp_path):
    folder = tmp_path / "data"
    folder.mkdir()
    _csv(folder / "with_truth.csv", truth=True)
    _csv(folder / "own_only.csv", truth=False)
    out = tmp_path / "o"
    r = bench(
        "run",
        "--data",
        folder,
        "-p",
        "cv",
        "--gps-profile",
        "consumer",
        "--out",
        out,
        "--plot-format",
        "none",
        cwd=tmp_path,
        columns=200,
    )
    assert r.returncode == 0, r.stderr
    notes = [ln for ln in (r.stdout + r.stderr).splitlines() if ln.startswith("note: --gps")]
    assert len(notes) == 1, r.stdout + r.stderr
    assert "1 drive without a truth (own_only)" in notes[0] and "(native)" in notes[0]
    res = json.loads((out / "results.json").read_text())
    assert res["config"]["gps_profile"] == "consumer"  # what was asked, as asked
    assert res["gps_conditions"] == {"consumer": 1, "native": 1}  # what was scored
    assert res["unhonoured"] == [notes[0].removeprefix("note: ")]
    by_drive = {d["name"]: d["gps_condition"] for d in res["drives"]}
    assert by_drive == {"with_truth": "consumer", "own_only": "native"}


def test_the_default_run_records_its_conditions_and_no_notes():
    import posbench

    run = posbench.run(predictors="cv", synthetic_duration_s=30, out=None)
    assert run.results["gps_conditions"] == {"rtk": 1}
    assert "unhonoured" not in run.results


def test_latency_that_misses_some_drives_is_one_note(tmp_path):
    folder = tmp_path / "data"
    folder.mkdir()
    _csv(folder / "with_truth.csv", truth=True)
    _csv(folder / "own_only.csv", truth=False)
    r = bench(
        "run",
        "--data",
        folder,
        "-p",
        "cv",
        "--gps-profile",
        "rtk",
        "--gps-latency",
        "0.1",
        "--out",
        tmp_path / "o",
        "--plot-format",
        "none",
        cwd=tmp_path,
        columns=200,
    )
    assert r.returncode == 0, r.stderr
    notes = [ln for ln in (r.stdout + r.stderr).splitlines() if ln.startswith("note: --gps-lat")]
    assert notes == [
        "note: --gps-latency 0.1: 1 drive fed their own receiver's fixes (own_only) "
        "without the latency"
    ]
