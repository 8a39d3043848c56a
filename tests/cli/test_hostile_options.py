"""The smaller hostile inputs of issue 40, each refused in one line or read as it should be:
an ``--out`` no command could write (a name longer than the file system allows, a folder in
a system file system), a ``--synthetic-duration`` too long for memory, a ``file://`` data path
given to ``bench data inspect``, and messages that quoted numpy scalars
(``np.float64(95.0)``) instead of plain numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench

#: a folder name no Linux file system takes (NAME_MAX is 255 bytes)
LONG = "a" * 300


def _forbid_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make generating or loading a drive fail loudly: the checks must refuse first."""

    def no(*args: object, **kwargs: object) -> None:
        raise AssertionError("a drive was made or loaded before the options were checked")

    monkeypatch.setattr("posbench.scenarios.synthetic.generate_drive", no)
    monkeypatch.setattr("posbench.scenarios.synthetic.default_drives", no)
    monkeypatch.setattr("posbench.pipeline.drives.load_drives", no)


def _commands(tmp_path: Path, out: str) -> dict[str, list[str]]:
    """Every command that takes ``--out`` (a folder or, for ``tune``, a file), otherwise
    valid as far as its checks before ``--out`` go."""
    (tmp_path / "answers.csv").write_text("drive,kind,t_query,x,y\n")
    (tmp_path / "q").mkdir(exist_ok=True)
    return {
        "run": ["run", "-p", "cv", "--synthetic-duration", "10", "--out", out],
        "queries": ["queries", "--synthetic-duration", "10", "--out", out],
        "score": ["score", "answers.csv", "--queries", "q", "--name", "x", "--out", out],
        "compare": ["compare", "r1", "r2", "--out", out],
        "export": ["export", "r1", "--out", out],
        "tune": ["tune", "kf", "--out", out + ".json"],
    }


