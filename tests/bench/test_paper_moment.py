"""The paper's figures are drawn from the run's own records: each drive's moment is chosen from
its future queries, lstm's step there is recorded while the run replays it (without changing
any answer), and the figures replay nothing again."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from posbench.config import RunConfig
from posbench.replay.loop import replay
from posbench.replay.paper_moment import moment_fix, moment_probe, turn_queries
from posbench.replay.predictor_setup import build_predictor
from posbench.replay.prepare import prepare_drive
from posbench.replay.runner import run_drive
from posbench.scenarios.synthetic import default_drives

CFG = RunConfig(predictors=("kf-paper", "lstm"))


@pytest.fixture(scope="module")
def drive():
    return next(d for d in default_drives() if "roundabout" in d.name)


def _moment_from_traces(traces: pd.DataFrame) -> float:
    """The moment as the figures picked it from lstm's traces before (the oracle): the fix
    whose reference course, between neighbouring future queries, changes most over five
    of them at more than 2 m/s."""
    f = traces[(traces.kind == "future") & (traces.predictor == "lstm")]
    f = f.dropna(subset=["x_ref"]).sort_values("t_issue")
    hd = np.unwrap(np.arctan2(np.gradient(f.y_ref.to_numpy()), np.gradient(f.x_ref.to_numpy())))
    change = np.abs(hd[5:] - hd[:-5])
    change[~(f.speed_mps.to_numpy()[:-5] > 2)] = 0
    return float(f.t_issue.iloc[int(np.argmax(change)) + 2])


def test_the_moment_is_the_one_the_traces_give_and_its_step_is_recorded(drive):
    r = run_drive(drive, CFG)
    m = r.paper_moment
    assert m["t_fix"] == _moment_from_traces(r.traces)
    fut = r.traces[(r.traces.predictor == "lstm") & (r.traces.kind == "future")]
    assert m["turns"] == int(fut.label.isin(["turn", "roundabout"]).sum()) > 0
    assert m["grid"].shape == (8, 2) and m["pred"].shape == (2,)
    assert np.all(np.isfinite(m["grid"])) and np.all(np.isfinite(m["now_xy"]))
    # the first answer recorded is the run's current-position answer at the fix
    assert m["now_t"][0] == m["t_fix"] and m["now_t"][-1] == pytest.approx(m["t_fix"] + 0.2)


def test_recording_the_step_changes_no_answer(drive):
    prep = prepare_drive(drive, CFG)
    plain = replay(build_predictor(CFG, "lstm", prep.gps_condition), prep, CFG.horizon_s)
    lstm = build_predictor(CFG, "lstm", prep.gps_condition)
    probe, record = moment_probe(lstm, prep.future, CFG.horizon_s)
    assert probe is not None and probe[0] == moment_fix(prep.future)
    probed = replay(lstm, prep, CFG.horizon_s, probe)
    assert "grid" in record and record["turns"] == turn_queries(prep.future)
    np.testing.assert_array_equal(plain.future_xy, probed.future_xy)
    np.testing.assert_array_equal(plain.now_xy, probed.now_xy)


def test_a_drive_too_short_for_a_moment_records_its_turns_only(drive):
    short = drive.window(0.0, 3.0)
    prep = prepare_drive(short, CFG)
    probe, record = moment_probe(object(), prep.future, CFG.horizon_s)
    assert probe is None and set(record) == {"turns"}


def test_the_paper_figures_replay_nothing(drive, tmp_path, monkeypatch):
    import posbench.predictor_tools.paper_figures as figures
    import posbench.predictors.registry as registry
    import posbench.replay.loop as loop
    from posbench.scoring.records import all_traces

    runs = [run_drive(drive, CFG)]

    def refused(*args, **kwargs):
        raise AssertionError("the paper figures built a predictor or replayed a drive")

    monkeypatch.setattr(registry, "create", refused)  # no predictor is built
    monkeypatch.setattr(loop, "replay", refused)
    figs = figures.paper_figures([drive], CFG, all_traces(runs), tmp_path, runs)
    assert [f for f, _ in figs] == [
        "paper_fig_prediction.png",
        "paper_fig_current_position.png",
        "paper_fig_path.png",
        "paper_fig_kalman.png",
    ]
    t_fix = runs[0].paper_moment["t_fix"]
    assert f"t = {t_fix:.2f} s" in figs[3][1]  # kf-paper's own answer at the same fix
