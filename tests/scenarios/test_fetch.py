"""Data paths as fsspec URLs: detected (even after pathlib collapsed '//'), copied, loaded."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import bench

from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders import load
from posbench.scenarios.remote import as_url, fetch, local_paths

fsspec = pytest.importorskip("fsspec")


def write_csv_drive(folder: Path, name: str = "drive_a", n: int = 300) -> Path:
    """A wide GPS-only CSV: x = 10 t, y = 0.5 t^2 / 10, fixes every 0.1-0.4 s."""
    folder.mkdir(parents=True, exist_ok=True)
    t = np.cumsum(np.random.default_rng(1).uniform(0.1, 0.4, n))
    path = folder / f"{name}.csv"
    rows = "\n".join(f"{ti:.6f},{10 * ti:.4f},{0.05 * ti * ti:.4f}" for ti in t)
    path.write_text("t,x,y\n" + rows + "\n")
    return path


@pytest.mark.parametrize(
    ("given", "url"),
    [
        ("s3://bucket/drives/a", "s3://bucket/drives/a"),
        ("s3:/bucket/drives/a", "s3://bucket/drives/a"),  # str(Path("s3://bucket/drives/a"))
        ("https://example.org/x.csv", "https://example.org/x.csv"),
        ("file:///tmp/drives", "file:///tmp/drives"),
        (str(Path("file:///tmp/drives")), "file:///tmp/drives"),
        ("/tmp/drives", None),
        ("relative/drive.csv", None),
        ("C:/drives/a.csv", None),  # a Windows drive letter, not a scheme
    ],
)
def test_as_url(given, url):
    assert as_url(given) == url
    assert as_url(Path(given)) == url


def test_fetch_folder_and_file(tmp_path):
    src = tmp_path / "src" / "drives"
    write_csv_drive(src / "day1", "drive_a")
    write_csv_drive(src, "drive_b")
    dest = tmp_path / "dest"
    local = fetch(f"file://{src}", dest)
    assert local == dest / "drives"
    copied = sorted(p.relative_to(local).as_posix() for p in local.rglob("*") if p.is_file())
    assert copied == ["day1/drive_a.csv", "drive_b.csv"]
    assert (local / "drive_b.csv").read_bytes() == (src / "drive_b.csv").read_bytes()
    mem = fsspec.filesystem("memory")
    mem.pipe("/posbench-test/one/drive_c.csv", (src / "drive_b.csv").read_bytes())
    one = fetch("memory://posbench-test/one/drive_c.csv", tmp_path / "m")
    assert one.name == "drive_c.csv"
    a, b = load(one)[0], load(src / "drive_b.csv")[0]
    assert np.array_equal(a.gps.t, b.gps.t) and np.array_equal(a.gps.x, b.gps.x)


def test_fetch_errors(tmp_path):
    with pytest.raises(DataError, match="no such file or folder"):
        fetch(f"file://{tmp_path}/missing", tmp_path / "d")
    with pytest.raises(DataError, match="cannot open this URL"):
        fetch("nosuchprotocol://bucket/key", tmp_path / "d")


def test_local_paths_cleans_up(tmp_path):
    src = write_csv_drive(tmp_path / "src")
    with local_paths([src, Path(f"file://{src}")]) as paths:
        assert paths[0] == src and paths[1] != src and paths[1].read_bytes() == src.read_bytes()
        copy = paths[1]
    assert not copy.exists()
    with local_paths(None) as none:
        assert none is None


@pytest.mark.slow
def test_cli_run_on_url_equals_local_path(tmp_path):
    src = tmp_path / "drives"
    write_csv_drive(src, "drive_a")
    res = {}
    for key, arg in (("path", str(src)), ("url", f"file://{src}")):
        out = tmp_path / key
        r = bench(
            "run",
            "--data",
            arg,
            "-p",
            "cv",
            "--workers",
            "1",
            "--out",
            out,
            "--plot-format",
            "none",
            columns=200,
        )
        assert r.returncode == 0, r.stdout + r.stderr
        res[key] = json.loads((out / "results.json").read_text())
    assert [d["name"] for d in res["url"]["drives"]] == ["drive_a"]
    assert json.dumps(res["url"]["predictors"]["cv"]["future"]) == json.dumps(
        res["path"]["predictors"]["cv"]["future"]
    )
    r = bench("run", "--data", f"file://{tmp_path}/missing", "-p", "cv", columns=None)
    assert (
        r.returncode == 2 and "no such file or folder" in r.stderr and "Traceback" not in r.stderr
    )
