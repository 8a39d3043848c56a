"""Outage lengths side by side (issue 49): a short synthetic run with the outage-lengths profile
carries the curve in results.json (schema 1.10, validated), its figures agree with the traces
and the drive's truth recomputed by hand, report.md shows the section with the curve and the
tables, the figure and the table files are written; a 1.9 file and other profiles have none."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import jsonschema
import numpy as np
import pytest

from posbench.aggregation.outage_lengths import outage_length_section
from posbench.config import RunConfig
from posbench.figures.style import PlotsWritten
from posbench.metrics.outage_lengths import path_lengths
from posbench.pipeline.results import build_results
from posbench.replay.runner import run
from posbench.report.markdown import render_markdown, write_report
from posbench.saved_run.run import SCHEMA_VERSION, Run, load_run, results_schema, save_run
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.records import all_traces
from posbench.scoring.schema import scored_mask

PROFILE = "outage-lengths"


@pytest.fixture(scope="module")
def drives():
    # 90 s: room for 60 s, then 5 s; 50 s: room for 30 s
    return [
        generate_drive(seed=0, duration_s=90.0),
        generate_drive(seed=1, route="turns", duration_s=50.0),
    ]


@pytest.fixture(scope="module")
def result(drives):
    cfg = RunConfig(predictors=("cv", "kf"), dropouts=PROFILE, gps_profile="rtk")
    runs = run(drives, cfg)
    return cfg, runs, build_results(runs, cfg, [], f"bench run --dropouts {PROFILE}", models={})


def test_results_carry_the_curve_and_follow_the_schema(result):
    _, runs, res = result
    saved = Run.from_results(res).results
    assert saved["schema_version"] == SCHEMA_VERSION == "1.10"
    jsonschema.validate(saved, results_schema())
    sec = saved["outage_lengths"]
    assert sec["lengths_s"] == [1.0, 2.0, 5.0, 10.0, 30.0, 60.0] and sec["ate"] == "rms"
    cut = {k: c["outages"] for k, c in sec["counts"].items()}
    assert cut == {"1s": 0, "2s": 0, "5s": 1, "10s": 0, "30s": 1, "60s": 1}
    assert sum(cut.values()) == sum(len(r.outages) for r in runs)
    for p in ("cv", "kf"):
        for k, n in cut.items():
            e = sec["predictors"][p][k]
            assert e["outages"] == n
            if n:
                lo, hi = e["ci95"]["fde_pct"]  # resampled in float32: 1e-6 relative
                assert lo <= e["fde_pct"] * (1 + 1e-6) and e["fde_pct"] <= hi * (1 + 1e-6)
            else:
                assert e["fde_mean_m"] is None and e["fde_pct"] is None  # too short: skipped
    # cv drifts without GPS, the longer the worse
    cv = sec["predictors"]["cv"]
    assert cv["5s"]["fde_mean_m"] < cv["30s"]["fde_mean_m"] < cv["60s"]["fde_mean_m"]


def test_the_figures_match_the_traces_and_the_truth_by_hand(result, drives):
    """cv's 60 s outage: FDE = the error of its last now-query; distance = the truth's path
    (100 Hz) from the last fix to that query, not the now-queries' polyline the aggregation
    uses; the two agree within 0.1 %."""
    _, runs, res = result
    r, d = runs[0], drives[0]
    (k,) = [i for i, (a, b) in enumerate(r.outages) if b - a >= 60.0]
    tr = r.traces[scored_mask(r.traces)]
    mine = tr[(tr.predictor == "cv") & (tr.kind == "now") & (tr.outage == k)]
    last = mine.loc[mine.t_query.idxmax()]
    dist = path_lengths(
        d.truth.t, d.truth.x, d.truth.y, np.array([r.outages[k][0]]), np.array([last.t_query])
    )[0]
    e = res["outage_lengths"]["predictors"]["cv"]["60s"]
    assert e["fde_mean_m"] == pytest.approx(last.error_m, rel=1e-12)
    assert e["ate_mean_m"] == pytest.approx(np.sqrt(np.mean(mine.error_m**2)), rel=1e-12)
    assert e["distance_mean_m"] == pytest.approx(dist, rel=1e-3)
    assert e["fde_pct"] == pytest.approx(100 * last.error_m / dist, rel=1e-3)
    assert 50 < dist < 1000  # the drive moved: a real distance, not a standstill


def test_report_shows_the_section_the_curve_and_the_tables(result, tmp_path):
    _, runs, res = result
    run_ = Run.from_results(res, all_traces(runs))
    save_run(tmp_path, run_)
    written = write_report(load_run(tmp_path), tmp_path, plots=PlotsWritten())
    fig = tmp_path / "outage_lengths.png"
    assert fig in written and fig.read_bytes()[:4] == b"\x89PNG"
    md = (tmp_path / "report.md").read_text()
    section = md[md.index("## GPS outages by length") :]
    assert "![outage_lengths.png](outage_lengths.png)" in section
    assert "5 s: 1 (1 drive); 10 s: 0 (0 drives); 30 s: 1 (1 drive)" in section
    assert "No drive was long enough for: 1 s, 2 s, 10 s." in section
    assert "FDE [% of distance] after | 1 s | 2 s | 5 s | 10 s | 30 s | 60 s |" in section
    cv_pct = res["outage_lengths"]["predictors"]["cv"]["60s"]["fde_pct"]
    assert f"{cv_pct:.1f} [" in section
    assert md.count("](outage_lengths.png)") == 1  # in its section, not again under Plots
    for stem in ("fde_m", "fde_pct", "ate_m", "ate_pct"):
        assert (tmp_path / "tables" / f"outage_lengths_{stem}.csv").exists()
        assert (tmp_path / "tables" / f"outage_lengths_{stem}.tex").exists()
    assert "ATE (outage)" in md and "% of distance" in md  # the glossary


def test_a_1_9_file_and_other_profiles_have_no_section(result, tmp_path):
    cfg, runs, res = result
    assert outage_length_section(runs, replace(cfg, dropouts="outages"), None) is None
    old = json.loads(json.dumps(Run.from_results(res).results))
    old["schema_version"] = "1.9"
    del old["outage_lengths"]
    (tmp_path / "results.json").write_text(json.dumps(old))
    loaded = load_run(tmp_path)
    jsonschema.validate(loaded.results, results_schema())
    md = render_markdown(loaded.results, [])
    assert "## GPS outages" in md and "by length" not in md and "ATE (outage)" not in md
    assert math.isfinite(loaded.results["outages"]["cv"]["scores"]["fde_mean_m"])
