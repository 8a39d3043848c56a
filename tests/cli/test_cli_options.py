"""The command line behaves like the tools people know: one value per option, repeatable,
positional paths never taken for an option's value, -q/-v, --config FILE.toml and
--print-config, and last release's spellings still working for one release with a notice."""

from __future__ import annotations

import json
import subprocess
import tomllib
from pathlib import Path

import pytest
from helpers import bench as run_bench
from ros_synth import SynthBag, write_bag


def bench(
    *args: object, cwd: Path | None = None, columns: int = 200, process: bool = False
) -> subprocess.CompletedProcess:
    """``bench ARGS`` at a terminal ``columns`` wide, in this process unless ``process``."""
    return run_bench(*args, cwd=cwd, columns=columns, process=process)


def ok(r: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert r.returncode == 0, r.stdout + r.stderr
    return r


def config_of(out: Path) -> dict:
    return json.loads((out / "results.json").read_text())["config"]


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return write_bag(tmp_path_factory.mktemp("bag") / "robot", SynthBag(duration_s=30.0))


def test_a_topic_never_takes_the_path_after_it(bag: Path):
    """`bench data inspect --topic gps=/fix BAG`: BAG is the recording, not a topic."""
    r = ok(bench("data", "inspect", "--topic", "gps=/fix", bag, "--json"))
    assert json.loads(r.stdout)[0]["name"] == bag.stem
    assert "ROLE=VALUE" not in r.stderr and "deprecated" not in r.stderr
    r = ok(bench("data", "inspect", "--topic", "gps=/fix", "--topic", "imu=/imu", bag, "--json"))
    assert json.loads(r.stdout)[0]["gps_count"] > 0


def test_a_model_never_takes_the_predictor_after_it():
    r = bench("check", "--model", "cv=somewhere", "cv")
    assert r.returncode == 2 and "ROLE=VALUE" not in r.stderr
    assert r.stderr.startswith("error: --model cv=somewhere: predictor cv has no option 'model'"), (
        r.stderr
    )  # cv was read as the predictor to check


@pytest.mark.slow
def test_predictors_repeat_or_split_on_commas(tmp_path: Path):
    ok(
        bench(
            "run",
            "-p",
            "kf",
            "-p",
            "cv,poly",
            "--workers",
            "1",
            "--plot-format",
            "none",
            "--synthetic-duration",
            "30",
            "--out",
            tmp_path / "a",
            "-q",
        )
    )
    assert config_of(tmp_path / "a")["predictors"] == ["kf", "cv", "poly"]
    r = bench("run", "-p", "kf", "-p", "kf", "--out", tmp_path / "b")
    assert r.returncode == 2 and "lists kf more than once" in r.stderr


@pytest.mark.slow
def test_quiet_and_verbose(tmp_path: Path):
    args = (
        "run",
        "-p",
        "cv",
        "--workers",
        "1",
        "--plot-format",
        "none",
        "--synthetic-duration",
        "30",
    )
    quiet = ok(bench(*args, "--out", tmp_path / "q", "-q"))
    assert quiet.stdout == "" and quiet.stderr == ""
    assert (tmp_path / "q" / "report.md").is_file()
    loud = ok(bench(*args, "--out", tmp_path / "v", "--verbose"))
    assert "synthetic-mixed-s0 done (1/1" in loud.stdout and "wrote " in loud.stdout
    normal = ok(bench(*args, "--out", tmp_path / "n"))
    assert "done (1/1" not in normal.stdout and "wrote " in normal.stdout
    both = bench(*args, "-q", "-v")
    assert both.returncode == 2 and "-q and -v together" in both.stderr
    assert len(both.stderr.strip().splitlines()) == 1
    assert ok(bench("predictors", "-q")).stdout.count("kf") >= 1  # the asked-for table stays


@pytest.mark.slow
def test_config_file_gives_defaults_the_command_line_overrides(tmp_path: Path):
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        '[run]\npredictors = ["cv"]\nworkers = 1\nplot-format = "none"\n'
        'synthetic_duration = 30.0\ngps-profile = "consumer"\ngate = false\n'
    )
    ok(bench("run", "--config", cfg, "--out", tmp_path / "a", "-q"))
    c = config_of(tmp_path / "a")
    assert c["predictors"] == ["cv"] and c["gps_profile"] == "consumer" and c["gate"] is False
    ok(bench("run", "-c", cfg, "-p", "kf", "--gate", "--out", tmp_path / "b", "-q"))
    c = config_of(tmp_path / "b")
    assert c["predictors"] == ["kf"] and c["gps_profile"] == "consumer" and c["gate"] is True


