"""Issue 46, combining in children: with ``workers`` > 1 each predictor's figures are computed
in a forked child process (:func:`posbench.scenarios.forked.forked_map`), so the main process
never reads a predictor's rows and what the figures allocated goes back to the system with
the child. results.json is the same to the bit, key order included."""

from __future__ import annotations

import json
import os

import pytest
from helpers import without_timings

from posbench.aggregation.aggregate import aggregate
from posbench.config import RunConfig
from posbench.replay.runner import run
from posbench.scenarios.forked import can_fork, forked_map
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.trace_set import TraceSet

CFG = RunConfig(predictors=("cv", "kf", "poly"), dropouts="outages")

needs_fork = pytest.mark.skipif(not can_fork(), reason="children are forked (Linux)")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    drives = [
        generate_drive(seed=1, route="mixed", duration_s=90.0),
        generate_drive(seed=2, route="roundabout", duration_s=70.0),
        generate_drive(seed=3, route="turns", duration_s=60.0),
    ]
    return run(drives, CFG, workers=1, limit=True, parts=tmp_path_factory.mktemp("parts"))


#: kf "trained" on the first drive: held-out figures and paired held-out comparisons too
MODELS = {"kf": {"model": "test", "bundled": False, "train_drives": ["synthetic-mixed-s1"]}}


def _text(res: dict) -> str:
    """results.json's figures as text, key order kept, timings left out (they are measured)."""
    return json.dumps(without_timings(res))


@needs_fork
@pytest.mark.parametrize("models", [{}, MODELS], ids=["plain", "held-out"])
def test_figures_combined_in_children_are_those_combined_here(runs, models):
    here = aggregate(runs, CFG, models=models, workers=1)
    children = aggregate(runs, CFG, models=models, workers=2)
    assert _text(children) == _text(here)
    assert here["sanity"]["checked"] and here["uncertainty"]["predictors"]  # families present
    assert here["limit"] and all("limit" in d for d in children["drives"])
    if models:
        assert children["held_out"] and children["paired"]["held_out"]


@needs_fork
def test_the_main_process_reads_no_predictor_rows(runs, tmp_path, monkeypatch):
    main = os.getpid()
    log = tmp_path / "reads"
    log.mkdir()
    scored = TraceSet.scored

    def noted(self, predictor, columns):
        (log / f"{os.getpid()}-{predictor}-{len(list(log.iterdir()))}").touch()
        return scored(self, predictor, columns)

    monkeypatch.setattr(TraceSet, "scored", noted)
    aggregate(runs, CFG, models={}, workers=2)
    readers = {int(p.name.split("-")[0]) for p in log.iterdir()}
    assert readers and main not in readers


def _square(x: int) -> int:
    if x == 3:
        raise ValueError("three")
    return x * x


@needs_fork
def test_forked_map_keeps_order_and_raises_what_a_child_raised():
    assert forked_map(_square, [5, 1, 4, 2], workers=2) == [25, 1, 16, 4]
    assert forked_map(_square, [5, 1], workers=1) == [25, 1]
    with pytest.raises(ValueError, match="three"):
        forked_map(_square, [1, 3, 2, 4], workers=2)


def _pid(_: object) -> int:
    return os.getpid()


@needs_fork
def test_one_item_still_gets_a_child_and_one_worker_none():
    """A run of one predictor combines it in a child too (its allocations go with it)."""
    assert forked_map(_pid, [0], workers=2) != [os.getpid()]
    assert forked_map(_pid, [0, 1], workers=1) == [os.getpid()] * 2
