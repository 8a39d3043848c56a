"""The Ray executor: same figures as the local executor, failures retried then reported.

Needs Ray (``posbench-harness[ray]``, part of ``dev``): skipped without it, but failing when CI is
set.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import fields, replace

import numpy as np
import pandas as pd
import pytest
from helpers import bench

from posbench.config import RunConfig
from posbench.pipeline.results import build_results
from posbench.predictors.registry import available
from posbench.replay.executors import merge_predictor_runs, run_local, run_predictor, run_ray
from posbench.report.markdown import render_markdown
from posbench.scenarios.synthetic import default_drives
from posbench.scoring.records import DriveRun, all_traces

if os.environ.get("CI"):
    import ray  # CI installs the dev extra, which has ray: the test must run there
else:
    ray = pytest.importorskip("ray")

# each Ray start costs ~5 s; the whole file runs in ~45 s; serial: one local Ray at a time
# (its processes and ports), not one per test worker
pytestmark = [pytest.mark.slow, pytest.mark.serial]

CFG = RunConfig(predictors=("cv", "kf"))
LATENCY = ("latency_us", "query_us", "covariance_us")


def error_figures(res: dict) -> str:
    """results.json without what may differ between executors (latencies, command, versions),
    as canonical JSON text: exact floats, and NaN (empty groups) compares equal to NaN."""
    preds = {
        p: {k: v for k, v in e.items() if k not in LATENCY} for p, e in res["predictors"].items()
    }
    keep = {
        "predictors": preds,
        **{
            k: res[k] for k in ("by_dataset", "by_label", "by_speed", "outages", "drives", "config")
        },
    }
    return json.dumps(keep, sort_keys=True, default=float)


@pytest.fixture(scope="module")
def drives():
    return default_drives(seed=0)[:2]


@pytest.fixture(scope="module")
def ray_session():
    """One local Ray instance for the tests below; run_ray uses it and leaves it running."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    yield
    ray.shutdown()


class ExplodingExtra(dict):
    """Drive metadata that makes run_drive raise (it asks for ``truth_poor``), counting the
    attempts in a file. Sent to Ray workers by value (they cannot import this module)."""

    def get(self, key, default=None):
        if key == "truth_poor":
            with open(self["attempts_file"], "a") as f:
                f.write("attempt\n")
            raise RuntimeError("corrupt recording")
        return super().get(key, default)


def test_merge_matches_run_drive(drives):
    """Per-predictor parts merged == one run_drive with every predictor (no Ray needed)."""
    whole = run_local(drives[:1], CFG, workers=1)[0]
    parts = [run_predictor(drives[0], CFG, n, {n: available()[n]}) for n in CFG.predictors]
    merged = merge_predictor_runs(parts)
    for f in fields(DriveRun):
        a, b = getattr(merged, f.name), getattr(whole, f.name)
        if isinstance(a, pd.DataFrame):
            pd.testing.assert_frame_equal(a, b, check_exact=True)
        elif f.name in ("step_ns", "query_ns", "cov_ns"):  # timings: same calls, not the same
            assert {k: len(v) for k, v in a.items()} == {k: len(v) for k, v in b.items()}
            assert list(a) == [p for p in CFG.predictors if p in a]  # cov_ns: those reporting one
            assert f.name == "cov_ns" or list(a) == list(CFG.predictors)
        else:
            assert a == b, f.name


def test_cli_ray_equals_local(cv_kf_run, tmp_path, monkeypatch):
    """`bench run --executor ray` (its own local Ray instance) writes the same error figures
    as `--executor local` (the session's `bench run -p cv,kf`, tests/conftest.py); a missing
    Ray is one line naming the extra."""
    # a new process: the command starts a Ray instance of its own and shuts it down, which
    # in this one would find ray_session's instance (if a test started it) and use that
    r = bench(
        "run",
        "-p",
        "cv,kf",
        "--workers",
        "2",
        "--executor",
        "ray",
        "--plot-format",
        "none",
        "--out",
        tmp_path / "ray",
        columns=200,
        process=True,
        timeout=240,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    res = {
        ex: json.loads((o / "results.json").read_text())
        for ex, o in (("local", cv_kf_run), ("ray", tmp_path / "ray"))
    }
    assert len(res["ray"]["drives"]) == 4
    assert error_figures(res["ray"]) == error_figures(res["local"])
    assert (
        res["ray"]["predictors"]["kf"]["latency_us"]["count"]
        == res["local"]["predictors"]["kf"]["latency_us"]["count"]
    )
    with monkeypatch.context() as m:
        m.setitem(sys.modules, "ray", None)  # `import ray` fails as it does without Ray
        r = bench("run", "--executor", "ray")
    assert r.returncode == 2 and "pip install 'posbench-harness[ray]'" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    r = bench("run", "--address", "auto")
    assert r.returncode == 2 and "--address is for --executor ray" in r.stderr, r.stderr


def test_ray_traces_identical_to_local(drives, ray_session):
    local = run_local(drives, CFG, workers=2)
    done = []
    remote = run_ray(drives, CFG, on_done=lambda r: done.append(r.name))
    assert ray.is_initialized()  # an existing session is used, not shut down
    assert sorted(done) == sorted(d.name for d in drives)
    assert [r.name for r in remote] == [d.name for d in drives]
    for a, b in zip(local, remote, strict=True):
        assert not b.skipped
        pd.testing.assert_frame_equal(a.traces, b.traces, check_exact=True)
        assert list(b.step_ns) == ["cv", "kf"] and len(b.step_ns["kf"]) == len(a.step_ns["kf"])
    la, ra = (build_results(runs, CFG, [], "test") for runs in (local, remote))
    assert error_figures(ra) == error_figures(la)
    assert np.array_equal(
        all_traces(remote)["error_m"].to_numpy(),
        all_traces(local)["error_m"].to_numpy(),
        equal_nan=True,
    )


def test_failed_task_retried_then_reported(drives, ray_session, tmp_path):
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    attempts = tmp_path / "attempts.txt"
    bad = drives[0]
    broken = replace(
        bad,
        meta=replace(
            bad.meta, name="broken-drive", extra=ExplodingExtra(attempts_file=str(attempts))
        ),
    )
    runs = run_ray([broken, drives[1]], CFG, max_retries=1)
    assert [r.name for r in runs] == ["broken-drive", drives[1].name]
    # 2 predictor tasks x (1 try + 1 retry)
    assert attempts.read_text().count("attempt") == 4
    failed = runs[0]
    assert failed.skipped and failed.skipped.startswith("worker failed: predictor cv: ")
    assert "RuntimeError: corrupt recording" in failed.skipped and "2 attempts" in failed.skipped
    assert failed.traces.empty
    assert not runs[1].skipped and set(runs[1].traces["predictor"]) == {"cv", "kf"}
    res = build_results(runs, CFG, [], "test")
    assert res["drives"][0]["skipped"] == failed.skipped
    # the figures are those of the surviving drive alone: nothing of the failed one leaks in
    assert json.dumps(res["predictors"], sort_keys=True) == json.dumps(
        build_results(runs[1:], CFG, [], "test")["predictors"], sort_keys=True
    )
    md = render_markdown(res, [])
    assert "| broken-drive |" in md and "skipped: worker failed" in md
