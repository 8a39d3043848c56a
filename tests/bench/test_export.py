"""`bench export` (a saved run's tracks as TUM or CSV files) and TUM files as `bench score`
answers.

The central check: evo (the trajectory evaluation tool, GPL, used here as a tool only)
reading the exported TUM files computes, per drive and predictor, the run's own figures of
results.json (and report.md's per-drive future mean) to 1e-6 m: translation APE without
alignment over exactly the queries posbench scored, for `now` and `future`, with some
answers missing. evo comes with the dev extra; without it these tests skip on a developer's
machine and fail under CI.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import assert_one_error_line, bench, missing

from posbench.config import RunConfig
from posbench.offline.answer_scoring import score_answers
from posbench.offline.answers import read_answers
from posbench.offline.export import export_run, track_stem
from posbench.offline.queries_folder import MANIFEST, read_queries, write_queries
from posbench.offline.tum import read_tum
from posbench.pipeline.results import build_results
from posbench.replay.runner import run
from posbench.saved_run.run import Run, load_run, save_run
from posbench.scenarios.errors import DataError
from posbench.scenarios.synthetic import default_drives
from posbench.scoring.records import all_traces
from posbench.scoring.schema import scored_mask

OPTIONS = {"dropouts": "outages", "seed": 5}
FIGURES = (("mean_m", "mean"), ("median_m", "median"), ("rmse_m", "rmse"), ("max_m", "max"))
TOL_M = 1e-6


def need_evo():
    """evo's modules, or a skip (a developer's machine) / a failure (CI set) without it."""
    try:
        from evo import main_ape
        from evo.core import metrics, sync
        from evo.tools import file_interface
    except ImportError as e:
        missing(f"evo not installed ({e}; pip install -e '.[dev]' brings it)")
    return main_ape, metrics, sync, file_interface


def ok(r: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    return r


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A saved run (cv, kf; two synthetic drives cut to 25 s, GPS outages) with report.md,
    every 9th scored now answer of cv on the first drive removed (scored as missing), and a
    queries folder of the same drives and options."""
    d = tmp_path_factory.mktemp("export")
    drives = [dr.window(0.0, 25.0) for dr in default_drives()[:2]]
    cfg = RunConfig(predictors=("cv", "kf"), **OPTIONS)
    runs = run(drives, cfg)
    tr = runs[0].traces
    pick = np.flatnonzero(
        ((tr.predictor == "cv") & (tr.kind == "now")).to_numpy() & scored_mask(tr)
    )[::9]
    tr.loc[tr.index[pick], ["x", "y", "error_m", "along_m", "cross_m"]] = np.nan
    traces = all_traces(runs)
    r = Run.from_results(build_results(runs, cfg, [], "test", traces=traces, models={}), traces)
    save_run(d / "run", r)
    r.report(d / "run", drive_plots=0, table_formats=())
    write_queries(drives, RunConfig(predictors=(), **OPTIONS), d / "q", command="test", data=[])
    assert (
        load_run(d / "run").results["drives"][0]["predictors"]["cv"]["now"]["missing"]
        == len(pick)
        > 0
    )
    return d


@pytest.fixture(scope="module")
def tum_dir(saved):
    ok(bench("export", str(saved / "run"), "--format", "tum", "--out", str(saved / "tum")))
    return saved / "tum"


def _drives(run_dir: Path) -> list[dict]:
    return [d for d in load_run(run_dir).results["drives"] if not d["skipped"]]


# ------------------------------------------------------------------------ evo agrees
@pytest.mark.slow
def test_evo_ape_of_the_exported_tracks_is_the_runs_per_drive_figures(saved, tum_dir):
    main_ape, metrics, sync, file_interface = need_evo()
    worst = 0.0
    report = (saved / "run" / "report.md").read_text()
    for d in _drives(saved / "run"):
        for p, kinds in d["predictors"].items():
            for kind, want in kinds.items():
                ref = tum_dir / (track_stem(d["name"], None, kind) + ".tum")
                est = tum_dir / (track_stem(d["name"], p, kind) + ".tum")
                t_ref = file_interface.read_tum_trajectory_file(str(ref))
                t_est = file_interface.read_tum_trajectory_file(str(est))
                t_ref, t_est = sync.associate_trajectories(t_ref, t_est)  # max_diff 0.01 s
                # exact association: every answer paired with its own query
                np.testing.assert_array_equal(t_ref.timestamps, t_est.timestamps)
                assert t_est.num_poses == want["count"], (d["name"], p, kind)
                res = main_ape.ape(
                    t_ref,
                    t_est,
                    metrics.PoseRelation.translation_part,
                    align=False,
                    correct_scale=False,
                )
                for ours, theirs in FIGURES:
                    diff = abs(res.stats[theirs] - want[ours])
                    worst = max(worst, diff)
                    assert diff <= TOL_M, (d["name"], p, kind, ours, res.stats[theirs], want[ours])
                if kind == "future":  # report.md's per-drive figure: the future mean
                    row = next(
                        ln for ln in report.splitlines() if ln.startswith(f"| {d['name']} |")
                    )
                    assert f"{res.stats['mean']:.3f}" in row, (row, res.stats["mean"])
    print(f"largest difference evo - posbench: {worst:.3g} m")


