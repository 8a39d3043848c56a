"""The command line: one-line errors with exit status 2 for user mistakes, inspect, run."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
from pathlib import Path

import pytest
from helpers import bench as run_bench


def bench(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``bench ARGS`` in this process, tables printed 200 characters wide."""
    return run_bench(*args, cwd=cwd, columns=200)


def assert_user_error(r: subprocess.CompletedProcess, *needles: str) -> None:
    assert r.returncode == 2, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout
    err = r.stderr.strip()
    assert err.startswith("error:"), err
    for n in needles:
        assert n in err, err


def test_missing_path(tmp_path):
    missing = tmp_path / "nope.bag"
    assert_user_error(bench("data", "inspect", str(missing)), str(missing), "no such file")
    assert_user_error(bench("run", "--data", str(missing), "-p", "cv"), str(missing))


def test_unknown_format(tmp_path):
    f = tmp_path / "drive.xyz"
    f.write_text("hello")
    assert_user_error(bench("data", "inspect", str(f)), str(f), "unknown format")


def test_unknown_predictor():
    assert_user_error(bench("run", "-p", "cv,magic"), "magic", "known:")


def test_lstm_authors_needs_model():
    assert_user_error(bench("run", "-p", "lstm-authors"), "--model lstm-authors=")


class Evil:
    def __reduce__(self):
        return (os.system, ("touch pwned-marker",))


def test_malicious_pickle_refused_and_not_run(tmp_path):
    f = tmp_path / "route.pickle"
    f.write_bytes(pickle.dumps(Evil()))
    r = bench("data", "inspect", str(f), cwd=tmp_path)
    assert_user_error(r, str(f), "refused to unpickle", "system")
    assert not (tmp_path / "pwned-marker").exists()


def test_truncated_csv(tmp_path):
    f = tmp_path / "drive.csv"
    f.write_text('stream,t,x,y\ngps,0.0,0,0\ngps,0.2,"1,\n')
    assert_user_error(bench("data", "inspect", str(f)), str(f))


def test_bad_topic_syntax(tmp_path):
    assert_user_error(bench("data", "inspect", "--topic", "gps", str(tmp_path)), "--topic")


def test_inspect_default_json():
    r = bench("data", "inspect", "--json")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert len(rows) >= 4 and all(row["format"] == "synthetic" and row["has_truth"] for row in rows)
    assert {"name", "format", "duration_s", "gps_count", "has_truth"} <= set(rows[0])
    shares = {row["name"]: row["label_shares"] for row in rows}
    for sh in shares.values():
        assert sum(sh.values()) == pytest.approx(1.0)
    assert shares["synthetic-roundabout-s0"]["roundabout"] > 0.3
    assert shares["synthetic-stop_and_go-s0"]["start_stop"] > 0.3


@pytest.mark.slow
@pytest.mark.shared
def test_inspect_all_shared_drives(kitti_dir, comma_dir, aslan_dir):
    r = bench("data", "inspect", str(kitti_dir), str(comma_dir), str(aslan_dir), "--json")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    fmts = [row["format"] for row in rows]
    assert (fmts.count("kitti"), fmts.count("comma2k19"), fmts.count("aslan")) == (46, 1, 15)
    for row in rows:
        assert row["duration_s"] > 5 and row["gps_count"] > 50
        assert 50 <= row["gps_interval_ms"]["p50"] <= 300


@pytest.mark.slow
def test_run_default_writes_report(default_run):
    """`bench run` as it comes (tests/conftest.py: all default predictors, two workers)."""
    _, res, out = default_run
    for name in ("cv", "kf", "lstm"):
        f = res["predictors"][name]["future"]
        assert f["count"] > 1000 and 0 < f["mean_m"] < 0.5
        assert res["predictors"][name]["latency_us"]["p50"] > 0
    assert res["config"]["gps_profile"] == "auto"  # synthetic fixes: drawn from the truth
    assert {d["gps_condition"] for d in res["drives"]} == {"rtk"}
    report = (out / "report.md").read_text()
    assert "Route type (paper's Table I layout)" in report
    for png in ("error_cdf.png", "error_vs_speed.png", "path.png"):
        assert (out / png).stat().st_size > 10_000
    assert (out / "traces.parquet").exists()


