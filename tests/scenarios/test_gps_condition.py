"""Which fixes a drive is fed and scored on: the recording's own receiver wherever its fixes
and its truth come from different sources, fixes simulated from the truth only where the
fixes *are* the truth (KITTI's OXTS, the synthetic drives) or when asked (issue 28)."""

from __future__ import annotations

import json
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import bench

from posbench.config import GPS_CONDITIONS, RunConfig, gps_condition
from posbench.replay.prepare import prepare_drive
from posbench.scenarios.corpus import corpus_drive
from posbench.scenarios.drive import (
    FIXES_FROM_TRUTH,
    Drive,
    DriveMeta,
    GpsStream,
    TruthStream,
)
from posbench.scenarios.synthetic import generate_drive


def _drive(
    fixes: str = "receiver", offset_m: float = 3.0, with_truth: bool = True, n_fix: int = 300
) -> Drive:
    """A 60 s straight drive at 10 m/s: truth at 100 Hz, fixes at 5 Hz ``offset_m`` north
    of it (a receiver of its own) or on it."""
    t = np.arange(0.0, 60.0, 0.01)
    truth = TruthStream(t, 10.0 * t, np.zeros_like(t), yaw=np.zeros_like(t), v=np.full_like(t, 10))
    tf = np.arange(n_fix) * 0.2
    gps = GpsStream(tf, 10.0 * tf, np.full_like(tf, offset_m), accuracy=np.full_like(tf, 8.0))
    meta = DriveMeta(name="d", source="test", format="table", fix_source=fixes)
    return Drive(meta, gps, truth=truth if with_truth else None)


@pytest.mark.parametrize(
    ("drive", "expected"),
    [
        (_drive(), "native"),  # a receiver beside an INS truth: scored as it is
        (_drive(with_truth=False), "native"),  # no truth: its own fixes, always
        (_drive(fixes=FIXES_FROM_TRUTH), "rtk"),  # KITTI: the fixes are the truth
        (_drive(offset_m=0.0), "rtk"),  # fixes lying on the truth are no receiver of their own
        (_drive(n_fix=0), "rtk"),  # a truth without fixes: fixes must be drawn
    ],
)
def test_auto_condition_per_drive(drive, expected):
    assert gps_condition(RunConfig(), drive) == expected


def test_synthetic_drives_keep_simulated_fixes_by_default():
    """The built-in drives' fixes were simulated from their truth: `bench run` by default
    draws them from the truth as before (its figures unchanged)."""
    for d in (generate_drive(seed=0), corpus_drive(0, "urban", duration_s=60.0)):
        assert d.fixes_from_truth and gps_condition(RunConfig(), d) == "rtk"


@pytest.mark.parametrize("profile", GPS_CONDITIONS)
def test_an_explicit_profile_holds_for_every_drive_with_truth(profile):
    for d in (_drive(), _drive(fixes=FIXES_FROM_TRUTH)):
        assert gps_condition(RunConfig(gps_profile=profile), d) == profile
    assert gps_condition(RunConfig(gps_profile=profile), _drive(with_truth=False)) == "native"


def test_prepared_drive_feeds_the_recorded_fixes_and_says_so():
    d = _drive()
    prep = prepare_drive(d, RunConfig())
    assert prep.gps_condition == "native"
    np.testing.assert_array_equal(prep.gps.y, d.gps.y)  # the receiver's 3 m offset kept
    assert prep.notes[0] == "GPS: the recording's own receiver"
    sim = prepare_drive(d, RunConfig(gps_profile="rtk"))
    assert sim.gps_condition == "rtk" and np.abs(sim.gps.y).max() < 0.5
    assert sim.notes[0].startswith("GPS: simulated `rtk` fixes drawn from the truth")


def test_native_on_a_truth_without_fixes_draws_them():
    d = _drive(n_fix=0)
    assert gps_condition(RunConfig(gps_profile="native"), d) == "rtk"
    assert len(prepare_drive(d, RunConfig(gps_profile="native")).gps) > 0


def _csv(path, offset_m: float = 3.0) -> None:
    """The issue's case in small: a CSV with the receiver's fixes (stating 8 m) and a truth."""
    d = _drive(offset_m=offset_m)
    rows = [
        pd.DataFrame({"stream": "truth", "t": d.truth.t, "x": d.truth.x, "y": d.truth.y}),
        pd.DataFrame(
            {"stream": "gps", "t": d.gps.t, "x": d.gps.x, "y": d.gps.y, "accuracy": d.gps.accuracy}
        ),
    ]
    pd.concat(rows).sort_values("t", kind="stable").to_csv(path, index=False)


