"""The fast harness of `bench run`: figures drawn in forked processes give the same files
as in-process, a child's failure comes back to the parent, recordings load in parallel in
their order, the costliest drives start first without changing the results, and the CLI
runs OpenBLAS on one thread."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_plots import make_traces, res_for

from posbench.config import RunConfig
from posbench.figures.writer import write_plots
from posbench.pipeline.jobs import FigureJobs, Job, can_fork
from posbench.replay.runner import replay_cost, run
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders import iter_load_many
from posbench.scenarios.synthetic import default_drives
from posbench.scoring.records import all_traces

needs_fork = pytest.mark.skipif(not can_fork(), reason="no fork on this platform")


def _files(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.mark.slow
@needs_fork
def test_figures_drawn_in_children_are_the_same_bytes(tmp_path):
    # PNG and PDF: matplotlib's SVG ids differ even between two drawings in one process
    tr = make_traces(n_fix=120, drives=3)
    here = write_plots(tr, res_for(tr), tmp_path / "here", formats=("png", "pdf"), drive_plots=2)
    jobs = FigureJobs(
        tr, list(res_for(tr)["predictors"]), tmp_path / "forked", ("png", "pdf"), drive_plots=2
    )
    forked = jobs.plots()
    assert [p.relative_to(tmp_path / "forked") for p in forked.files] == [
        p.relative_to(tmp_path / "here") for p in here.files
    ]
    assert forked.notes == here.notes and "error_over_time" in forked.notes  # 2 of 3 drives
    assert len(here.files) > 4
    assert _files(tmp_path / "forked") == _files(tmp_path / "here")
    assert jobs.paper() == []


def test_figures_without_background_are_drawn_when_asked(tmp_path):
    tr = make_traces(n_fix=60, drives=1)
    jobs = FigureJobs(
        tr, ["cv", "kf"], tmp_path, ("png",), paper=lambda: [("f.png", "c")], background=False
    )
    assert not any(tmp_path.iterdir())  # nothing drawn yet
    assert jobs.paper() == [("f.png", "c")]
    assert any(p.name == "error_cdf.png" for p in jobs.plots().files)


def _fail(message: str) -> None:
    raise DataError(Path("drive.csv"), message)


@needs_fork
def test_a_child_exception_is_raised_in_the_parent():
    job = Job(_fail, "bad column t")
    with pytest.raises(DataError, match="drive.csv: bad column t"):
        job.result()


@needs_fork
def test_a_child_that_dies_is_redone_here():
    calls = []

    def work() -> int:
        calls.append(os.getpid())
        if calls[0] != os.getpid():  # in the child: die without an answer
            os._exit(3)
        return 7

    calls.append(os.getpid())  # the parent's pid first
    assert Job(work).result() == 7
    assert calls == [os.getpid(), os.getpid()]  # the child's append is not seen here


@needs_fork
def test_children_run_nicer_than_the_parent():
    from posbench.pipeline.jobs import CHILD_NICENESS

    mine = os.nice(0)
    assert Job(os.nice, 0).result() == min(mine + CHILD_NICENESS, 19)


@needs_fork
def test_traces_written_by_a_child_are_those_save_run_writes(tmp_path):
    from posbench.saved_run.run import Run, save_run, write_traces

    cfg = RunConfig(predictors=("cv", "kf"))
    runs = run(default_drives()[:1], cfg)
    traces = all_traces(runs)
    from posbench.pipeline.results import build_results

    res = build_results(runs, cfg, [], "bench run -p cv,kf", traces=traces)
    here, there = tmp_path / "here", tmp_path / "there"
    save_run(here, Run.from_results(dict(res), traces))
    job = Job(write_traces, there, traces)
    written = save_run(there, Run.from_results(dict(res), traces), traces_written=job.result)
    assert written == [there / "traces.parquet", there / "results.json"]
    assert (there / "traces.parquet").read_bytes() == (here / "traces.parquet").read_bytes()
    assert write_traces(tmp_path / "none", traces.iloc[:0]) is None


def _write_table(path: Path, name: str, n: int) -> None:
    t = np.arange(n, dtype=float) * 0.2
    pd.DataFrame({"stream": "gps", "t": t, "x": 10 * t, "y": 0.0 * t}).to_csv(path, index=False)


def test_parallel_loading_keeps_the_order_and_the_drives(tmp_path):
    for i, n in enumerate((40, 60, 50)):
        _write_table(tmp_path / f"d{i}.csv", f"d{i}", n)
    one = list(iter_load_many([tmp_path], workers=1))
    two = list(iter_load_many([tmp_path / "d2.csv", tmp_path], workers=2))
    assert [d.name for d in one] == ["d0", "d1", "d2"]
    assert [d.name for d in two] == ["d2", "d0", "d1", "d2"]
    for a, b in zip(one, two[1:], strict=True):
        assert np.array_equal(a.gps.t, b.gps.t) and np.array_equal(a.gps.x, b.gps.x)


def _loaded_where(index: int, drive: object) -> int:
    return os.getpid()


def test_a_single_recording_kept_is_loaded_in_a_child(tmp_path):
    # a run's stored drives: even one recording is loaded (and kept) by a child process, so
    # the run's own process never holds a drive's loading peak; without keep it comes back
    _write_table(tmp_path / "a.csv", "a", 40)
    (pid,) = iter_load_many([tmp_path / "a.csv"], workers=2, keep=_loaded_where)
    assert pid != os.getpid()
    (pid,) = iter_load_many([tmp_path / "a.csv"], workers=1, keep=_loaded_where)
    assert pid == os.getpid()


def test_parallel_loading_raises_the_loaders_error(tmp_path):
    _write_table(tmp_path / "a.csv", "a", 40)
    (tmp_path / "b.csv").write_text("stream,t,x\ngps,not-a-number,1\n")
    with pytest.raises(DataError, match="b.csv"):
        list(iter_load_many([tmp_path], workers=2))
    with pytest.raises(DataError, match="no such file"):  # every path checked before loading
        list(iter_load_many([tmp_path, tmp_path / "missing"], workers=2))


@pytest.mark.slow
def test_costliest_drives_first_changes_nothing():
    drives = default_drives()[:3]
    cfg = RunConfig(predictors=("cv", "kf"))
    costs = [replay_cost(d, cfg) for d in drives]
    assert all(c > d.duration_s / cfg.now_step_s for c, d in zip(costs, drives, strict=True))
    order: list[str] = []
    two = run(drives, cfg, workers=2, on_done=lambda r: order.append(r.name))
    one = run(drives, cfg, workers=1)
    assert [r.name for r in two] == [d.name for d in drives]  # drive order, whatever finished
    pd.testing.assert_frame_equal(all_traces(two), all_traces(one))
    assert sorted(order) == sorted(d.name for d in drives)


@pytest.mark.parametrize("preset, expected", [(None, "1"), ("3", "3")])
def test_the_cli_runs_one_blas_thread_unless_told(preset, expected):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if preset:
        env["OPENBLAS_NUM_THREADS"] = preset
    code = (
        "import sys, posbench.cli.app, os; assert 'numpy' in sys.modules; "
        "print(os.environ['OPENBLAS_NUM_THREADS'])"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.strip()
    assert out == expected


def test_score_many_is_the_concatenation_of_score():
    from posbench.replay.prepare import prepare_drive
    from posbench.replay.queries import query_frame
    from posbench.scoring.score import score, score_many

    prep = prepare_drive(default_drives()[0], RunConfig())
    qf, qn = query_frame(prep, "future"), query_frame(prep, "now")
    rng = np.random.default_rng(0)
    ans = {
        n: (rng.normal(size=(len(qf), 2)), rng.normal(size=(len(qn), 2)))
        for n in ("cv", "kf", "lstm@mine")
    }
    ans["cv"][0][3] = np.nan  # no answer
    old = pd.concat(
        [f for n, (a, b) in ans.items() for f in (score(qf, n, a), score(qn, n, b))],
        ignore_index=True,
    )
    new = score_many(
        pd.concat([qf, qn], ignore_index=True),
        [(n, np.concatenate([a, b])) for n, (a, b) in ans.items()],
    )
    pd.testing.assert_frame_equal(new, old, check_exact=True)
    assert score_many(qf, []).empty
    with pytest.raises(ValueError, match="answers for 2 x"):
        score_many(qf, [("a", ans["kf"][0]), ("b", ans["kf"][0][:-1])])


def test_a_long_drive_is_split_by_predictor_and_merged_exactly():
    from posbench.replay.runner import plan_tasks

    drives = default_drives()[:2]
    cfg = RunConfig(predictors=("cv", "kf", "poly"))
    assert plan_tasks(drives[:1], cfg, 2) == [(0, "cv"), (0, "kf"), (0, "poly")]
    fleet = plan_tasks(drives * 4, cfg, 2)  # no drive holds a quarter of the work: whole
    assert sorted(fleet) == [(i, None) for i in range(8)]
    split = run(drives[:1], cfg, workers=2)
    whole = run(drives[:1], cfg, workers=1)
    assert len(split) == 1 and list(split[0].step_ns) == ["cv", "kf", "poly"]
    pd.testing.assert_frame_equal(split[0].traces, whole[0].traces, check_exact=True)
    assert split[0].notes == whole[0].notes and split[0].rejected == whole[0].rejected
    assert run([], cfg, workers=2) == []


def test_preload_imports_in_a_thread_and_swallows_failures():
    import sys

    from posbench.pipeline.preload import MODULES, Preload

    p = Preload(("json.tool", "no_such_module_for_posbench"))
    p.join()  # not started: nothing to wait for
    p.start()
    p.start()  # once
    p.join()
    assert "json.tool" in sys.modules and "no_such_module_for_posbench" not in sys.modules
    assert "matplotlib.figure" in MODULES and "scipy.special" in MODULES
