"""The data consistency check (scenarios/consistency.py, bench/consistency.py): synthetic
drives pass, each planted fault is flagged on its stream with the right figure, every shared
drive is free of failures, and ``--strict`` is one line and exit 2 before anything runs."""

from __future__ import annotations

import json
import pickle
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench

from posbench.pipeline.data_check import affected_predictors, strict_error, to_results, uses_stream
from posbench.predictors.base import Predictor
from posbench.report.data_check import report_lines, table_rows
from posbench.scenarios.align import similarity_2d
from posbench.scenarios.consistency import (
    FAIL,
    NA,
    PASS,
    STREAMS,
    WARN,
    check_drive,
)
from posbench.scenarios.drive import GpsStream, ImuStream, SpeedStream, TruthStream
from posbench.scenarios.synthetic import default_drives, generate_drive


@pytest.fixture(scope="module")
def drive():
    return generate_drive(seed=3, route="mixed")


def with_imu(d, **cols):
    imu = d.imu
    kw = {f: getattr(imu, f) for f in ("t", "ax", "ay", "yaw", "yaw_rate")}
    kw.update(cols)
    return replace(d, imu=ImuStream(**kw))


def test_synthetic_drives_pass():
    for d in default_drives(seed=0):
        res = check_drive(d)
        assert list(res.checks) == list(STREAMS)
        for s, c in res.checks.items():
            assert c.verdict == PASS, (d.name, s, c)


def test_yaw_rate_sign_flip_fails(drive):
    c = check_drive(with_imu(drive, yaw_rate=-drive.imu.yaw_rate)).checks["imu.yaw_rate"]
    assert c.verdict == FAIL
    assert c.reason.startswith("sign -1") and c.figures["sign"] == -1
    assert c.figures["corr"] < -0.9


def test_speed_scale_error_flagged(drive):
    d = replace(drive, speed=SpeedStream(drive.speed.t, 1.3 * drive.speed.v))
    c = check_drive(d).checks["speed"]
    assert c.verdict == FAIL and abs(c.figures["scale"] - 1.3) < 0.03, c
    d = replace(drive, speed=SpeedStream(drive.speed.t, 1.08 * drive.speed.v))
    assert check_drive(d).checks["speed"].verdict == WARN


def test_imu_time_offset_measured(drive):
    d = with_imu(drive, t=drive.imu.t + 0.3)  # IMU stamps 0.3 s late
    c = check_drive(d).checks["imu.yaw_rate"]
    assert abs(c.figures["lag_s"] - 0.3) < 0.05, c.figures
    assert c.verdict == WARN and "time offset" in c.reason
    d = with_imu(drive, t=drive.imu.t - 0.3)
    assert abs(check_drive(d).checks["imu.yaw_rate"].figures["lag_s"] + 0.3) < 0.05


def test_gravity_left_in_ax_flagged(drive):
    c = check_drive(with_imu(drive, ax=drive.imu.ax + 2.0)).checks["imu.ax"]
    assert c.verdict == FAIL and abs(c.figures["bias_mps2"] - 2.0) < 0.15, c
    assert "gravity" in c.reason
    # a sideways mount: gravity on y, ax is then the lateral acceleration
    c = check_drive(with_imu(drive, ax=drive.imu.ay, ay=drive.imu.ax)).checks["imu.ax"]
    assert c.verdict == FAIL, c


def test_yaw_in_another_frame_fails(drive):
    c = check_drive(with_imu(drive, yaw=drive.imu.yaw + np.radians(40))).checks["imu.yaw"]
    assert c.verdict == FAIL and abs(c.figures["offset_deg"] - 40) < 1, c
    c = check_drive(drive).checks["imu.yaw"]
    assert abs(c.figures["offset_deg"]) < 1 and c.figures["spread_deg"] < 3


def test_truth_in_another_frame_fails(drive):
    tr = drive.truth
    a = np.radians(20)
    x = np.cos(a) * tr.x - np.sin(a) * tr.y + 150.0
    y = np.sin(a) * tr.x + np.cos(a) * tr.y
    d = replace(drive, truth=TruthStream(tr.t, x, y, tr.yaw, tr.v))
    c = check_drive(d).checks["truth"]
    assert c.verdict == FAIL and c.figures["offset_m"] > 100
    assert abs(c.figures["rotation_deg"] + 20) < 0.5 and c.figures["fit_rms_m"] < 0.5


def test_similarity_fit_recovers_transform():
    rng = np.random.default_rng(0)
    src = rng.normal(0, 100, (200, 2))
    a = 0.3
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    dst = 1.02 * src @ rot.T + [5.0, -7.0]
    s, ang, t, rms = similarity_2d(src, dst)
    assert abs(s - 1.02) < 1e-9 and abs(ang - a) < 1e-9 and np.allclose(t, [5, -7]) and rms < 1e-9


def test_understated_gps_accuracy_flagged(drive):
    g = drive.gps
    noisy = GpsStream(
        g.t, g.x + np.random.default_rng(1).normal(0, 1.0, len(g)), g.y, g.lat, g.lon, g.accuracy
    )  # 1 m scatter, ~0.08 m stated
    c = check_drive(replace(drive, gps=noisy)).checks["gps"]
    assert c.verdict == FAIL and 0.8 < c.figures["scatter_m"] < 1.3, c


