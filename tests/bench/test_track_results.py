"""Along/cross-track errors through the pipeline: the reference heading computed in
bench.prepare, the trace columns of bench.scoring, results.json's track_errors block and
the report's "Where the error points" table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from posbench.aggregation.track import track_section
from posbench.config import RunConfig
from posbench.metrics.track_errors import inward_cross, track_summary
from posbench.pipeline.results import build_results
from posbench.replay.prepare import prepare_drive
from posbench.replay.runner import run
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.records import all_traces
from posbench.scoring.trace_set import TraceSet
from posbench.tables.track import track_table


@pytest.fixture(scope="module")
def drive():
    return generate_drive(seed=4, route="mixed", duration_s=40.0)


def test_reference_heading_follows_the_truth_yaw(drive):
    prep = prepare_drive(drive, RunConfig(predictors=("cv",)))
    q = prep.now
    assert drive.truth.yaw is not None
    yaw = np.interp(q.t_query, drive.truth.t, np.unwrap(drive.truth.yaw))
    ok = np.isfinite(q.heading_rad)
    assert ok.mean() > 0.5
    diff = np.angle(np.exp(1j * (q.heading_rad[ok] - yaw[ok])))
    assert np.abs(diff).max() < 0.05  # rad: the direction of travel is the yaw here
    # standstill has no heading
    slow = q.speed_mps < 0.3
    assert np.isnan(q.heading_rad[slow]).all()


def test_results_block_matches_the_traces(drive):
    cfg = RunConfig(predictors=("cv", "kf"))
    runs = run([drive], cfg)
    traces = all_traces(runs)
    for c in ("along_m", "cross_m", "heading_ref", "yaw_rate_ref"):
        assert c in traces
    both = traces[["along_m", "cross_m"]].notna().all(axis=1)
    np.testing.assert_allclose(
        np.hypot(traces.along_m[both], traces.cross_m[both]),
        traces.error_m[both],
        rtol=1e-9,
        atol=1e-12,
    )
    res = build_results(runs, cfg, [], "test", traces=traces)
    block = res["track_errors"]
    scored = ~traces.warmup & traces.x_ref.notna()
    for p in ("cv", "kf"):
        for k in ("future", "now"):
            m = scored & (traces.predictor == p) & (traces.kind == k)
            g = traces[m]
            want = track_summary(
                g.along_m, g.cross_m, inward_cross(g.cross_m, g.yaw_rate_ref), g.error_m
            )
            assert block["predictors"][p][k] == pytest.approx(want, nan_ok=True)
            assert (
                block["predictors"][p][k]["count"] + block["predictors"][p][k]["standstill"]
                == res["predictors"][p][k]["count"]
            )
            turns = block["by_label"][p][k]["turn"]
            assert turns["count"] == int(
                (m & (traces.label == "turn") & g.reindex(traces.index).along_m.notna()).sum()
            )
    # constant velocity runs wide in turns (its straight extrapolation leaves the curve)
    assert block["predictors"]["cv"]["future"]["inward_mean_m"] < 0
    table = track_table(res).markdown()
    assert table.splitlines()[0].count("|") == 10  # no '|' inside a header cell
    assert "| cv | future |" in table


def test_section_without_track_columns_is_empty():
    tr = pd.DataFrame({"predictor": ["a"], "kind": ["now"], "error_m": [1.0]})
    assert track_section(TraceSet(tr), ["a"]) == {"predictors": {}, "by_label": {}}
