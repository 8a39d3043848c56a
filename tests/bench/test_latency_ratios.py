"""How ``bench latency`` and the CI gate turn timings into ratios to cv's step
(:func:`posbench.predictor_tools.latency.ratios_to_cv`): pure arithmetic on result dicts."""

from __future__ import annotations

import pytest

from posbench.predictor_tools.latency import ratios_to_cv


def result(p50: float, p99: float, rounds: list[float] | None = None) -> dict:
    r = {"step_us": {"p50": p50, "p99": p99}}
    if rounds is not None:
        r["step_p50_rounds"] = rounds
    return r


def test_one_round_divides_the_p50s():
    got = ratios_to_cv({"cv": result(4.0, 8.0), "kf": result(10.0, 30.0)})
    assert got["cv"] == {"step_p50": 1.0, "step_p99": 2.0, "p99_over_p50": 2.0}
    assert got["kf"] == {"step_p50": 2.5, "step_p99": 7.5, "p99_over_p50": 3.0}


def test_rounds_are_paired_and_the_median_ratio_taken():
    """cv ran fast in round 3 only: divided lowest by lowest, kf would read 5x; the rounds'
    own ratios are 2, 2.5, 5, 2.2, 2.4, whose median is 2.4."""
    cv = result(2.0, 9.0, [5.0, 4.0, 2.0, 5.0, 5.0])
    kf = result(10.0, 40.0, [10.0, 10.0, 10.0, 11.0, 12.0])
    got = ratios_to_cv({"cv": cv, "kf": kf})
    assert got["kf"]["step_p50"] == pytest.approx(2.4)
    assert got["cv"]["step_p50"] == 1.0
    assert got["kf"]["step_p99"] == 20.0  # p99s: over cv's lowest p50, as before
    assert got["kf"]["p99_over_p50"] == 4.0


def test_rounds_that_do_not_pair_fall_back_to_the_p50s():
    got = ratios_to_cv({"cv": result(4.0, 8.0, [4.0, 5.0]), "kf": result(10.0, 20.0, [10.0])})
    assert got["kf"]["step_p50"] == 2.5


def test_without_cv_no_ratios_and_stages_are_skipped():
    assert ratios_to_cv({"kf": result(10.0, 20.0)}) == {}
    got = ratios_to_cv({"cv": result(4.0, 8.0), "lstm_stages": {"step_us": {"p50": 1.0}}})
    assert list(got) == ["cv"]
