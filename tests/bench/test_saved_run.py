"""A run as data: save_run / load_run, the shipped JSON Schema, scoring as its own step,
the golden synthetic run."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT, bench

from posbench.config import RunConfig
from posbench.pipeline.results import build_results
from posbench.replay.queries import query_frame
from posbench.replay.runner import run, run_drive
from posbench.saved_run.run import SCHEMA_VERSION, Run, load_run, results_schema, save_run
from posbench.scenarios.errors import DataError
from posbench.scenarios.synthetic import default_drives
from posbench.scoring.records import all_traces
from posbench.scoring.schema import TRACE_COLUMNS
from posbench.scoring.score import score


def validate(results: dict) -> None:
    import jsonschema

    jsonschema.validate(results, results_schema())


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    cfg = RunConfig(predictors=("cv", "kf"))
    runs = run(default_drives()[:2], cfg)
    traces = all_traces(runs)
    r = Run.from_results(build_results(runs, cfg, [], "bench run -p cv,kf", traces=traces), traces)
    save_run(out, r)
    return out, r


def test_round_trip_is_exact_and_strict_json(saved):
    out, r = saved
    text = (out / "results.json").read_text()
    assert "NaN" not in text and "Infinity" not in text  # strict JSON for any reader
    back = load_run(out)
    assert back.results == json.loads(text)
    assert back.results["schema_version"] == SCHEMA_VERSION
    assert back._traces is None  # traces load lazily ...
    pd.testing.assert_frame_equal(back.traces, r.traces)  # ... and equal what was saved
    assert list(back.traces.columns) == list(TRACE_COLUMNS)
    assert back.predictors == ["cv", "kf"]
    assert back.provenance["command"] == "bench run -p cv,kf"
    assert back.config["horizon_s"] == 0.2


def test_results_follow_the_shipped_schema(saved):
    out, _ = saved
    validate(json.loads((out / "results.json").read_text()))


def test_schema_rejects_a_broken_results_file(saved):
    import jsonschema

    out, _ = saved
    res = json.loads((out / "results.json").read_text())
    res["predictors"]["cv"]["future"]["count"] = -1
    with pytest.raises(jsonschema.ValidationError):
        validate(res)


def test_summary_is_numeric(saved):
    out, r = saved
    s = load_run(out).summary("future")
    assert list(s.index) == ["cv", "kf"] and s.dtypes.eq(float).all()
    assert s.loc["kf", "mean_m"] == pytest.approx(r.results["predictors"]["kf"]["future"]["mean_m"])


def test_load_run_errors_name_the_file(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        load_run(tmp_path)
    (tmp_path / "results.json").write_text("{not json")
    with pytest.raises(DataError, match="not readable as JSON"):
        load_run(tmp_path)
    (tmp_path / "results.json").write_text(json.dumps({"schema_version": "2.0", "predictors": {}}))
    with pytest.raises(DataError, match="schema_version 2.0"):
        load_run(tmp_path)


def test_scoring_answers_from_a_file_equals_the_live_scoring():
    """Answers given as a table (as another program would write them), shuffled, one
    missing: matched to the queries by drive, kind and time, the same traces result."""
    from posbench.predictors.registry import create
    from posbench.replay.loop import replay
    from posbench.replay.prepare import prepare_drive

    d = default_drives()[2]
    cfg = RunConfig(predictors=("cv",))
    prep = prepare_drive(d, cfg)
    q = query_frame(prep, "now")
    res = replay(create("cv"), prep, cfg.horizon_s)
    live = score(q, "cv", res.now_xy)
    answers = pd.DataFrame(
        {
            "drive": d.name,
            "kind": "now",
            "t_query": q.t_query,
            "x": res.now_xy[:, 0],
            "y": res.now_xy[:, 1],
        }
    )
    answers = answers.sample(frac=1.0, random_state=0).drop(index=answers.index[5])
    from_file = score(q, "cv", answers)
    assert np.isnan(from_file.error_m.iloc[5])
    keep = np.arange(len(q)) != 5
    pd.testing.assert_frame_equal(
        from_file[keep].reset_index(drop=True), live[keep].reset_index(drop=True)
    )
    with pytest.raises(ValueError, match="two answers"):
        score(q, "cv", pd.concat([answers, answers.iloc[:1]]))


def test_runner_traces_are_the_scoring_of_its_answers():
    r = run_drive(default_drives()[0], RunConfig(predictors=("cv",)))
    assert list(r.traces.columns) == list(TRACE_COLUMNS)
    err = np.hypot(r.traces.x - r.traces.x_ref, r.traces.y - r.traces.y_ref)
    np.testing.assert_allclose(r.traces.error_m, err)


# ---------------------------------------------------------------- golden run
#: the error figures of a synthetic run are deterministic for a given seed; onnxruntime and
#: BLAS may differ in the last bits across CPUs, hence a relative tolerance
GOLDEN_RTOL = 1e-6
GOLDEN_ATOL_M = 1e-9
#: the networks run in float32 (onnxruntime), whose kernels differ by CPU (AVX2, AVX-512):
#: their answers, and the figures made of them, agree to float32's precision carried
#: through the recurrence, not float64's (8.1e-6 at most measured on an AVX-512 machine
#: against reports/synthetic, made on AVX2; a few hundred float32 ulps)
GOLDEN_RTOL_FLOAT32 = 5e-5
FLOAT32_PREDICTORS = {"lstm", "hybrid", "lstm-authors"}
NOT_COMPARED = {"command", "versions", "git_commit", "outputs", "paper_figures", "schema_version"}


def _minor(res: dict) -> int:
    return int(str(res.get("schema_version", "1.0")).split(".")[1])


def _compare(a, b, path="", added_ok=False):
    """Yield differences between two results trees; latency figures (``*_us``) are skipped.
    ``added_ok``: ``a`` follows a newer schema MINOR than ``b``, whose added keys (e.g. the
    ``ci95`` of 1.1) ``b`` cannot have; every key ``b`` has must still be in ``a``, equal."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys_a = set(a) & set(b) | (set() if added_ok else set(a))
        if keys_a != set(b):
            yield f"{path}: keys {sorted(keys_a ^ set(b))}"
        for k in set(a) & set(b):
            if k in NOT_COMPARED or k.endswith("_us"):
                continue
            yield from _compare(a[k], b[k], f"{path}/{k}", added_ok)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            yield f"{path}: length {len(a)} vs {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            yield from _compare(x, y, f"{path}[{i}]", added_ok)
    elif isinstance(a, float) and isinstance(b, float):
        learned = not FLOAT32_PREDICTORS.isdisjoint(path.split("/"))
        rtol = GOLDEN_RTOL_FLOAT32 if learned else GOLDEN_RTOL
        if not math.isclose(a, b, rel_tol=rtol, abs_tol=GOLDEN_ATOL_M):
            yield f"{path}: {a!r} vs {b!r}"
    elif a != b:
        yield f"{path}: {a!r} vs {b!r}"


