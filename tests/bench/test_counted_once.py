"""Issue 40, "the same recording counted twice": a recording given twice (the same path, a
link to it, a file also inside a folder given) or a byte-identical copy under another name
is loaded once, with one line saying which paths were the same and which one counts; the
run's results.json lists its data once and the copies left out."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import bench

from posbench.pipeline.drives import load_drives
from posbench.pipeline.reporter import WARNING, Reporter
from posbench.saved_run.run import load_run, results_schema
from posbench.scenarios import loaders
from posbench.scenarios.loaders import Duplicate, distinct_recordings


class Lines(Reporter):
    """A reporter that keeps its lines."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, int]] = []

    def line(self, text: str, level: int = 0) -> None:
        self.lines.append((text, level))


def _drive_csv(path: Path, n: int = 50, speed: float = 10.0) -> Path:
    """A GPS-only CSV drive: ``n`` fixes at 5 Hz going east at ``speed`` [m/s]."""
    t = np.arange(n) * 0.2
    frame = pd.DataFrame({"stream": "gps", "t": t, "x": speed * t, "y": 0.0, "accuracy": 1.0})
    frame.to_csv(path, index=False)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("second", ["a.csv", "b.csv"], ids=["same-path", "copy"])
def test_a_recording_given_twice_is_run_once(tmp_path, second):
    a = _drive_csv(tmp_path / "a.csv")
    if second != "a.csv":
        shutil.copy(a, tmp_path / second)
    out = tmp_path / "out"
    r = bench(
        "run", "--data", "a.csv", "--data", second, "-p", "cv", "--out", "out",
        "--plot-format", "none", "--table-format", "md", "--workers", "1",
        cwd=tmp_path, columns=200,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    notes = [ln for ln in r.stdout.splitlines() if ln.startswith("note: ")]
    if second == "a.csv":
        assert notes == ["note: a.csv given twice: counted once"]
    else:
        assert notes == [
            "note: b.csv is the same recording as a.csv (identical bytes): counted once, as a.csv"
        ]
    res = load_run(out).results
    assert [d["name"] for d in res["drives"]] == ["a"]  # not ['a', 'a']
    assert [d["path"] for d in res["data"]] == ["a.csv"]  # its sha256 once
    assert res["data_duplicates"] == [
        {"path": second, "same_as": "a.csv", "same_file": second == "a.csv"}
    ]
    import jsonschema

    jsonschema.validate(res, results_schema())


def test_load_drives_loads_each_recording_once_and_says_which_counts(tmp_path):
    a = _drive_csv(tmp_path / "a.csv")
    copy = tmp_path / "sub" / "copy.csv"
    copy.parent.mkdir()
    shutil.copy(a, copy)
    (tmp_path / "link.csv").symlink_to(a)
    other = tmp_path / "sub" / "other.csv"  # the same size, another accuracy in its last row
    other.write_bytes(a.read_bytes().removesuffix(b",1.0\n") + b",2.0\n")
    assert other.stat().st_size == a.stat().st_size
    lines = Lines()
    drives = load_drives([a, tmp_path / "link.csv", tmp_path / "sub", a], reporter=lines)
    assert [d.name for d in drives] == ["a", "other"]
    assert lines.lines == [
        (f"note: {tmp_path / 'link.csv'} is the same recording as {a} (the same file): "
         f"counted once, as {a}", WARNING),
        (f"note: {copy} is the same recording as {a} (identical bytes): counted once, as {a}",
         WARNING),
        (f"note: {a} given twice: counted once", WARNING),
    ]  # fmt: skip


def test_a_file_inside_a_folder_given_is_not_counted_again(tmp_path):
    a = _drive_csv(tmp_path / "a.csv")
    _drive_csv(tmp_path / "b.csv", n=60)
    found = distinct_recordings([tmp_path, a])
    assert found.found == [(a, "table"), (tmp_path / "b.csv", "table")]
    assert found.duplicates == [Duplicate(a, a, same_file=True)]
    assert found.sources == [tmp_path]  # a.csv alone adds no recording: not in the data block


def test_a_copied_folder_recording_is_counted_once(tmp_path):
    """A folder recording (a ROS 2 bag folder) copied under another name: the same relative
    paths and bytes."""
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "bag_0.db3").write_bytes(b"\x00" * 4096)
    shutil.copytree(bag, tmp_path / "bag-copy")
    shutil.copytree(bag, tmp_path / "bag-changed")
    (tmp_path / "bag-changed" / "bag_0.db3").write_bytes(b"\x01" * 4096)  # same sizes
    found = distinct_recordings([bag, tmp_path / "bag-changed", tmp_path / "bag-copy"])
    assert found.found == [(bag, "ros2"), (tmp_path / "bag-changed", "ros2")]
    assert found.duplicates == [Duplicate(tmp_path / "bag-copy", bag, same_file=False)]
    assert found.sources == [bag, tmp_path / "bag-changed"]


def test_only_recordings_of_equal_size_are_read_each_file_once(tmp_path, monkeypatch):
    a = _drive_csv(tmp_path / "a.csv", n=50)
    b = _drive_csv(tmp_path / "b.csv", n=60)
    c = tmp_path / "c.csv"
    shutil.copy(a, c)
    read: list[str] = []
    digest = hashlib.file_digest

    def counted(f, name):
        read.append(Path(f.name).name)
        return digest(f, name)

    monkeypatch.setattr(hashlib, "file_digest", counted)
    loaders._file_sha256.cache_clear()
    assert distinct_recordings([a, b]).duplicates == []
    assert read == []  # different sizes: nothing hashed
    distinct_recordings([a, b, c])
    distinct_recordings([c, a])  # again (as bench run does for its data block): remembered
    assert sorted(read) == ["a.csv", "c.csv"]
