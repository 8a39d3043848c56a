"""Positions no vehicle can have, and statements no receiver can make (issues 49 and 50):
a fix beyond any point on Earth is refused at load in one line naming its line; a plugin
answering one is refused in one line naming it; a stated accuracy of 1e-170 m runs, with no
RuntimeWarning."""

from __future__ import annotations

import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench


def _csv(path: Path, far: str | None = None, accuracy: str = "") -> Path:
    """A straight 10 m/s drive, fixes at 5 Hz with a truth at 20 Hz; fix 100 at ``far``."""
    rows = ["stream,t,x,y,accuracy"]
    for i, t in enumerate(np.arange(0.0, 40.0, 0.2)):
        rows.append(f"gps,{t:.3f},{far if (far and i == 100) else f'{10 * t:.3f}'},0.0,{accuracy}")
    for t in np.arange(0.0, 40.0, 0.05):
        rows.append(f"truth,{t:.3f},{10 * t:.3f},0.0,")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("far", ["1e15", "1e20", "1e100", "1e300", "-2e9"])
def test_a_fix_beyond_any_point_on_earth_is_refused_at_load(tmp_path, far):
    data = _csv(tmp_path / "far.csv", far)
    r = bench("run", "--data", data, "-p", "cv,kf", "--out", tmp_path / "o", cwd=tmp_path)
    line = assert_one_error_line(r, "line 102, column 'x'", "is no position")
    assert "RuntimeWarning" not in r.stderr and line.count("\n") == 0
    assert not (tmp_path / "o").exists()
    r = bench("data", "inspect", data, cwd=tmp_path)
    assert_one_error_line(r, "line 102, column 'x'")


def test_the_loaders_last_check_names_the_fix(tmp_path):
    from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, refuse_far_positions
    from posbench.scenarios.errors import DataError

    t = np.arange(5.0)
    x = np.array([0.0, 1.0, 3e9, 3.0, 4.0])
    drive = Drive(DriveMeta("d", "test", "t"), GpsStream(t, x, np.zeros(5)))
    with pytest.raises(DataError, match=r"fix at t=2\.000 s: x = 3e\+09 m is no position"):
        refuse_far_positions(drive, tmp_path / "d.bag")


def test_a_tiny_stated_accuracy_runs_without_a_warning(tmp_path):
    import posbench

    data = _csv(tmp_path / "tiny.csv", accuracy="1e-170")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        run = posbench.run(data=[data], predictors="cv,kf,ekf", out=None)
    for p in ("cv", "kf", "ekf"):
        assert np.isfinite(run.results["predictors"][p]["future"]["mean_m"])


def test_a_plugin_answering_no_position_is_one_error_line(tmp_path):
    (tmp_path / "huge.py").write_text(
        textwrap.dedent(
            """
            import math
            from posbench.predictors.base import Predictor

            class Huge(Predictor):
                name = "huge"
                def reset(self):
                    self.n = 0
                def observe_gps(self, t, x, y, sigma=None):
                    self.n += 1
                def position_at(self, t):
                    return (1e308, 1e308) if self.n else (math.nan, math.nan)
            """
        )
    )
    r = bench(
        "run",
        "-p",
        "cv,huge:Huge",
        "--synthetic-duration",
        "20",
        "--out",
        tmp_path / "o",
        cwd=tmp_path,
        env={"PYTHONPATH": str(tmp_path)},
    )
    line = assert_one_error_line(r, "predictor huge:Huge answered (1e+308, 1e+308) m")
    assert "no position" in line and "RuntimeWarning" not in r.stderr