@pytest.mark.slow
def test_golden_synthetic_run_equals_the_committed_report(request, tmp_path):
    """`bench run` on the built-in drives reproduces reports/synthetic/results.json: every
    error figure within GOLDEN_RTOL, every count exact (latency and provenance excluded)."""
    golden = load_run(ROOT / "reports" / "synthetic")
    args = golden.results["command"].split()[2:]  # "bench run ..." as recorded
    out_i = args.index("--out")
    if set(args[:out_i] + args[out_i + 2 :]) <= {"-q", "--quiet"}:
        # `bench run` as it comes (-q changes only what is printed): the session's default
        # run (tests/conftest.py) is that command
        fresh = load_run(request.getfixturevalue("default_run")[2])
    else:
        args[out_i + 1] = str(tmp_path / "o")
        r = bench("run", *args, columns=200)
        assert r.returncode == 0, r.stderr
        fresh = load_run(tmp_path / "o")
    validate(fresh.results)
    assert _minor(fresh.results) >= _minor(golden.results)
    diffs = list(
        _compare(
            fresh.results, golden.results, added_ok=_minor(fresh.results) > _minor(golden.results)
        )
    )
    assert not diffs, "\n".join(diffs[:20])


@pytest.mark.parametrize(
    "name", ["synthetic", "kitti", "all-data", "outages", "aslan-gate", "aslan-no-gate"]
)
def test_committed_reports_follow_the_schema(name):
    validate(load_run(ROOT / "reports" / name).results)
