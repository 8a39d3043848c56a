"""A truth sampled too sparsely for a reference position is named where it decides: the data
check warns (the truth's sample interval and the reference's gap limit), and a run that
could score nothing for want of a reference says so instead of "past the end"."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from helpers import assert_one_error_line, bench

from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, TruthStream
from posbench.scenarios.loaders.table import write_table
from posbench.scenarios.truth_gaps import TRUTH_MAX_GAP_S, truth_gap_note

#: what a 1 Hz truth is told
ONE_HZ = (
    "the truth is sampled every 1 s (median); a reference position is interpolated only "
    "across gaps up to 0.5 s, so 100 % of its span has none"
)


def slow_truth_csv(path: Path, truth_dt_s: float = 1.0, duration_s: float = 30.0) -> Path:
    """A drive at 10 m/s, gently accelerating: fixes at 10 Hz (2 cm noise), its truth every
    ``truth_dt_s`` [s] over the same span."""
    rng = np.random.default_rng(0)
    tt, tg = np.arange(0.0, duration_s + 1e-9, truth_dt_s), np.arange(0.0, duration_s, 0.1)

    def track(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return 10.0 * t, 0.05 * t * t

    gx, gy = track(tg)
    drive = Drive(
        meta=DriveMeta(name="slow-truth", source="test", format="test"),
        gps=GpsStream(tg, gx + rng.normal(0, 0.02, tg.size), gy + rng.normal(0, 0.02, tg.size)),
        truth=TruthStream(tt, *track(tt)),
    )
    write_table(drive, path)
    return path


def test_the_note_names_the_sampling_and_the_limit() -> None:
    assert TRUTH_MAX_GAP_S == 0.5
    assert truth_gap_note(np.arange(0.0, 60.0, 0.1)) == ""  # 10 Hz: every query has one
    assert truth_gap_note(np.arange(0.0, 61.0, 1.0)) == ONE_HZ
    # 10 Hz with a 5 s dropout in 100 s: 5 % of the span has none
    t = np.concatenate([np.arange(0.0, 50.0, 0.1), np.arange(55.0, 100.0, 0.1)])
    assert truth_gap_note(t) == (
        "the truth has 1 gap over 0.5 s (longest 5.1 s; sampled every 0.1 s otherwise): a "
        "reference position is interpolated only across gaps up to 0.5 s, so 5.11 % of its "
        "span has none"
    )
    t = np.concatenate([np.arange(0.0, 99.0, 0.1), [99.6]])  # one 0.7 s gap: 0.7 %, quiet
    assert truth_gap_note(t) == ""


def test_data_inspect_warns_of_a_1_hz_truth(tmp_path: Path) -> None:
    data = slow_truth_csv(tmp_path / "slow.csv")
    r = bench("data", "inspect", data, "--json")
    assert r.returncode == 0, r.stderr
    truth = json.loads(r.stdout)[0]["consistency"]["truth"]
    assert truth["verdict"] == "warn" and truth["reason"].startswith(ONE_HZ + "; offset")
    # at 10 Hz the same drive passes, with no word on gaps
    ok = json.loads(
        bench("data", "inspect", slow_truth_csv(tmp_path / "ok.csv", 0.1), "--json").stdout
    )
    assert ok[0]["consistency"]["truth"]["verdict"] == "pass"
    assert "gap" not in ok[0]["consistency"]["truth"]["reason"]


def test_run_names_the_truths_sampling_when_nothing_has_a_reference(tmp_path: Path) -> None:
    data = slow_truth_csv(tmp_path / "slow.csv")
    r = bench("run", "--data", data, "-p", "cv", "--out", tmp_path / "run", "-q")
    line = assert_one_error_line(r, "without a reference position", f"drive slow: {ONE_HZ}")
    assert "past the end" not in line
