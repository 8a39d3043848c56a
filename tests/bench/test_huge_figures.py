"""Absurdly large values (issue 40): a stated accuracy of 1e300 m, answers of 1e308 m. No
numpy RuntimeWarning reaches the user, no 300-digit number reaches report.md or a table; every
ordinary figure prints as it always has."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import assert_one_error_line, bench

#: a figure written out in full: 20 digits in a row
LONG_NUMBER = re.compile(r"\d{20}")


def _circle_csv(path: Path, accuracy: float) -> Path:
    """A GPS-only drive, 60 s on a 50 m circle at 10 m/s, 5 Hz fixes stating ``accuracy``."""
    t = np.arange(0.0, 60.0, 0.2)
    x, y = 50 * np.sin(0.2 * t), 50 * (1 - np.cos(0.2 * t))
    rows = [f"{a:.1f},{b:.4f},{c:.4f},{accuracy!r}" for a, b, c in zip(t, x, y, strict=True)]
    path.write_text("t,x,y,accuracy\n" + "\n".join(rows) + "\n")
    return path


# ------------------------------------------------------------------ a stated accuracy of 1e300 m
@pytest.mark.slow
def test_huge_stated_accuracy_runs_without_warnings(tmp_path):
    """Once: the EKF's covariance overflowed (raw RuntimeWarnings) and report.md held the
    accuracy in 300 digits. A fix stating more than 1000 km tells a filter nothing; it is
    given sigma = 1000 km (finite squares), and the data check's warning writes 1.0e+300."""
    src = _circle_csv(tmp_path / "acc.csv", 1e300)
    r = bench(
        "run", "--data", str(src), "-p", "cv,kf,ekf", "--drive-plots", "0", "--out", "o",
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "RuntimeWarning" not in r.stdout + r.stderr, r.stderr
    report = (tmp_path / "o" / "report.md").read_text()
    assert "median stated accuracy 1.0e+300 m > 5 m" in report
    for f in [tmp_path / "o" / "report.md", *(tmp_path / "o" / "tables").glob("*.[mt]*")]:
        assert not LONG_NUMBER.search(f.read_text()), f


def test_inspect_writes_a_huge_accuracy_short(tmp_path):
    src = _circle_csv(tmp_path / "acc.csv", 1e300)
    r = bench("data", "inspect", str(src), env={"COLUMNS": "250"})
    assert r.returncode == 0, r.stderr
    assert "RuntimeWarning" not in r.stderr
    assert "/ 1.00e+300 m" in r.stdout and "accuracy 1.0e+300 m" in r.stdout
    assert not LONG_NUMBER.search(r.stdout)


def test_fix_sigma_capped_finite():
    from posbench.replay.loop import MAX_SIGMA_M, fix_sigma

    assert fix_sigma(2.5) == 2.5 and fix_sigma(MAX_SIGMA_M) == MAX_SIGMA_M
    assert fix_sigma(1e300) == MAX_SIGMA_M and math.isfinite(MAX_SIGMA_M**2)
    assert fix_sigma(math.nan) is None and fix_sigma(0.0) is None and fix_sigma(math.inf) is None


# ------------------------------------------------------------------ answers of 1e308 m
@pytest.fixture(scope="module")
def queries(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A queries folder of one 10 s synthetic drive."""
    from posbench.config import RunConfig
    from posbench.offline.queries_folder import write_queries
    from posbench.scenarios.synthetic import generate_drive

    q = tmp_path_factory.mktemp("huge") / "q"
    drive = generate_drive(seed=0, route="mixed", duration_s=10.0)
    write_queries([drive], RunConfig(predictors=(), gate=False), q, command="test", data=[])
    return q


def test_huge_answers_are_one_error_line(queries, tmp_path):
    """Once: overflow RuntimeWarnings from the metrics, the bootstrap and the plots, and
    309-digit figures in report.md. No position on Earth is 1e9 m from a drive's origin in
    local metres: an answer beyond that is refused, naming the file, line and column."""
    q = pd.read_csv(queries / "queries.csv")
    answers = q[["drive", "kind", "t_query"]].assign(x=1.0, y=1e308)
    answers.to_csv(tmp_path / "answers.csv", index=False)
    r = bench("score", "answers.csv", "--queries", str(queries), "--out", "o", cwd=tmp_path)
    assert_one_error_line(
        r, "answers.csv: line 2, column 'y': 1e+308 is no position", "1e+09 m", f"{len(q)} such"
    )
    assert not (tmp_path / "o").exists()
    drive = q["drive"].iloc[0]
    (tmp_path / f"{drive}.tum").write_text(f"{float(q['t_query'].iloc[-1])!r} -1e300 0 0 0 0 0 1\n")
    r = bench("score", f"{drive}.tum", "--queries", str(queries), cwd=tmp_path)
    assert_one_error_line(r, "line 1, column 'x': -1e+300 is no position")


def test_far_but_possible_answers_are_read():
    """The bound leaves every position on Earth, in either projection (a Mercator y near a
    pole is a few 1e7 m), to be scored as the error it is."""
    from posbench.offline.answers import MAX_POSITION_M, Answers, _positions_checked

    frame = pd.DataFrame({"x": [0.0, 9e7, -MAX_POSITION_M], "y": [0.0, 1e8, 0.0]})
    answers = Answers(Path("a.csv"), frame, True)
    assert _positions_checked(answers) is answers


# ------------------------------------------------------------------ how figures are written
def test_huge_figures_stay_short_ordinary_ones_unchanged():
    from posbench.report.data_check import cell
    from posbench.report.notes import _interval
    from posbench.scenarios.consistency import Check
    from posbench.scenarios.text import fixed
    from posbench.tables.table import _FIGURE, fmt

    assert [fmt(v) for v in (0.1234, 123456.7891, 999999999.4, -2.0)] == [
        "0.123", "123456.789", "999999999.400", "-2.000",
    ]  # fmt: skip
    assert fmt(1.4142e308) == "1.414e+308" and fmt(-1e300, 2) == "-1.00e+300"
    assert fmt(math.nan) == "-" and fmt(math.inf) == "inf" and fmt(np.float64(1e12), 1) == "1.0e+12"
    assert (
        fixed(0.05, 2) == "0.05"
        and fixed(2.0, 1, "+") == "+2.0"
        and fixed(1e10, 1, "+") == ("+1.0e+10")
    )
    gps = Check("gps", "warn", "", {"scatter_m": 0.05, "stated_m": 1e300})
    assert cell(gps) == "warn 0.05 m / 1.00e+300 m"
    imu = Check("imu.yaw_rate", "pass", "", {"scale": 1.0, "corr": 0.99, "lag_s": 0.01})
    assert cell(imu) == "pass x1.00 r 0.99 +0.01 s"
    assert _interval([0.083, 0.157]) == " [0.083, 0.157]"
    assert _interval([1e300, 2e300]) == " [1.000e+300, 2.000e+300]"
    assert _FIGURE.match("1.414e+308 [1.000e+300, 1.414e+308]")  # still a figure: right-aligned