def test_config_file_mistakes_are_one_line(tmp_path: Path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[run]\nhorizon_secs = 0.2\n")
    r = bench("run", "--config", bad)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert f"{bad}: [run] has no option 'horizon_secs'" in lines[0] and "horizon" in lines[0]
    broken = tmp_path / "broken.toml"
    broken.write_text("[run\n")
    r = bench("run", "--config", broken)
    assert r.returncode == 2 and "not TOML" in r.stderr and len(r.stderr.splitlines()) == 1
    r = bench("compare", "x", "--config", tmp_path / "missing.toml")
    assert r.returncode == 2 and "missing.toml: no such file" in r.stderr


def test_print_config_round_trips(tmp_path: Path):
    r = ok(
        bench(
            "run",
            "-p",
            "cv,kf",
            "--data",
            tmp_path,
            "--gps-profile",
            "consumer",
            "--set",
            "kf.jerk_psd=4",
            "--topic",
            "gps=/fix",
            "--no-gate",
            "--print-config",
            cwd=tmp_path,
        )
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # printed, nothing run
    table = tomllib.loads(r.stdout)["run"]
    assert table["predictors"] == ["cv,kf"] and table["data"] == [str(tmp_path)]
    assert table["gps-profile"] == "consumer" and table["set"] == ["kf.jerk_psd=4"]
    assert table["topic"] == ["gps=/fix"] and table["gate"] is False
    assert "print-config" not in table and "quiet" not in table
    saved = tmp_path / "run.toml"  # written after the check above
    saved.write_text(r.stdout)
    again = ok(bench("run", "--config", saved, "--print-config"))
    assert again.stdout == r.stdout


def test_inspect_reads_its_own_table(tmp_path: Path, bag: Path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[data.inspect]\ntopic = ["gps=/fix"]\n')
    r = ok(bench("data", "inspect", bag, "--config", cfg, "--json"))
    assert json.loads(r.stdout)[0]["gps_count"] > 0


# ------------------------------------------------------------- last release's spellings
def _notice(r: subprocess.CompletedProcess, *words: str) -> None:
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    assert len(lines) == 1, r.stderr
    assert "deprecated" in lines[0] and all(w in lines[0] for w in words), lines[0]


@pytest.mark.slow
def test_old_spellings_work_for_one_release_with_a_notice(tmp_path: Path, bag: Path):
    base = ("--workers", "1", "--plot-format", "none", "-p", "cv")
    r = ok(
        bench(
            "run", "--data", bag, bag, "--topic", "gps=/fix", *base, "--out", tmp_path / "a", "-q"
        )
    )
    _notice(r, "--data")
    res = json.loads((tmp_path / "a" / "results.json").read_text())
    assert len(res["data"]) + len(res["data_duplicates"]) == 2  # both paths read, bag once
    r = ok(
        bench(
            "run",
            "--synthetic-duration",
            "30",
            *base,
            "--format",
            "md",
            "--out",
            tmp_path / "b",
            "-q",
        )
    )
    _notice(r, "--format", "--table-format")
    assert not (tmp_path / "b" / "tables").exists()
    r = ok(
        bench(
            "run",
            "--synthetic-duration",
            "30",
            *base,
            "--set",
            "cv.fix_sigma=0.1",
            "cv.accel_sigma=1",
            "--out",
            tmp_path / "c",
            "-q",
        )
    )
    _notice(r, "--set")
    assert config_of(tmp_path / "c")["predictor_options"]["cv"] == {
        "fix_sigma": 0.1,
        "accel_sigma": 1,
    }
    r = ok(
        bench(
            "queries",
            "--synthetic-duration",
            "30",
            "--format",
            "parquet",
            "--out",
            tmp_path / "q",
            "-q",
        )
    )
    _notice(r, "--format", "--file-format")
    assert (tmp_path / "q" / "queries.parquet").is_file()
    r = bench("train", "--model", "gru")
    _notice(r, "--model", "--network")
    assert r.returncode == 2 and "error: --network 'gru'" in r.stderr
    r = ok(bench("compare", tmp_path / "b", tmp_path / "b", "--format", "csv", "--seed", "3"))
    assert r.stdout.startswith("scope,") and r.stderr.count("deprecated") == 2


def test_a_plugin_written_for_the_old_layout_is_told_the_new_name(tmp_path: Path):
    (tmp_path / "oldplug.py").write_text(
        "from predictors.base import Predictor\n\n\nclass Mine(Predictor):\n    pass\n"
    )
    # a new process: the plugin's import path is what is tested (here, tests/ is on sys.path
    # and its predictors/ folder would answer `import predictors`)
    r = bench("predictors", "oldplug:Mine", cwd=tmp_path, process=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "import posbench.predictors instead of predictors" in r.stderr
