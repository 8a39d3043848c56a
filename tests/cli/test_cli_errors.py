"""Never a traceback: bad invocations of ``bench`` end in one ``error:`` line, exit 2.

Each case runs the real command line (``helpers.bench``: the entry point in this process,
on fresh streams and environment, COLUMNS=80) in a scratch folder and checks: exit status 2,
stderr exactly one non-empty line starting ``error:``, no ``Traceback`` anywhere, and nothing
written (the folder's files are unchanged, no --out folder created). The options are checked
before any drive is loaded, so each call takes a fraction of a second.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import pytest
from helpers import ROOT, assert_one_error_line, bench, snapshot
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st


@pytest.fixture(scope="module")
def ws(tmp_path_factory) -> Path:
    """A scratch folder: an ordinary file, a sub-folder, a non-ONNX 'model' with a valid
    model description beside it."""
    from posbench.predictors.lstm.predictor import bundled_model

    d = tmp_path_factory.mktemp("ws")
    (d / "notes.txt").write_text("not a folder\n")
    (d / "folder").mkdir()
    (d / "bad.onnx").write_text("this is not an ONNX protobuf\n")
    shutil.copy(bundled_model().with_suffix(".json"), d / "bad.json")
    return d


# (id, arguments with {ws} for the scratch folder, text the error line must contain,
#  whether the command takes --workers)
CASES = [
    ("dropouts-typo", "run --dropouts outage", "--dropouts", True),
    ("dropouts-random-1", "run --dropouts random:1.5", "--dropouts", True),
    ("model-missing", "run -p lstm --model lstm={ws}/nope.onnx", "{ws}/nope.onnx", True),
    ("model-not-onnx", "run -p lstm --model lstm={ws}/bad.onnx", "{ws}/bad.onnx", True),
    ("authors-not-onnx", "run -p lstm-authors --model lstm-authors={ws}/bad.onnx", "ONNX", True),
    ("model-not-run", "run -p cv --model lstm={ws}/bad.onnx", "not among", True),
    ("horizon-negative", "run --horizon -1", "--horizon", True),
    ("horizon-zero", "run --horizon 0", "--horizon", True),
    ("horizon-11", "run --horizon 11", "--horizon", True),
    ("horizon-nan", "run --horizon nan", "--horizon", True),
    ("horizon-no-value", "run --horizon", "--horizon", False),
    ("gps-profile", "run --gps-profile x", "--gps-profile", True),
    ("gps-latency", "run --gps-latency -0.1", "--gps-latency", True),
    ("topic-role", "run --topic foo=/x", "--topic", True),
    ("topic-no-equals", "run --topic gps", "--topic", True),
    ("workers-0", "run --workers 0", "--workers", False),
    ("out-is-a-file", "run -p cv --out {ws}/notes.txt", "{ws}/notes.txt", True),
    ("out-under-a-file", "run -p cv --out {ws}/notes.txt/out", "{ws}/notes.txt", True),
    ("rerun-is-a-folder", "run -p cv --rerun {ws}/folder", "--rerun", True),
    (
        "rerun-color-by-not-run",
        "run -p cv,kf --rerun {ws}/x.rrd --rerun-color-by ekf",
        "--rerun-color-by ekf: not among the predictors to run (cv, kf)",
        True,
    ),
    (
        "rerun-color-by-without-rerun",
        "run -p cv --rerun-color-by cv",
        "--rerun-color-by cv: colours the track of a rerun recording; give --rerun",
        True,
    ),
    ("unknown-predictor", "run -p cv,magic", "magic", True),
    ("predictor-twice", "run -p cv,cv", "more than once", True),
    ("unknown-predictor-lists-known", "run -p kf,nope", "known: cv, ekf, hybrid, kf", True),
    ("import-path-no-module", "run -p kf,nosuchmodule:X", "no module named 'nosuchmodule'", True),
    ("import-path-not-a-class", "run -p os:path", "path is not a class", True),
    (
        "import-path-not-a-predictor",
        "run -p collections:OrderedDict",
        "OrderedDict is not a subclass of posbench.predictors.base.Predictor",
        True,
    ),
    ("import-path-no-class", "run -p module:", "expected a registered name or module:Class", True),
    (
        "import-path-no-module-name",
        "run -p :Class",
        "expected a registered name or module:Class",
        True,
    ),
    (
        "set-unknown-option",
        "run -p kf --set kf.nosuch=1",
        "--set kf.nosuch=1: predictor kf has no option 'nosuch'; its options: gps_sigma, ",
        True,
    ),
    ("set-no-option", "run -p kf --set kf=1", "--set kf=1: names no option", True),
    ("set-no-equals", "run -p kf --set kf.jerk_psd", "expected NAME.OPTION=VALUE", True),
    (
        "set-not-in-run",
        "run -p kf --set nope.x=1",
        "--set nope.x=1: nope is not among the predictors to run (kf)",
        True,
    ),
    (
        "set-bad-json-rejected",
        "run -p kf --set kf.jerk_psd=[1,",
        "--set kf.jerk_psd=[1,: '[1,' is not valid JSON (Expecting value at column 4)",
        True,
    ),
    (
        "set-bad-value-of-alias",
        "run -p cv,kf@slow --set kf@slow.gps_sigma=0.1 --set kf@slow.jerk_psd=-1",
        "--set kf@slow.jerk_psd=-1: predictor kf@slow rejects jerk_psd=-1",
        True,
    ),
    ("set-twice", "run -p kf --set kf.jerk_psd=1 --set kf.jerk_psd=2", "set twice", True),
    (
        "set-model-disagrees",
        "run -p lstm --model lstm={ws}/bad.onnx --set lstm.model={ws}/x.onnx",
        "disagree",
        True,
    ),
    (
        "set-model-not-onnx",
        "run -p lstm --set lstm.model={ws}/bad.onnx",
        "--set lstm.model={ws}/bad.onnx: lstm cannot load it",
        True,
    ),
    ("predictors-import-path-bad", "predictors collections:OrderedDict", "not a subclass", False),
    ("unknown-option", "run --bogus", "bench run --help", True),
    ("seed-not-a-number", "run --seed x", "--seed", True),
    ("seed-negative", "run --seed -1", "--seed", True),
    ("seed-and-seeds", "run --seed 1 --seeds 3", "--seed and --seeds", True),
    ("seeds-zero", "run --seeds 0", "--seeds", True),
    ("seeds-not-a-number", "run --seeds x", "--seeds", True),
    ("seeds-twice", "run --seeds 1,1", "more than once", True),
    ("seeds-negative", "run --seeds 0,-1", "--seeds", True),
    ("baseline-not-run", "run -p cv,kf --baseline ekf", "--baseline ekf", True),
    ("baseline-unknown", "run -p cv,kf --baseline magic", "--baseline magic", True),
    ("data-missing", "run --data {ws}/missing.bag", "{ws}/missing.bag", True),
    ("synthetic-duration", "run --synthetic-duration 0.5", "--synthetic-duration", True),
    ("projection", "run --projection utm", "--projection", True),
    ("executor", "run --executor k8s", "--executor", True),
    ("view-missing", "view {ws}/missing.rrd", "{ws}/missing.rrd", False),
    ("tune-predictor", "tune magic", "magic", True),
    ("tune-profile", "tune kf --gps-profile x", "--gps-profile", True),
    ("tune-native-no-data", "tune kf --gps-profile native", "--data", True),
    ("tune-drives-0", "tune kf --drives 0", "--drives", True),
    ("latency-predictor", "latency -p nope", "nope", False),
    ("latency-steps-0", "latency --steps 0", "--steps", False),
    ("latency-rounds-0", "latency --rounds 0", "--rounds", False),
    ("latency-model-missing", "latency -p lstm --model lstm={ws}/nope.onnx", "nope.onnx", False),
    ("train-epochs-0", "train --epochs 0 --synthetic 1", "--epochs", False),
    ("train-out-is-a-file", "train --synthetic 1 --out {ws}/notes.txt", "notes.txt", False),
    ("inspect-topic", "data inspect --topic gps", "--topic", False),
    ("no-such-command", "frobnicate", "frobnicate", False),
]


def _expand(cases: list[tuple[str, str, str, bool]]):
    for cid, args, needle, has_workers in cases:
        for w in (1, 2) if has_workers else (None,):
            yield pytest.param(args, needle, w, id=cid + (f"-w{w}" if w else ""))


@pytest.mark.parametrize(("args", "needle", "workers"), list(_expand(CASES)))
def test_bad_invocation_is_one_error_line(ws, args, needle, workers):
    argv = args.replace("{ws}", str(ws)).split()
    if workers is not None:
        argv += ["--workers", str(workers)]
    if argv[0] == "run" and "--out" not in argv:
        argv += ["--out", str(ws / "out")]
    before = snapshot(ws)
    r = bench(*argv, cwd=ws)
    assert_one_error_line(r, needle.replace("{ws}", str(ws)))
    assert snapshot(ws) == before  # nothing half-written, no --out folder created
    assert r.stdout == ""


def test_data_error_inside_a_worker_is_one_line(tmp_path):
    """Drives that load but fail in the workers' preparation (fixes drawn from a truth of
    one sample): the worker's DataError is the one error line, with 1 worker and with 2."""
    data = tmp_path / "drives"
    data.mkdir()
    for k in (1, 2):
        rows = ["stream,t,x,y"] + [f"gps,{0.2 * i:.1f},{2 * i},0" for i in range(50)]
        (data / f"drive{k}.csv").write_text("\n".join([*rows, "truth,5.0,10,0"]) + "\n")
    for w in ("1", "2"):
        r = bench(
            "run",
            "-p",
            "cv",
            "--data",
            str(data),
            "--workers",
            w,
            "--gps-profile",
            "rtk",
            "--out",
            str(tmp_path / "out"),
            cwd=tmp_path,
        )
        assert_one_error_line(r, "truth: need at least 2 samples")
        assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ view
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the check is for Linux")
def test_view_without_display_says_how_to_open_it_elsewhere(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    rerun = fake_bin / "rerun"  # a viewer that must not be started without a display
    rerun.write_text(f"#!/bin/sh\ntouch {tmp_path / 'viewer-started'}\n")
    rerun.chmod(0o755)
    r = bench(
        "view",
        str(rrd),
        cwd=ROOT,
        env={
            "DISPLAY": None,
            "WAYLAND_DISPLAY": None,
            "PATH": f"{fake_bin}{os.pathsep}{os.environ.get('PATH', '')}",
        },
    )
    line = assert_one_error_line(r, "no display", f"rerun {rrd}", f"bench view {rrd} --web")
    assert "URL" in line
    assert not (tmp_path / "viewer-started").exists()


def test_view_reports_a_failing_viewer_in_one_line(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    rerun = fake_bin / "rerun"
    rerun.write_text(
        "#!/bin/sh\necho 'loading...' >&2\necho 'Failed to open connection to X "
        "server' >&2\nexit 3\n"
    )
    rerun.chmod(0o755)
    r = bench(
        "view",
        str(rrd),
        env={"DISPLAY": ":99", "PATH": f"{fake_bin}{os.pathsep}{os.environ['PATH']}"},
    )
    assert_one_error_line(r, "status 3", str(rrd), "X server")


def test_view_runs_the_viewer_and_exits_0(tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"RRF2")
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    rerun = fake_bin / "rerun"
    rerun.write_text(f'#!/bin/sh\necho "$1" > {tmp_path / "opened"}\n')
    rerun.chmod(0o755)
    r = bench(
        "view",
        str(rrd),
        env={"DISPLAY": ":99", "PATH": f"{fake_bin}{os.pathsep}{os.environ['PATH']}"},
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "opened").read_text().strip() == str(rrd)


def test_no_display_reason_is_pure():
    from posbench.cli.view import no_display_reason

    assert no_display_reason("linux", {}) is not None
    assert no_display_reason("linux", {"DISPLAY": ":0"}) is None
    assert no_display_reason("linux", {"WAYLAND_DISPLAY": "wayland-0"}) is None
    assert no_display_reason("darwin", {}) is None and no_display_reason("win32", {}) is None


# ------------------------------------------------------------ help, version, completion
def test_help_still_works_and_exits_0():
    for cmd in ([], ["run"], ["data", "inspect"], ["view"], ["train"], ["latency"], ["tune"]):
        r = bench(*cmd, "--help")
        assert r.returncode == 0 and r.stderr == "", r.stderr
        assert r.stdout.startswith(f"Usage: bench {' '.join(cmd)}".rstrip()), r.stdout[:80]


def test_no_command_prints_the_help():
    r = bench()
    assert r.returncode == 0 and r.stderr == ""
    assert "Usage: bench" in r.stdout and "run" in r.stdout


def test_version():
    from importlib.metadata import version

    r = bench("--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"posbench {version('posbench-harness')}\n"


def test_shell_completion_is_enabled():
    r = bench("--help")
    assert "--install-completion" in r.stdout and "--show-completion" in r.stdout
    # the shell named, not detected from the parent process (which fails where pytest runs
    # without a shell above it, e.g. started in the background): typer's switch for that
    r = bench(
        "--show-completion", "bash", env={"_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION": "1"}
    )
    assert r.returncode == 0 and "_BENCH_COMPLETE" in r.stdout
    r = bench(
        env={"_BENCH_COMPLETE": "complete_bash", "COMP_WORDS": "bench lat", "COMP_CWORD": "1"}
    )
    assert r.returncode == 0 and r.stdout.split() == ["latency"]


@pytest.mark.parametrize(
    ("cmd", "placeholders"),
    [
        (
            "run",
            [
                "--data PATH",
                "--model NAME=PATH",
                "--topic ROLE=TOPIC",
                "--out DIR",
                "--rerun FILE",
                "--projection enu|mercator",
                "--set NAME.OPTION=VALUE",
                "--config FILE.toml",
            ],
        ),
        ("data inspect", ["--topic ROLE=TOPIC"]),
        ("train", ["--data PATH", "--out DIR", "--network NAME"]),
        ("latency", ["--data PATH", "--model NAME=PATH"]),
        ("tune", ["--data PATH"]),
    ],
)
def test_help_placeholders(cmd, placeholders):
    r = bench(*cmd.split(), "--help")
    options = r.stdout.split("Options:", 1)[1]
    for p in placeholders:
        assert p in options, (p, options)
    assert "<list[" not in options and "<path>" not in options


def test_projection_help_shows_one_percent_sign():
    out = bench("run", "--help").stdout
    assert "~+52 % at" in " ".join(out.split()) and "%%" not in out


def test_usage_error_names_the_command_help():
    line = assert_one_error_line(bench("data", "inspect", "--bogus"))
    assert line.endswith("(see `bench data inspect --help`)") and "Usage:" not in line
    line = assert_one_error_line(bench("latency", "--steps"))
    assert line.endswith("(see `bench latency --help`)")


# ------------------------------------------------------------------ bench.options
def test_option_checks():
    import math

    from posbench.checks import (
        check_at_least,
        check_dropouts,
        check_horizon,
        check_synthetic_duration,
        parse_predictor_names,
    )
    from posbench.errors import UsageError

    assert check_horizon(0.2) == 0.2 and check_horizon(10.0) == 10.0
    for bad in (-1.0, 0.0, 10.01, math.nan, math.inf):
        with pytest.raises(UsageError, match="--horizon"):
            check_horizon(bad)
    for ok in ("none", "outages", "random:0", "random:0.5", "outage:2"):
        assert check_dropouts(ok) == ok
    for bad in ("outage", "random:1", "random:-0.1", "outage:0", "outage:inf", "x", ""):
        with pytest.raises(UsageError, match="--dropouts"):
            check_dropouts(bad)
    assert check_at_least(0.0, 0.0, "--gps-latency") == 0.0
    with pytest.raises(UsageError, match="--gps-latency must be at least 0"):
        check_at_least(math.nan, 0.0, "--gps-latency")
    assert parse_predictor_names(" cv, kf ,") == ("cv", "kf")
    with pytest.raises(UsageError, match="no predictor"):
        parse_predictor_names(" , ")
    assert check_synthetic_duration(None, ["x"]) is None
    with pytest.raises(UsageError, match="without --data"):
        check_synthetic_duration(60.0, ["x"])


def test_out_checks_create_nothing(tmp_path):
    from posbench.checks import check_out_dir, check_out_file
    from posbench.errors import UsageError

    target = tmp_path / "a" / "b"
    assert check_out_dir(target) == target and not (tmp_path / "a").exists()
    (tmp_path / "f").write_text("x")
    with pytest.raises(UsageError, match="not a folder"):
        check_out_dir(tmp_path / "f")
    with pytest.raises(UsageError, match="is a file"):
        check_out_dir(tmp_path / "f" / "sub")
    with pytest.raises(UsageError, match="is a folder"):
        check_out_file(tmp_path, "--rerun")
    assert check_out_file(tmp_path / "new" / "run.rrd", "--rerun").name == "run.rrd"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_validate_predictors_resolves_a_model_folder(tmp_path):
    from posbench.errors import UsageError
    from posbench.predictors.lstm.predictor import bundled_model
    from posbench.replay.predictor_setup import validate_predictors

    shutil.copy(bundled_model(), tmp_path / "model.onnx")
    shutil.copy(bundled_model().with_suffix(".json"), tmp_path / "model.json")
    opts = validate_predictors(["cv", "lstm"], {"lstm": {"model": str(tmp_path)}})
    assert opts == {"lstm": {"model": str(tmp_path / "model.onnx")}}
    (tmp_path / "empty").mkdir()
    with pytest.raises(UsageError, match="folder without a model.onnx"):
        validate_predictors(["lstm"], {"lstm": {"model": str(tmp_path / "empty")}})
    with pytest.raises(UsageError, match="lstm-authors needs"):
        validate_predictors(["lstm-authors"], {})


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    horizon=st.one_of(st.text(max_size=12), st.floats().map(repr)), dropouts=st.text(max_size=16)
)
def test_random_option_values_give_one_error_line(tmp_path, capsys, horizon, dropouts):
    """In-process ``main``: any --horizon / --dropouts text with a bad --seed (checked
    after them, so the run never starts) ends in one error line and status 2."""
    import posbench.cli.app as cli

    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        cli.main(
            [
                "run",
                f"--horizon={horizon}",
                f"--dropouts={dropouts}",
                "--seed=-1",
                "--out",
                str(out),
            ]
        )
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("error: "), err
    assert not out.exists()