def _run_cv(csv: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """``bench run --data CSV -p cv --out OUT`` with one worker and no figures (the tests
    here read results.json and report.md), plus ``extra``; output piped (no terminal)."""
    return bench(
        "run",
        "--data",
        str(csv),
        "-p",
        "cv",
        "--out",
        str(out),
        "--workers",
        "1",
        "--plot-format",
        "none",
        *extra,
        columns=None,
    )


@pytest.mark.slow
def test_bench_run_scores_the_users_receiver_by_default(tmp_path):
    csv = tmp_path / "canyon.csv"
    _csv(csv)
    out = tmp_path / "o"
    r = _run_cv(csv, out)
    assert r.returncode == 0, r.stderr
    assert (
        "reference in table: the truth, the file's truth rows (errors in true metres); fixes "
        "scored: the recording's own receiver" in " ".join(r.stdout.split())
    )
    res = json.loads((out / "results.json").read_text())
    drive = res["drives"][0]
    assert drive["gps_condition"] == "native" and drive["gps_fed"] == 300
    assert res["config"]["gps_profile"] == "auto"
    # the receiver sits 3 m off the truth: its errors say so (simulated rtk would give cm)
    assert res["predictors"]["cv"]["future"]["mean_m"] > 2.5
    md = (out / "report.md").read_text()
    assert (
        "- Reference in `table`: the truth, the file's truth rows (errors in true metres); "
        "fixes scored: the recording's own receiver." in md
    )
    assert "fixes: the recording's own receiver." in md

    out2 = tmp_path / "o2"
    r = _run_cv(csv, out2, "--gps-profile", "rtk", "-q")
    assert r.returncode == 0, r.stderr
    res2 = json.loads((out2 / "results.json").read_text())
    assert res2["drives"][0]["gps_condition"] == "rtk"
    assert res2["predictors"]["cv"]["future"]["mean_m"] < 0.5
    assert "simulated `rtk` fixes drawn from the truth" in (out2 / "report.md").read_text()


def test_reports_of_older_runs_name_their_fixes():
    """A results.json before schema 1.6 holds no gps_condition: it is inferred from the
    run's profile and the drive's reference."""
    from posbench.report.notes import fixes_scored

    res = {
        "config": {"gps_profile": "consumer"},
        "drives": [
            {"name": "a", "dataset": "kitti", "reference": "truth", "skipped": None},
            {"name": "b", "dataset": "aslan", "reference": "cubic", "skipped": None},
        ],
    }
    assert fixes_scored(res) == {
        "kitti": "simulated `consumer` fixes drawn from the truth",
        "aslan": "the recording's own receiver",
    }
    mixed = replace_drives(
        res, [{"name": "c", "dataset": "kitti", "reference": "cubic", "skipped": None}]
    )
    assert fixes_scored(mixed)["kitti"] == (
        "the recording's own receiver (1 drive); simulated `consumer` fixes drawn from the "
        "truth (1 drive)"
    )


def replace_drives(res: dict, more: list[dict]) -> dict:
    return {**res, "drives": res["drives"] + more}


def test_meta_default_is_a_receiver():
    meta = DriveMeta(name="x", source="s", format="f")
    assert meta.fix_source == "receiver"
    assert not replace(_drive(), meta=meta).fixes_from_truth


@pytest.mark.slow
def test_urban_canyon_csv_is_scored_on_its_receiver_without_blaming_the_truth(tmp_path):
    """The issue's drive in small: a receiver stating 8 m and ~11 m off (multipath) beside a
    GNSS/INS truth, as a CSV. `bench run` scores the recorded fixes, and the data check calls
    the receiver poor (a gps warning) instead of failing the truth."""
    from test_consistency_truth import urban_canyon_drive

    from posbench.scenarios.loaders.table import write_table

    csv = tmp_path / "canyon.csv"
    d = urban_canyon_drive()
    write_table(d, csv)
    out = tmp_path / "o"
    r = _run_cv(csv, out)
    assert r.returncode == 0, r.stderr
    assert "FAIL" not in r.stdout + r.stderr and "poor receiver" in r.stdout + r.stderr
    res = json.loads((out / "results.json").read_text())
    assert res["drives"][0]["gps_condition"] == "native"
    assert res["drives"][0]["gps_fed"] == len(d.gps)
    checks = res["consistency"]["drives"]["canyon"]
    assert checks["truth"]["verdict"] != "fail" and checks["gps"]["verdict"] == "warn"
    assert not res["consistency"]["affected_predictors"]