@pytest.mark.slow
def test_run_with_lstm_writes_paper_figures(default_run):
    """The paper's figures need kf-paper and lstm: the default run has both."""
    _, res, out = default_run
    assert {"kf-paper", "lstm"} <= set(res["config"]["predictors"])
    files = [f["file"] for f in res["paper_figures"]]
    assert files == [
        "paper_fig_prediction.png",
        "paper_fig_current_position.png",
        "paper_fig_path.png",
        "paper_fig_kalman.png",
    ]
    for f in res["paper_figures"]:
        assert (out / f["file"]).stat().st_size > 10_000
        assert "drive `synthetic-" in f["caption"] and "t = " in f["caption"]
    assert "The paper's figures, from this run" in (out / "report.md").read_text()


def test_installed_package_ships_tuned_parameters_and_model():
    from posbench.predictors.lstm.predictor import bundled_model
    from posbench.predictors.registry import tuned_params

    assert tuned_params("kf", "rtk") and tuned_params("ekf", "native")
    assert bundled_model().is_file() and bundled_model().with_suffix(".json").is_file()


@pytest.mark.slow
def test_latency_json_shape():
    r = bench("latency", "-p", "cv,lstm", "--steps", "200", "--rounds", "2", "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    cv_rounds, lstm_rounds = res["cv"]["step_p50_rounds"], res["lstm"]["step_p50_rounds"]
    assert len(cv_rounds) == len(lstm_rounds) == 2  # timed in turn, twice
    assert res["cv"]["step_us"]["p50"] == min(cv_rounds)  # the lowest of the rounds
    ratios = sorted(a / b for a, b in zip(lstm_rounds, cv_rounds, strict=True))
    assert res["ratio_to_cv"]["lstm"]["step_p50"] == pytest.approx(sum(ratios) / 2)
    for name in ("cv", "lstm"):
        assert {"p50", "p99"} <= set(res[name]["step_us"]) and {"p50", "p99"} <= set(
            res[name]["query_us"]
        )
        assert 0 < res[name]["step_us"]["p50"] <= res[name]["step_us"]["p99"]
    assert {
        "resample_positions",
        "resample_imu",
        "features",
        "inference",
        "current_position_fit",
        "cubic_fit_lbfgs",
    } <= set(res["lstm_stages"])
    assert (
        res["lstm_stages"]["cubic_fit_lbfgs"]["p50"]
        > res["lstm_stages"]["cubic_fit_closed_form"]["p50"]
    )
    assert list(res["lstm_fused_stages"]) == [
        "resample",
        "features",
        "inference",
        "current_position_fit",
    ]
    assert set(res["batch"]) == {"1", "64", "1024"}


@pytest.mark.slow
def test_run_writes_rerun_recording(tmp_path):
    rrd = tmp_path / "run.rrd"
    r = bench(
        "run", "-p", "cv", "--out", str(tmp_path / "o"), "--rerun", str(rrd), "--workers", "1"
    )
    assert r.returncode == 0, r.stderr
    assert rrd.stat().st_size > 10_000
    assert "bench view" in r.stdout


@pytest.mark.slow
def test_train_command_writes_a_usable_model(tmp_path):
    out = tmp_path / "m"
    r = bench("train", "--synthetic", "2", "--epochs", "1", "--out", str(out))
    assert r.returncode == 0, r.stderr
    info = json.loads((out / "model.json").read_text())
    assert info["command"].startswith("bench train") and "--synthetic 2" in info["command"]
    r = bench(
        "run",
        "-p",
        "lstm",
        "--model",
        f"lstm={out / 'model.onnx'}",
        "--out",
        str(tmp_path / "o"),
        "--workers",
        "1",
        "--plot-format",
        "none",
    )
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "o" / "results.json").read_text())
    assert res["predictors"]["lstm"]["future"]["count"] > 1000
    assert res["training_drives"]["lstm"]  # the run knows which drives that model trained on