# ------------------------------------------------------------------ --out
@pytest.mark.parametrize("command", ["run", "queries", "score", "compare", "export", "tune"])
def test_out_name_longer_than_the_file_system_allows(tmp_path, monkeypatch, command):
    _forbid_work(monkeypatch)
    args = _commands(tmp_path, LONG)[command]
    r = bench(*args, cwd=tmp_path)
    name = args[args.index("--out") + 1]  # tune's is a file: LONG.json
    assert_one_error_line(
        r, f"--out {name}: cannot be written: a name in it has {len(name)} characters", "255"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["answers.csv", "q"]


@pytest.mark.parametrize("command", ["run", "queries", "score", "compare", "export", "tune"])
def test_out_in_a_system_folder_refused_before_any_work(tmp_path, monkeypatch, command):
    """/proc takes no new folder, even from root (the tests may run as root, for whom every
    permission check passes): the check tries for real, before any drive is loaded."""
    _forbid_work(monkeypatch)
    r = bench(*_commands(tmp_path, "/proc/posbench-out")[command], cwd=tmp_path)
    assert_one_error_line(r, "--out /proc/posbench-out", "/proc takes no new files or folders")


def test_out_under_a_file_and_rerun_file_refused(tmp_path, monkeypatch):
    _forbid_work(monkeypatch)
    (tmp_path / "f").write_text("x")
    r = bench("run", "-p", "cv", "--synthetic-duration", "10", "--out", "f/sub", cwd=tmp_path)
    assert_one_error_line(r, "--out f/sub", "is a file")
    r = bench(
        "run", "-p", "cv", "--synthetic-duration", "10", "--rerun", "/proc/x.rrd", cwd=tmp_path
    )
    assert_one_error_line(r, "--rerun /proc/x.rrd", "/proc takes no new files or folders")


def test_out_check_is_a_real_try_that_leaves_nothing(tmp_path):
    from posbench.checks import check_out_dir, check_out_file

    assert check_out_dir(tmp_path / "a" / "b" / "c") == tmp_path / "a" / "b" / "c"
    assert check_out_file(tmp_path / "d" / "run.rrd", "--rerun").name == "run.rrd"
    (tmp_path / "kept").mkdir()
    assert check_out_dir(tmp_path / "kept") == tmp_path / "kept"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["kept"]


# ------------------------------------------------------------------ --synthetic-duration
@pytest.mark.parametrize("value", ["1e12", "28801", "inf", "nan", "0", "-5"])
def test_synthetic_duration_bounded(tmp_path, monkeypatch, value):
    """1e12 s once died of a MemoryError traceback in the generator: the option now states
    its range (8 h at most: the memory grows with the simulated length) before any drive
    is made."""
    _forbid_work(monkeypatch)
    for command in ("run", "queries"):
        r = bench(command, "--synthetic-duration", value, "--out", "o", cwd=tmp_path)
        line = assert_one_error_line(r, "--synthetic-duration", "at most 28800 s", "GB")
        shown = f"{float(value):g}"
        assert line.endswith(f"got {shown}"), line


def test_synthetic_duration_bounded_in_the_python_api():
    import posbench
    from posbench.checks import MAX_SYNTHETIC_S, check_synthetic_duration
    from posbench.errors import UsageError
    from posbench.scenarios.time_axis import MAX_SPAN_S

    assert MAX_SYNTHETIC_S == MAX_SPAN_S  # every synthetic drive is one a Drive accepts

    assert check_synthetic_duration(MAX_SYNTHETIC_S, None) == MAX_SYNTHETIC_S
    with pytest.raises(UsageError, match="at most 28800 s"):
        posbench.run(predictors="cv", synthetic_duration_s=1e12, out=None)
    with pytest.raises(UsageError, match="more than 1 s"):
        check_synthetic_duration(math.nan, None)


# ------------------------------------------------------------------ file:// in data inspect
def _circle_csv(path: Path, lat: float | None = None) -> Path:
    """A GPS-only drive, 60 s on a 50 m circle at 5 Hz (the second fix at ``lat`` if given,
    lon 16.0: lat/lon columns then)."""
    t = np.arange(0.0, 60.0, 0.2)
    a = 0.2 * t
    if lat is None:
        x, y = 50 * np.sin(a), 50 * (1 - np.cos(a))
        rows = [f"{ti:.1f},{xi:.4f},{yi:.4f}" for ti, xi, yi in zip(t, x, y, strict=True)]
        path.write_text("t,x,y\n" + "\n".join(rows) + "\n")
    else:
        rows = [f"{ti:.1f},{lat if i == 1 else 45.0},16.0" for i, ti in enumerate(t)]
        path.write_text("t,lat,lon\n" + "\n".join(rows) + "\n")
    return path


def test_inspect_reads_a_file_url_as_run_does(tmp_path):
    """``bench data inspect file:///abs/x.csv`` once said "no such file" where ``bench run
    --data`` read it: both now read a URL through the same function."""
    src = _circle_csv(tmp_path / "circle.csv")
    r = bench("data", "inspect", "--json", f"file://{src}", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert [d["name"] for d in rows] == ["circle"] and rows[0]["gps_count"] == 300
    r = bench("data", "inspect", f"file://{tmp_path}/missing.csv", cwd=tmp_path)
    assert_one_error_line(r, f"file://{tmp_path}/missing.csv", "no such file or folder")


def test_an_error_in_a_fetched_copy_names_the_url(tmp_path):
    bad = _circle_csv(tmp_path / "bad.csv", lat=95.0)
    r = bench("data", "inspect", f"file://{bad}", cwd=tmp_path)
    line = assert_one_error_line(r, f"file://{bad}: gps row 1")
    assert "posbench-fetch-" not in line


# ------------------------------------------------------------------ plain numbers
def test_messages_quote_plain_numbers_not_numpy_reprs(tmp_path):
    """numpy 2 writes ``repr(np.float64(95.0))`` as ``np.float64(95.0)``: messages quote the
    number as Python writes it."""
    bad = _circle_csv(tmp_path / "bad.csv", lat=95.0)
    line = assert_one_error_line(bench("data", "inspect", str(bad)), "(95.0, 16.0)")
    assert "np.float64(" not in line
    from posbench.scenarios.text import quoted

    assert quoted(np.float64(95.0)) == "95.0" and quoted(np.float32(0.5)) == "0.5"
    assert quoted(np.int64(3)) == "3" and quoted("kf") == "'kf'" and quoted(np.inf) == "inf"


def test_option_messages_quote_plain_numbers():
    import posbench
    from posbench.errors import UsageError

    with pytest.raises(UsageError) as e:
        posbench.run(
            predictors="kf",
            options={"kf": {"gps_sigma": np.float64(1e9)}},
            synthetic_duration_s=10,
            out=None,
        )
    assert "gps_sigma=1000000000.0 must be in" in str(e.value)
    assert "np.float64(" not in str(e.value)