def test_missing_streams_are_na_with_a_reason(drive):
    d = replace(
        drive,
        imu=None,
        speed=None,
        truth=None,
        gps=GpsStream(drive.gps.t, drive.gps.x, drive.gps.y),
    )
    res = check_drive(d)
    for c in res.checks.values():
        assert c.verdict == NA and c.reason
    parked = generate_drive(seed=1, route="stop_and_go").window(0.0, 5.0)
    assert check_drive(parked).checks["imu.yaw_rate"].verdict == NA


def test_uses_stream_follows_overrides():
    class GpsOnly(Predictor):
        def position_at(self, t):
            return (0.0, 0.0)

    class WithImu(GpsOnly):
        def observe_imu(self, t, ax, ay, yaw, yaw_rate):
            pass

    assert not uses_stream(GpsOnly, "imu.ax") and uses_stream(WithImu, "imu.yaw_rate")
    assert not uses_stream(WithImu, "speed") and uses_stream(GpsOnly, "gps")


def test_strict_error_affected_predictors_report(drive):
    bad = with_imu(drive, yaw_rate=-drive.imu.yaw_rate)
    checks = {bad.name: check_drive(bad)}
    err = strict_error(checks)
    assert str(err).startswith(f"--strict: drive {bad.name}: imu.yaw_rate: sign -1 (correlation")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is type(err) and str(back) == str(err)
    assert strict_error({drive.name: check_drive(drive)}) is None
    aff = affected_predictors(["cv", "kf", "ekf"], checks)
    assert set(aff) == {"kf", "ekf"} and aff["kf"] == [f"{bad.name}: imu.yaw_rate"]
    section = json.loads(json.dumps(to_results(checks, ["cv", "kf"])))
    lines = "\n".join(report_lines({"consistency": section}))
    assert "**fail**" in lines and "imu.yaw_rate" in lines and "`kf`" in lines
    header, rows = table_rows(section["drives"])
    assert header[1:7] == list(STREAMS) and rows[0][1].startswith("fail") and rows[0][-1] == FAIL


@pytest.mark.slow
def test_every_shared_drive_has_no_failure(aslan_dir, kitti_dir, comma_dir):
    from posbench.scenarios.loaders import load

    seen, slow = 0, []
    for folder in (aslan_dir, kitti_dir, comma_dir):
        for d in load(folder):
            t0 = time.perf_counter()
            res = check_drive(d)
            dt = time.perf_counter() - t0
            if d.meta.format == "kitti":
                slow.append(dt)
            assert not res.failures(), (d.name, [c.reason for c in res.failures()])
            seen += 1
    assert seen == 15 + 46 + 1
    assert np.median(slow) < 0.05, slow  # KITTI drive: well under 50 ms on this machine


# ---------------------------------------------------------------- command line


@pytest.fixture(scope="module")
def flipped_csv(tmp_path_factory) -> Path:
    from posbench.scenarios.loaders.table import write_table

    d = generate_drive(seed=3, route="mixed", name="flipped")
    d = with_imu(d, yaw_rate=-d.imu.yaw_rate)
    p = tmp_path_factory.mktemp("flip") / "flipped.csv"
    write_table(d, p)
    return p


def test_inspect_strict_is_one_line(flipped_csv):
    r = bench("data", "inspect", str(flipped_csv), "--strict")
    line = assert_one_error_line(r, "--strict: drive flipped: imu.yaw_rate: sign -1")
    assert "correlation -" in line
    assert "imu.yaw_rate" in r.stdout and "fail" in r.stdout  # the table came first


def test_run_strict_fails_before_predictors(flipped_csv, tmp_path):
    out = tmp_path / "out"
    r = bench("run", "--data", str(flipped_csv), "-p", "cv", "--strict", "--out", str(out))
    assert_one_error_line(r, "--strict: drive flipped: imu.yaw_rate: sign -1")
    assert not out.exists()


@pytest.mark.slow
def test_run_without_strict_reports_failure(flipped_csv, tmp_path):
    out = tmp_path / "out"
    r = bench(
        "run",
        "--data",
        str(flipped_csv),
        "-p",
        "cv,kf",
        "--out",
        str(out),
        "--plot-format",
        "none",
        "--table-format",
        "md",
    )
    assert r.returncode == 0, r.stderr
    assert "data check FAIL flipped: imu.yaw_rate: sign -1" in r.stdout
    assert "kf used a failing stream" in r.stdout and "cv used" not in r.stdout
    report = (out / "report.md").read_text()
    assert report.index("## Data consistency check") < report.index("## All drives")
    res = json.loads((out / "results.json").read_text())
    assert int(res["schema_version"].split(".")[1]) >= 2
    assert res["consistency"]["drives"]["flipped"]["imu.yaw_rate"]["verdict"] == FAIL
    assert res["consistency"]["affected_predictors"] == {"kf": ["flipped: imu.yaw_rate"]}
    # a run saved before the check (schema 1.1, no key) still validates and loads
    import jsonschema

    from posbench.saved_run.run import load_run, results_schema

    jsonschema.validate(res, results_schema())
    old = {k: v for k, v in res.items() if k != "consistency"} | {"schema_version": "1.1"}
    jsonschema.validate(old, results_schema())
    (out / "results.json").write_text(json.dumps(old))
    assert load_run(out).results["schema_version"] == "1.1"


def test_inspect_table_synthetic():
    r = bench("data", "inspect", env={"COLUMNS": "250"})
    assert r.returncode == 0, r.stderr
    assert "data consistency" in r.stdout
    for s in STREAMS:
        assert s in r.stdout
    assert r.stdout.count("pass") >= 4 * len(STREAMS)
    js = json.loads(bench("data", "inspect", "--json").stdout)
    assert js[0]["consistency"]["imu.yaw_rate"]["verdict"] == PASS
