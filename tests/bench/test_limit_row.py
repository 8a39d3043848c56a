"""How far from the limit: the bound beside every table (issue 38). A kf that knows only what
the bound knows reaches it; the bound is computed once per drive, split or not; results.json
(schema 1.9) carries it and each predictor's x limit, never as a predictor; the terminal,
report.md and the tables show its rows; a predictor below it is named with a reason; a 1.8
file still loads and renders without the row."""

from __future__ import annotations

import copy
import json
import math
from dataclasses import replace

import jsonschema
import numpy as np
import pandas as pd
import pytest
from helpers import bench

from posbench.aggregation.intervals import Statistics, drive_codes
from posbench.aggregation.limit import below_limit, limit_section
from posbench.config import RunConfig
from posbench.metrics.accuracy import summarize, summarize_groups
from posbench.metrics.limit import LIMIT_IMU_NAME, LIMIT_NAME, mean_ci
from posbench.pipeline.results import build_results
from posbench.replay.runner import run, run_drive
from posbench.report.markdown import render_markdown
from posbench.report.table_files import report_tables
from posbench.saved_run.run import SCHEMA_VERSION, Run, load_run, results_schema, save_run
from posbench.scenarios.labels import LABELS
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.schema import scored_mask
from posbench.tables.breakdown_tables import drives_table, label_table
from posbench.tables.run_tables import dataset_table, summary_table

FIXES_ONLY = {"use_imu": False, "use_speed": False}


@pytest.fixture(scope="module")
def drives():
    return [
        generate_drive(seed=0, duration_s=40.0),
        generate_drive(seed=1, route="turns", duration_s=40.0),
    ]


@pytest.fixture(scope="module")
def result(drives):
    cfg = RunConfig(predictors=("cv", "kf"))
    runs = run(drives, cfg, limit=True)
    return runs, build_results(runs, cfg, [], "bench run -p cv,kf", models={})


def test_a_kf_that_knows_what_the_bound_knows_comes_near_it(drives):
    """The fixes-only kf (no IMU, no wheel speed) is above the bound's mean on the same
    queries and within 35 % of it (the bound knows how the jerk varies along the drive,
    the kf's bank only adapts to it); the bound has one row per scored query."""
    cfg = RunConfig(predictors=("kf@fixes",), predictor_options={"kf@fixes": FIXES_ONLY})
    r = run_drive(drives[0], cfg, limit=True)
    scored = r.traces[scored_mask(r.traces)]
    assert len(r.limit) == len(scored)
    for kind in ("future", "now"):
        kf = scored.loc[scored["kind"] == kind, "error_m"].mean()
        bound = r.limit.loc[r.limit["kind"] == kind, "limit_m"].mean()
        assert 1.0 <= kf / bound < 1.35, (kind, kf, bound)
    assert (r.limit["limit_imu_m"] <= r.limit["limit_m"] + 1e-12).all()
    info = r.limit_info
    assert info["slow_added"] and info["q_m2_s5"] > 0 and info["fix_white_var_m2"] == 0.02**2
    assert run_drive(drives[0], cfg).limit is None  # only when asked (bench run asks)


def test_a_drive_split_by_predictor_gets_the_same_bound_once(drives):
    cfg = RunConfig(predictors=("cv", "kf"))
    whole = run_drive(drives[0], cfg, limit=True)
    split = run(drives[:1], cfg, workers=2, limit=True)[0]  # one long drive: per predictor
    pd.testing.assert_frame_equal(split.limit, whole.limit, check_exact=True)
    assert {k: v for k, v in split.limit_info.items() if k != "cost_s"} == {
        k: v for k, v in whole.limit_info.items() if k != "cost_s"
    }


def _whole_rows(runs, datasets, stats):
    """The bound's figures from every drive's rows joined (the oracle of the per-drive
    sums): per scope and kind the summary and the mean's interval, the route types'."""
    joined = pd.concat(
        [r.limit.assign(dataset=r.dataset, drive=r.name) for r in runs], ignore_index=True
    )
    out = {}
    for ds in [None, *datasets]:
        rows = joined if ds is None else joined[joined["dataset"] == ds]
        codes = drive_codes(rows)
        for k in ("future", "now"):
            m = (rows["kind"] == k).to_numpy()
            b = rows["limit_m"].to_numpy(float)[m]
            ci = mean_ci(b, codes[m], rows["t_query"].to_numpy(float)[m], stats.resamples)
            out[(ds, k)] = (summarize(b), ci["mean_m"], ci["clusters"])
            if ds is not None:
                out[(ds, k, "label")] = summarize_groups(
                    b, rows["label"].to_numpy()[m], order=list(LABELS)
                )
    return out