def test_evo_ape_console_script_prints_the_now_figures(saved, tum_dir, tmp_path):
    need_evo()
    exe = shutil.which("evo_ape") or shutil.which("evo_ape", path=str(Path(sys.executable).parent))
    if exe is None:
        missing("evo_ape console script not found beside this Python")
    d = _drives(saved / "run")[0]
    want = d["predictors"]["kf"]["now"]
    r = ok(
        subprocess.run(
            [
                exe,
                "tum",
                str(tum_dir / f"{d['name']}.reference.tum"),
                str(tum_dir / f"{d['name']}.kf.now.tum"),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            env={**os.environ, "HOME": str(tmp_path)},
        )
    )
    printed = dict(re.findall(r"^\s*(\w+)\s+([-\d.e+]+)\s*$", r.stdout, re.M))
    assert "not aligned" in r.stdout
    for ours, theirs in FIGURES:  # printed with 6 decimals
        assert abs(float(printed[theirs]) - want[ours]) <= 5e-7 + 1e-12, (theirs, printed)


# ------------------------------------------------------------------- what is written
def test_export_writes_the_scored_rows_and_says_so(saved, tum_dir):
    r = load_run(saved / "run")
    tr = r.traces[scored_mask(r.traces)]
    names = sorted(p.name for p in tum_dir.iterdir())
    expect = sorted(
        f"{track_stem(d['name'], p, k)}.tum"
        for d in _drives(saved / "run")
        for p in (None, "cv", "kf")
        for k in ("now", "future")
    )
    assert names == expect
    for d in _drives(saved / "run"):
        for kind in ("now", "future"):
            mine = tr[(tr.drive == d["name"]) & (tr.kind == kind)]
            ref = read_tum(tum_dir / f"{track_stem(d['name'], None, kind)}.tum")
            assert ref.drive == d["name"]
            q = mine[mine.predictor == "kf"].sort_values("t_query")
            np.testing.assert_array_equal(ref.t, q.t_query.to_numpy())
            np.testing.assert_array_equal(ref.x, q.x_ref.to_numpy())
            np.testing.assert_array_equal(ref.y, q.y_ref.to_numpy())
    lines = (
        (tum_dir / f"{track_stem(_drives(saved / 'run')[0]['name'], 'kf', 'now')}.tum")
        .read_text()
        .splitlines()
    )
    pose = next(ln for ln in lines if not ln.startswith("#")).split(" ")
    assert len(pose) == 8 and pose[3:] == ["0.0", "0.0", "0.0", "0.0", "1.0"]


def test_csv_export_round_trips_the_traces(saved, tmp_path):
    r = ok(bench("export", str(saved / "run"), "-f", "csv", "-o", str(tmp_path)))
    assert "12 CSV files" in " ".join(r.stdout.split())
    run_ = load_run(saved / "run")
    tr = run_.traces[scored_mask(run_.traces)]
    for d in _drives(saved / "run"):
        for kind in ("now", "future"):
            ref = pd.read_csv(tmp_path / f"{track_stem(d['name'], None, kind)}.csv")
            assert list(ref.columns) == ["t", "x", "y", "drive", "kind"]
            q = tr[(tr.drive == d["name"]) & (tr.kind == kind) & (tr.predictor == "kf")]
            np.testing.assert_array_equal(
                ref[["t", "x", "y"]].to_numpy(), q[["t_query", "x_ref", "y_ref"]].to_numpy()
            )
            assert set(ref.drive) == {d["name"]} and set(ref.kind) == {kind}
            for p in ("cv", "kf"):
                got = pd.read_csv(tmp_path / f"{track_stem(d['name'], p, kind)}.csv")
                assert list(got.columns) == [
                    "t",
                    "x",
                    "y",
                    "drive",
                    "predictor",
                    "kind",
                    "t_issue",
                    "error_m",
                ]
                a = tr[
                    (tr.drive == d["name"]) & (tr.kind == kind) & (tr.predictor == p) & tr.x.notna()
                ]
                np.testing.assert_array_equal(
                    got[["t", "x", "y", "t_issue", "error_m"]].to_numpy(),
                    a[["t_query", "x", "y", "t_issue", "error_m"]].to_numpy(),
                )
                assert set(got.predictor) == {p} and set(got.kind) == {kind}
                # the run's figures, from the file: count and mean
                want = d["predictors"][p][kind]
                assert len(got) == want["count"]
                assert abs(got.error_m.mean() - want["mean_m"]) <= 1e-12


def test_a_track_without_rows_is_left_out(saved, tmp_path):
    r = load_run(saved / "run")
    tr = r.traces.copy()
    tr.loc[(tr.predictor == "cv") & (tr.kind == "future"), ["x", "y"]] = np.nan
    done = export_run(Run(r.results, saved / "run", tr), tmp_path, "tum")
    names = [d["name"] for d in _drives(saved / "run")]
    assert done.empty == [f"{n}.cv.future" for n in names]
    assert done.drives == names and len(done.files) == 10 and len(done.pairs) == 6


# ----------------------------------------------------------- TUM answers, bench score
@pytest.mark.slow
def test_exported_now_track_scored_by_bench_score_gives_the_runs_figures(saved, tum_dir):
    man = json.loads((saved / "q" / MANIFEST).read_text())
    assert all(d["t0_s"] == 0 for d in man["drives"])  # the queries' clock is the run's
    run_res = load_run(saved / "run").results
    for i, d in enumerate(_drives(saved / "run")):
        for p in ("cv", "kf"):
            out = saved / f"scored-{p}-{i}"
            r = ok(
                bench(
                    "score",
                    str(tum_dir / f"{d['name']}.{p}.now.tum"),
                    "--queries",
                    str(saved / "q"),
                    "--name",
                    p,
                    "--out",
                    str(out),
                    "--drive-plots",
                    "0",
                    "--plot-format",
                    "png",
                )
            )
            assert "queries without an answer" in " ".join(r.stdout.split())
            res = load_run(out).results
            got = {e["name"]: e["predictors"] for e in res["drives"]}
            assert got[d["name"]][p]["now"] == run_res["drives"][i]["predictors"][p]["now"]
            others = [n for n in got if n != d["name"]]
            assert all(got[n][p]["now"]["count"] == 0 for n in others)
            assert res["answers"]["file"].endswith(".now.tum")


def test_exported_track_on_a_later_queries_clock_scores_as_the_run(tmp_path):
    """A drive whose inputs start after its t = 0 (queries folder ``t0_s`` > 0): the exported
    file says it is on the run's clock (``# clock: run``) and ``bench score`` moves it onto
    the folder's, so the round trip still gives the run's figures."""
    drive = default_drives()[0].window(7.3, 30.0)
    cfg = RunConfig(predictors=("kf",), seed=2)
    runs = run([drive], cfg)
    traces = all_traces(runs)
    r = Run.from_results(build_results(runs, cfg, [], "test", traces=traces, models={}), traces)
    save_run(tmp_path / "run", r)
    write_queries(
        [drive], RunConfig(predictors=(), seed=2), tmp_path / "q", command="test", data=[]
    )
    man = json.loads((tmp_path / "q" / MANIFEST).read_text())
    assert man["drives"][0]["t0_s"] > 7.0
    ok(bench("export", str(tmp_path / "run"), "--out", str(tmp_path / "tum")))
    f = tmp_path / "tum" / f"{drive.name}.kf.now.tum"
    assert "# clock: run" in f.read_text()
    s = score_answers(read_queries(tmp_path / "q"), read_answers(f), "kf")
    got = all_traces(s.runs)
    want = traces[(traces.kind == "now") & scored_mask(traces)]
    assert s.answered == len(want)
    np.testing.assert_array_equal(
        np.sort(got.loc[got.x.notna(), "error_m"].to_numpy()), np.sort(want["error_m"].to_numpy())
    )


def test_tum_drive_from_the_file_name_when_no_comment(saved, tum_dir, tmp_path):
    d = _drives(saved / "run")[1]["name"]
    body = [
        ln
        for ln in (tum_dir / f"{d}.kf.now.tum").read_text().splitlines()
        if not ln.startswith("#")
    ]
    path = tmp_path / f"{d}.mine.tum"
    path.write_text("\n".join(body) + "\n")
    a = read_answers(path)
    assert a.is_tum and a.tum_drive is None and (a.frame.kind == "now").all()
    s = score_answers(read_queries(saved / "q"), a, "kf")
    tr = all_traces(s.runs)
    want = load_run(saved / "run").traces
    want = want[
        (want.predictor == "kf") & (want.drive == d) & (want.kind == "now") & scored_mask(want)
    ]
    got = tr[(tr.drive == d) & (tr.kind == "now") & tr.x.notna()]
    drop = ["predictor", "cov_xx", "cov_xy", "cov_yy"]  # a TUM file carries no covariance
    assert got[drop[1:]].isna().all(axis=None)
    pd.testing.assert_frame_equal(
        got.drop(columns=drop).reset_index(drop=True),
        want.drop(columns=drop).reset_index(drop=True),
        check_categorical=False,
    )
    assert s.answered == len(body)


def test_read_tum_reads_whitespace_comments_and_ignores_z_and_orientation(tmp_path):
    p = tmp_path / "a.tum"
    p.write_text(
        "# a comment\n\n  1.5\t2.0  3.0 9 0.1 0.2 0.3 0.9\n# drive: seg/40\n2.5 -1e-3 4 0 0 0 0 1\n"
    )
    t = read_tum(p)
    np.testing.assert_array_equal(t.t, [1.5, 2.5])
    np.testing.assert_array_equal(t.x, [2.0, -1e-3])
    np.testing.assert_array_equal(t.y, [3.0, 4.0])
    np.testing.assert_array_equal(t.line, [3, 5])
    assert t.drive == "seg/40"
    with pytest.raises(DataError, match="no poses"):
        (tmp_path / "e.tum").write_text("# nothing\n")
        read_tum(tmp_path / "e.tum")


# ------------------------------------------------------------- one-line errors, exit 2
def _tum(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


SCORE_CASES = {
    "columns": (
        "synthetic-mixed-s0.x.tum",
        "# drive: synthetic-mixed-s0\n1.0 0 0 0 0 0 0 1\n1.05 0 0 0 0 1\n",
        ["line 3: 6 columns, a TUM line has 8"],
    ),
    "not a number": (
        "synthetic-mixed-s0.tum",
        "1.0 0 east 0 0 0 0 1\n",
        ["line 1: 'east' is not a number"],
    ),
    "no drive": (
        "answers.tum",
        "1.0 0 0 0 0 0 0 1\n",
        ["cannot tell which drive it answers", "synthetic-mixed-s0, synthetic-turns-s0"],
    ),
    "unknown drive": (
        "a.tum",
        "# drive: kitti-42\n1.0 0 0 0 0 0 0 1\n",
        ["'# drive: kitti-42' names no drive"],
    ),
    "no such time": (
        "synthetic-turns-s0.tum",
        "# c\n1700000000.25 0 0 0 0 0 0 1\n",
        [
            "line 2: no query of drive 'synthetic-turns-s0', kind now at t_query 1700000000.25 s",
            "not Unix time",
        ],
    ),
}


@pytest.mark.parametrize("case", list(SCORE_CASES))
def test_bad_tum_answers_are_one_error_line(saved, tmp_path, case):
    name, text, needles = SCORE_CASES[case]
    path = _tum(tmp_path, name, text)
    r = bench("score", str(path), "--queries", str(saved / "q"), "--out", str(tmp_path / "o"))
    assert_one_error_line(r, str(path), *needles)
    assert not (tmp_path / "o").exists()


def test_export_mistakes_are_one_error_line(saved, tmp_path):
    r = bench("export", str(saved / "q"), "--out", str(tmp_path / "o"))
    assert_one_error_line(r, "results.json: no such file")
    r = bench("export", str(saved / "run"), "--format", "kml", "--out", str(tmp_path / "o"))
    assert_one_error_line(r, "--format kml", "tum, csv")
    (tmp_path / "file").write_text("x\n")
    r = bench("export", str(saved / "run"), "--out", str(tmp_path / "file" / "sub"))
    assert_one_error_line(r, "--out", "is a file")
    r = bench("export", str(saved / "run"))
    assert_one_error_line(r, "--out", "bench export --help")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_export_help_teaches():
    r = ok(bench("export", "--help"))
    text = " ".join(r.stdout.split())
    for s in (
        "RUN_DIR",
        "--out DIR",
        "--format tum|csv",
        "evo_ape tum",
        "reference.future.tum",
        "identity quaternion",
        "local ENU",
        "Example:",
        "not Unix time",
    ):
        assert s in text, s
    r = ok(bench("score", "--help"))
    assert "TUM" in r.stdout and "# drive:" in " ".join(r.stdout.split())
