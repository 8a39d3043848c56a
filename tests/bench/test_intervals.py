"""Intervals and the paired comparison in a run: every summary of results.json carries its
ci95, identical predictors compare as exactly equal, --baseline and --seeds end to end,
tables mark conclusive and not-conclusive cells, the glossary comes from the metrics'
DEFINITIONS, and reports written before intervals existed still render."""

from __future__ import annotations

import io
import json
import math
import subprocess

import pandas as pd
import pytest
from helpers import ROOT
from helpers import bench as run_bench

from posbench.aggregation.intervals import Statistics
from posbench.config import RunConfig, default_baseline
from posbench.metrics import bootstrap, outages
from posbench.pipeline.results import build_results
from posbench.replay.runner import run
from posbench.report.markdown import render_markdown
from posbench.saved_run.run import SCHEMA_VERSION, Run, load_run, results_schema
from posbench.scenarios.synthetic import default_drives
from posbench.tables.breakdown_tables import NOT_CONCLUSIVE, label_table
from posbench.tables.run_tables import summary_table
from posbench.tables.stat_tables import paired_table


def bench(*args: str) -> subprocess.CompletedProcess:
    """``bench ARGS`` in this process, 120 columns wide."""
    return run_bench(*args, columns=120)


@pytest.fixture(scope="module")
def twin_run():
    """cv, kf and a second kf (kf@twin: the same filter under another name)."""
    cfg = RunConfig(predictors=("cv", "kf", "kf@twin"))
    runs = run(default_drives(), cfg, workers=2)
    return runs, cfg, build_results(runs, cfg, [], "test")


def summaries(tree, path=""):
    """Every summary dict (count, mean_m, ...) in a results tree, with its path."""
    if isinstance(tree, dict):
        if "mean_m" in tree and "count" in tree:
            yield path, tree
        for k, v in tree.items():
            yield from summaries(v, f"{path}/{k}")
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from summaries(v, f"{path}[{i}]")


@pytest.mark.slow
def test_every_summary_has_an_interval(twin_run):
    runs, _, res = twin_run
    found = list(summaries(Run.from_results(res).results))
    assert len(found) > 100
    for path, s in found:
        ci = s.get("ci95")
        assert ci is not None, path
        if not s["count"]:
            assert ci["drives"] == 0 and ci["mean_m"] == [None, None], path
            continue
        for fig in ("mean_m", "median_m", "p95_m"):
            lo, hi = ci[fig]
            assert lo <= hi, (path, fig, ci)
        assert ci["mean_m"][0] <= s["mean_m"] <= ci["mean_m"][1], (path, s)
        assert ci["drives"] >= 1
        assert (ci["block_len"] is None) == (ci["drives"] > 1), (path, ci)
    overall = res["predictors"]["kf"]["future"]["ci95"]
    assert overall["drives"] == len(runs) and overall["block_len"] is None
    one = res["drives"][0]["predictors"]["kf"]["now"]["ci95"]
    assert one["drives"] == 1 and one["block_len"] >= 1


def test_results_with_intervals_follow_the_schema(twin_run):
    import jsonschema

    _, _, res = twin_run
    r = Run.from_results(res)
    assert r.results["schema_version"] == SCHEMA_VERSION
    jsonschema.validate(r.results, results_schema())
    st = r.results["statistics"]
    assert st["resamples"] >= 1000 and st["level"] == 0.95 and st["baseline"] == "kf"


def test_identical_predictors_compare_as_exactly_equal(twin_run):
    _, _, res = twin_run
    paired = res["paired"]
    assert paired["baseline"] == "kf" and set(paired["overall"]) == {"cv", "kf@twin"}
    entries = [paired["overall"]["kf@twin"][k] for k in ("future", "now")]
    entries += [paired["by_dataset"]["synthetic"]["kf@twin"][k] for k in ("future", "now")]
    entries += [
        e
        for k in ("future", "now")
        for e in paired["by_label"]["synthetic"]["kf@twin"][k].values()
        if e["queries"]
    ]
    for e in entries:
        assert e["diff_m"] == 0.0 and e["ci95"] == [0.0, 0.0], e
        assert e["wins"] == 0 and not e["conclusive"]
    cv = paired["overall"]["cv"]["future"]
    assert cv["diff_m"] == pytest.approx(
        res["predictors"]["cv"]["future"]["mean_m"] - res["predictors"]["kf"]["future"]["mean_m"]
    )
    assert cv["ci95"][0] > 0 and cv["conclusive"] and cv["wins"] == 0
    assert cv["drives"] == 4 and cv["queries"] == res["predictors"]["cv"]["future"]["count"]


def test_baseline_none_and_default(twin_run):
    runs, cfg, _ = twin_run
    res = build_results(runs, cfg, [], "test", statistics=Statistics(baseline=None))
    assert res["paired"]["baseline"] is None and res["paired"]["overall"] == {}
    md = render_markdown(Run.from_results(res).results, [])
    assert "Against the baseline" not in md and bootstrap.DEFINITIONS["wins"] not in md
    assert default_baseline(["cv", "ekf"]) is None and default_baseline(["cv", "kf"]) == "kf"