def test_the_bound_figures_are_those_of_its_rows_joined(result, tmp_path):
    """Summed one drive at a time, from held and spilled runs alike, over one data set and
    two: counts, medians, p95s, maxima and the drives' numbers exact, means to rounding, the
    mean's interval exact (no floor measured: not widened); each drive's own entry."""
    runs, res = result
    stats = Statistics(resamples=200)
    spilled = [runs[0].spill(tmp_path, "a"), runs[1]]  # one from disk, one held
    assert spilled[0].limit is None and spilled[0].limit_part
    held, read = copy.deepcopy(res), copy.deepcopy(res)
    a, b = limit_section(runs, held, stats), limit_section(spilled, read, stats)
    assert a is not None and json.dumps(a) == json.dumps(b)  # NaN written alike
    assert json.dumps(held["drives"]) == json.dumps(read["drives"])
    two = [runs[0], replace(runs[1], dataset="other")]
    res2 = copy.deepcopy(res)
    res2["by_dataset"] = {"synthetic": res["by_dataset"]["synthetic"], "other": {}}
    c = limit_section(two, res2, stats)
    for section, mine, datasets in ((a, runs, ["synthetic"]), (c, two, ["synthetic", "other"])):
        oracle = _whole_rows(mine, datasets, stats)
        for ds in [None, *datasets]:
            scope = section["overall"] if ds is None else section["by_dataset"][ds]
            for k in ("future", "now"):
                whole, ci, drives = oracle[(ds, k)]
                got = scope[k]
                for key in ("count", "missing", "median_m", "p95_m", "max_m"):
                    assert got[key] == whole[key], (ds, k, key)
                for key in ("mean_m", "rmse_m"):
                    assert got[key] == pytest.approx(whole[key], rel=1e-12)
                assert got["floor_sd_m"] == 0.0 and got["ci95"]["drives"] == drives
                assert got["ci95"]["mean_m"] == pytest.approx(ci, rel=1e-12)
                if ds is not None:
                    labels = section["by_label"][ds][k]
                    for name, s in oracle[(ds, k, "label")].items():
                        assert labels[name]["count"] == s["count"]
                        if s["count"]:
                            assert labels[name]["median_m"] == s["median_m"]
                            assert labels[name]["p95_m"] == s["p95_m"]
    for d, r in zip(held["drives"], runs, strict=True):
        future = r.limit["limit_m"][r.limit["kind"] == "future"].to_numpy(float)
        assert d["limit"]["future"] == summarize(future)
        assert d["limit"]["slow_added"] == r.limit_info["slow_added"]


def test_results_carry_the_bound_beside_the_predictors_never_as_one(result):
    _, res = result
    saved = Run.from_results(res).results
    assert saved["schema_version"] == SCHEMA_VERSION and int(SCHEMA_VERSION.split(".")[1]) >= 9
    jsonschema.validate(saved, results_schema())
    lim = res["limit"]
    assert lim["name"] == LIMIT_NAME and lim["name_imu"] == LIMIT_IMU_NAME
    assert LIMIT_NAME not in res["predictors"] and "limit" not in res["paired"]["overall"]
    for kind in ("future", "now"):
        bound = lim["by_dataset"]["synthetic"][kind]
        assert bound["count"] == res["by_dataset"]["synthetic"]["kf"][kind]["count"]
        lo, hi = bound["ci95"]["mean_m"]
        assert lo <= bound["mean_m"] <= hi
        for p in ("cv", "kf"):
            ratio = lim["ratios"]["by_dataset"]["synthetic"][p][kind]
            assert ratio == pytest.approx(
                res["by_dataset"]["synthetic"][p][kind]["mean_m"] / bound["mean_m"]
            )
    assert lim["by_dataset"]["synthetic"]["gps_conditions"] == {"rtk": 2}
    for d in res["drives"]:
        assert d["limit"]["future"]["count"] > 0 and d["limit"]["imu"] is not None
        assert "cost_s" not in d["limit"]  # no timing: the same inputs, the same results


def test_tables_and_report_show_the_rows_and_the_ratio(result):
    _, res = result
    res = Run.from_results(res).results
    for t in (
        summary_table(res),
        summary_table(res, compact=True),
        dataset_table(res, "synthetic"),
    ):
        names = list(t.frame["predictor"])
        assert names[-2:] == [LIMIT_NAME, LIMIT_IMU_NAME]
        assert "x limit" in t.header() and "x IMU limit" in t.header()
        row = t.cells()[names.index(LIMIT_NAME)]
        header = t.header()
        assert row[header.index("x limit")] == "-"  # the bound has no ratio, no rank
        assert "[" in row[header.index("future mean [m]")]  # its interval
        if "median" in header:
            assert row[header.index("median")] == "-"
    assert "limit [cm]" in label_table(res, "synthetic", "future").header()
    assert "limit future mean [m]" in drives_table(res).header()
    md = render_markdown(res, [])
    assert f"| {LIMIT_NAME} |" in md and f"The rows `{LIMIT_NAME}`" in md
    assert "- Limit in `synthetic` (2 drives; GPS `rtk` (2))" in md
    assert "**x limit**" in md and "**PCRB**" in md  # the glossary
    for t in report_tables(res):  # every form renders (never a cut number)
        t.csv(), t.latex(), t.markdown()


def test_a_predictor_below_the_bound_is_named_with_a_reason():
    def summ(mean, hi):
        return {"mean_m": mean, "ci95": {"mean_m": [mean - 0.01, hi]}}

    by_dataset = {"d": {"a": {"future": summ(0.05, 0.06), "now": summ(0.2, 0.25)}}}
    bound = {
        "future": {"mean_m": 0.1},
        "now": {"mean_m": 0.1},
        "imu": {"future": {"mean_m": 0.04}, "now": {"mean_m": 0.03}},
    }
    below = below_limit(by_dataset, {"d": bound}, {"d": {"kind": "truth"}})
    assert [(b["predictor"], b["kind"]) for b in below] == [("a", "future")]
    assert below[0]["ratio"] == pytest.approx(0.5)
    assert "if it uses the IMU" in below[0]["reason"]
    bound["imu"]["future"]["mean_m"] = 0.09  # below the IMU variant too
    below = below_limit(by_dataset, {"d": bound}, {"d": {"kind": "fixes"}})
    assert "wheel speed" in below[0]["reason"] and "cubic through" in below[0]["reason"]


def test_schema_1_9_round_trips_and_a_1_8_file_still_loads(result, tmp_path):
    runs, res = result
    from posbench.scoring.records import all_traces

    r = Run.from_results(res, all_traces(runs))
    save_run(tmp_path / "new", r)
    back = load_run(tmp_path / "new")
    assert back.results == json.loads((tmp_path / "new" / "results.json").read_text())
    assert back.results["limit"]["name"] == LIMIT_NAME
    old = json.loads(json.dumps(back.results))
    old["schema_version"] = "1.8"
    del old["limit"]
    for d in old["drives"]:
        del d["limit"]
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "results.json").write_text(json.dumps(old))
    loaded = load_run(tmp_path / "old")
    jsonschema.validate(loaded.results, results_schema())
    md = render_markdown(loaded.results, [])
    assert LIMIT_NAME not in md and "x limit" not in md
    assert "x limit" not in summary_table(loaded.results).header()
    assert "limit [cm]" not in label_table(loaded.results, "synthetic", "now").header()


def test_a_drive_against_its_own_fixes_has_no_slow_floor():
    d = generate_drive(seed=1, route="turns", duration_s=30.0)
    d = replace(d, truth=None, meta=replace(d.meta, name="receiver-only", format="table"))
    r = run_drive(d, RunConfig(predictors=("cv",)), limit=True)
    assert r.limit_info["slow_added"] is False
    assert "white part" in r.limit_info["noise"]  # the synthetic receiver states its sigma
    assert math.isfinite(r.limit_info["q_m2_s5"]) and np.isfinite(r.limit["limit_m"]).all()


@pytest.mark.slow
def test_bench_run_prints_the_rows(tmp_path):
    r = bench(
        "run",
        "--synthetic-duration",
        "30",
        "-p",
        "cv,kf",
        "--plot-format",
        "none",
        "--out",
        tmp_path / "o",
        columns=300,
    )
    assert r.returncode == 0, r.stderr
    assert LIMIT_NAME in r.stdout and "x limit" in r.stdout
    assert f"{LIMIT_NAME}: a bound under stated assumptions, not a predictor" in r.stdout
    assert load_run(tmp_path / "o").results["limit"]["overall"]["future"]["count"] > 0