def test_paired_and_label_tables_mark_what_is_and_is_not_conclusive(twin_run):
    _, _, res = twin_run
    res = json.loads(json.dumps(Run.from_results(res).results))
    cells = dict(zip(paired_table(res).frame["predictor"], paired_table(res).cells(), strict=True))
    assert cells["cv"][1].endswith(" *") and "[" in cells["cv"][1]
    assert not cells["kf@twin"][1].endswith("*")
    # a route-type cell whose interval is wider than its value is marked not conclusive
    turn = res["by_label"]["synthetic"]["kf"]["future"]["turn"]
    turn["ci95"]["mean_m"] = [turn["mean_m"] * 0.1, turn["mean_m"] * 2.5]
    t = label_table(res, "synthetic", "future")
    row = t.cells()[1]
    assert row[0] == "Turn" and f" {NOT_CONCLUSIVE} (" in row[2]
    assert NOT_CONCLUSIVE not in t.cells()[0][2]
    csv = pd.read_csv(io.StringIO(t.csv()))
    assert {"kf [cm] ci95 lo", "kf [cm] ci95 hi", "kf mark", "kf n"} <= set(csv.columns)
    assert csv.loc[1, "kf mark"] == NOT_CONCLUSIVE
    assert csv.loc[1, "kf [cm] ci95 hi"] == pytest.approx(250 * turn["mean_m"])


def test_glossary_is_the_metrics_definitions(twin_run):
    _, _, res = twin_run
    md = render_markdown(Run.from_results(res).results, [])
    glossary = md[md.index("## Glossary") :]
    for text in (
        bootstrap.DEFINITIONS["95 % CI"],
        bootstrap.DEFINITIONS["paired difference"],
        bootstrap.DEFINITIONS["conclusive"],
    ):
        assert text in glossary
    assert outages.DEFINITIONS["ADE"] not in glossary  # no outage figure in this report
    assert md.rstrip().endswith(glossary.rstrip())  # the report ends with it


@pytest.mark.slow
def test_seeds_repeat_the_run_and_report_the_spread(tmp_path):
    import jsonschema

    out = tmp_path / "o"
    r = bench(
        "run",
        "-p",
        "cv,kf",
        "--seeds",
        "2",
        "--out",
        str(out),
        "--workers",
        "1",
        "--plot-format",
        "none",
    )
    assert r.returncode == 0, r.stderr
    res = json.loads((out / "results.json").read_text())
    jsonschema.validate(res, results_schema())
    seeds = res["seeds"]
    assert seeds["seeds"] == [0, 1] and seeds["traces_seed"] == 0 and len(seeds["runs"]) == 2
    first, second = (s["predictors"]["cv"]["future"]["mean_m"] for s in seeds["runs"])
    # the run is the first seed: its mean summed whole there, per drive here (last bits; which
    # depends on the CPU's summation kernels)
    assert first == pytest.approx(res["predictors"]["cv"]["future"]["mean_m"], rel=1e-12)
    assert second != first  # another draw of the GPS noise
    spread = seeds["spread"]["cv"]["future"]["mean_m"]
    assert spread["n"] == 2 and spread["min"] == min(first, second)
    assert spread["sd"] == pytest.approx(abs(first - second) / math.sqrt(2))
    assert seeds["spread"]["cv"]["future"]["diff_m"]["n"] == 2
    md = (out / "report.md").read_text()
    assert "## Repeated over 2 seeds (0, 1)" in md and "from seed 0" in md
    assert "over seeds 0, 1" in r.stdout


def _without_intervals(tree):
    """A results tree as schema 1.0 wrote it: no ci95, paired, statistics or seeds."""
    if isinstance(tree, dict):
        return {
            k: _without_intervals(v)
            for k, v in tree.items()
            if k not in ("ci95", "paired", "statistics", "seeds")
        }
    if isinstance(tree, list):
        return [_without_intervals(v) for v in tree]
    return tree


def test_reports_written_before_intervals_still_render(tmp_path):
    res = _without_intervals(load_run(ROOT / "reports" / "kitti").results)
    res["schema_version"] = "1.0"
    (tmp_path / "results.json").write_text(json.dumps(res))
    old = load_run(tmp_path).results
    assert old["schema_version"] == "1.0" and "paired" not in old
    md = render_markdown(old, [])
    assert "## All drives" in md and "Against the baseline" not in md
    assert not any("[" in c for row in summary_table(old).cells() for c in row)


def test_held_out_paired_leaves_the_training_drives_out(twin_run):
    """A learned predictor trained on one drive: the paired comparison is also given over
    the other drives, with exactly the difference of the means of those drives' queries;
    the table marks the trained predictor in the all-drives comparison only."""
    runs, cfg, _ = twin_run
    trained = runs[0].name
    res = build_results(
        runs,
        cfg,
        [],
        "test",
        models={"cv": {"model": "m.onnx", "bundled": False, "train_drives": [trained]}},
    )
    held = res["paired"]["held_out"]
    assert held["drives"] == sorted(r.name for r in runs[1:])
    entry = held["overall"]["cv"]["future"]
    assert entry["drives"] == len(runs) - 1
    tr = pd.concat([r.traces for r in runs[1:]])
    tr = tr[(tr["kind"] == "future") & ~tr["warmup"] & tr["x_ref"].notna()]
    want = (
        tr.loc[tr["predictor"] == "cv", "error_m"].mean()
        - tr.loc[tr["predictor"] == "kf", "error_m"].mean()
    )
    assert entry["diff_m"] == pytest.approx(want, rel=1e-9)
    assert res["paired"]["overall"]["cv"]["future"]["drives"] == len(runs)
    assert paired_table(res).frame["predictor"].tolist()[0] == "cv *"
    assert paired_table(res, held_out=True).frame["predictor"].tolist()[0] == "cv"
    md = render_markdown(Run.from_results(res).results, [])
    assert "on the held-out drives" in md
