"""Answers produced elsewhere: `bench queries` writes the queries and inputs, `bench score`
scores answers from a file exactly as `bench run` scores a predictor.

The central check: a built-in predictor's answers, taken from the traces `bench run` saved,
written to a file and scored by `bench score` give exactly (bit for bit) the error figures
and traces of that `bench run` (same config and seed), with GPS outages, on the synthetic
drives and on a real comma2k19 segment (whose inputs start after t = 0 and whose name is not
a file name).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import assert_one_error_line, bench

from posbench.config import RunConfig
from posbench.offline.answer_scoring import score_answers
from posbench.offline.answers import read_answers
from posbench.offline.queries_folder import (
    KEY_QUERIES,
    MANIFEST,
    drive_ids,
    input_start_s,
    read_queries,
    write_queries,
)
from posbench.replay.prepare import prepare_drive
from posbench.saved_run.run import load_run, results_schema
from posbench.scenarios.drive import ImuStream, SpeedStream
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.table import load_table
from posbench.scenarios.synthetic import default_drives


def ok(r: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    return r


def answers_from_traces(run_dir: Path, q_dir: Path, predictor: str, path: Path) -> int:
    """Write a predictor's answers (and its reported covariance, if any) from a saved run's
    traces as an answers file for the queries folder ``q_dir`` (its drive ids and clock);
    NaN answers are left out (no answer). Returns the number of answers written."""
    tr = load_run(run_dir).traces
    drives = {d["name"]: d for d in json.loads((q_dir / MANIFEST).read_text())["drives"]}
    t = tr[(tr.predictor == predictor) & tr.x.notna() & tr.y.notna()]
    names = t.drive.astype(str)
    ans = pd.DataFrame(
        {
            "drive": names.map(lambda n: drives[n]["drive"]),
            "kind": t.kind.astype(str),
            "t_query": t.t_query - names.map(lambda n: drives[n]["t0_s"]),
            "x": t.x,
            "y": t.y,
        }
    )
    cov = ["cov_xx", "cov_xy", "cov_yy"]
    if t[cov].notna().any(axis=None):  # the reported covariance travels with the answers
        ans[cov] = t[cov]
    if path.suffix == ".parquet":
        ans.to_parquet(path, index=False)
    else:
        ans.to_csv(path, index=False)
    return len(ans)


def assert_same_figures(run_dir: Path, scored_dir: Path, p: str) -> None:
    """Every error figure of predictor ``p`` in the scored run equals that of the replayed
    run exactly (latency aside), and so do the traces and the drive records."""
    a, b = load_run(run_dir), load_run(scored_dir)
    ra, rb = a.results, b.results

    def no_latency(d):
        return {k: v for k, v in d.items() if not k.endswith("_us")}

    assert list(rb["predictors"]) == [p]
    assert no_latency(rb["predictors"][p]) == no_latency(ra["predictors"][p])
    for key in ("by_dataset", "by_label"):
        assert {ds: v[p] for ds, v in rb[key].items()} == {ds: v[p] for ds, v in ra[key].items()}
    assert rb["by_speed"][p] == ra["by_speed"][p]
    assert rb["outages"].get(p) == ra["outages"].get(p)
    for part in ("warmup", "no_reference"):
        assert rb["excluded"][part][p] == ra["excluded"][part][p]
    assert len(rb["drives"]) == len(ra["drives"])
    # counted in build_results for a scored file as for a replay: the same conditions
    assert rb["gps_conditions"] == ra["gps_conditions"] and rb["gps_conditions"]
    for da, db in zip(ra["drives"], rb["drives"], strict=True):
        assert db["predictors"] == ({p: da["predictors"][p]} if da["predictors"] else {})
        for k in (
            "name",
            "dataset",
            "reference",
            "duration_s",
            "gps_fed",
            "notes",
            "warnings",
            "skipped",
        ):
            assert db[k] == da[k], (da["name"], k)
    same_cfg = (
        "horizon_s",
        "now_step_s",
        "gps_profile",
        "gps_latency_s",
        "intervals",
        "dropouts",
        "seed",
        "exclude_poor_truth",
    )
    assert {k: rb["config"][k] for k in same_cfg} == {k: ra["config"][k] for k in same_cfg}
    assert rb["config"]["predictors"] == [p] and rb["data"][:-1] == ra["data"]
    ta = a.traces[a.traces.predictor == p].reset_index(drop=True)
    pd.testing.assert_frame_equal(b.traces, ta)
    import jsonschema

    jsonschema.validate(rb, results_schema())


# ------------------------------------------------------- built-in answers, scored offline
@pytest.fixture(scope="module")
def synthetic_outages(tmp_path_factory):
    """`bench run -p cv,kf` and `bench queries` with the same options (outages), synthetic."""
    d = tmp_path_factory.mktemp("syn")
    opts = ["--dropouts", "outages", "--seed", "3"]
    ok(
        bench(
            "run",
            "-p",
            "cv,kf",
            *opts,
            "--out",
            str(d / "run"),
            "--plot-format",
            "none",
            timeout=600,
        )
    )
    ok(bench("queries", *opts, "--out", str(d / "q")))
    return d


@pytest.mark.slow
@pytest.mark.parametrize("predictor", ["cv", "kf"])
def test_builtin_answers_scored_offline_equal_bench_run(synthetic_outages, predictor):
    d = synthetic_outages
    n = answers_from_traces(d / "run", d / "q", predictor, d / f"{predictor}.csv")
    r = ok(
        bench(
            "score",
            str(d / f"{predictor}.csv"),
            "--queries",
            str(d / "q"),
            "--name",
            predictor,
            "--out",
            str(d / f"s-{predictor}"),
            "--drive-plots",
            "0",
        )
    )
    assert f"{n} answers to {n} queries; every query answered" in " ".join(r.stdout.split())
    res = load_run(d / "run").results
    assert res["outages"][predictor]["scores"], "the run should have GPS outages to compare"
    assert_same_figures(d / "run", d / f"s-{predictor}", predictor)
    for f in ("report.md", "results.json", "traces.parquet", "error_vs_since_fix.png"):
        assert (d / f"s-{predictor}" / f).is_file(), f


@pytest.mark.slow
@pytest.mark.shared
def test_real_drive_scored_offline_equals_bench_run(comma_dir, tmp_path):
    """comma2k19: inputs start 32 ms after the drive's t = 0 and the drive's name holds a
    '/', so the public files use another clock and another drive id; Parquet both ways."""
    opts = ["--data", str(comma_dir), "--dropouts", "outages"]
    ok(
        bench(
            "run",
            "-p",
            "cv",
            *opts,
            "--out",
            str(tmp_path / "run"),
            "--plot-format",
            "none",
            timeout=600,
        )
    )
    ok(bench("queries", *opts, "--out", str(tmp_path / "q"), "--file-format", "parquet"))
    man = json.loads((tmp_path / "q" / MANIFEST).read_text())
    (d,) = man["drives"]
    assert d["t0_s"] > 0 and d["drive"] != d["name"] and "/" not in d["drive"]
    answers_from_traces(tmp_path / "run", tmp_path / "q", "cv", tmp_path / "a.parquet")
    ok(
        bench(
            "score",
            str(tmp_path / "a.parquet"),
            "--queries",
            str(tmp_path / "q"),
            "--name",
            "cv",
            "--out",
            str(tmp_path / "s"),
            "--plot-format",
            "none",
        )
    )
    assert load_run(tmp_path / "run").results["outages"]["cv"]["scores"]
    assert_same_figures(tmp_path / "run", tmp_path / "s", "cv")


# ----------------------------------------------------------------- the queries folder
def _late_inputs(drive):
    """The drive with IMU and speed from t = 1.5 s on: its first input is a later fix."""
    imu, sp = drive.imu, drive.speed
    m, ms = imu.t >= 1.5, sp.t >= 1.5
    from dataclasses import replace

    return replace(
        drive,
        imu=ImuStream(imu.t[m], imu.ax[m], imu.ay[m], imu.yaw[m], imu.yaw_rate[m]),
        speed=SpeedStream(sp.t[ms], sp.v[ms]),
    )


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_inputs_read_back_with_the_table_reader_on_the_queries_clock(tmp_path, fmt):
    d0, d1 = default_drives()[:2]
    cfg = RunConfig(predictors=(), dropouts="outages", gate=False)
    drives = [d0, _late_inputs(d1)]
    write_queries(drives, cfg, tmp_path, command="test", data=[], fmt=fmt)
    man = json.loads((tmp_path / MANIFEST).read_text())
    assert man["give"] == [f"queries.{fmt}", "inputs/"] and man["keep"] == ["key/"]
    queries = (
        pd.read_csv(tmp_path / "queries.csv")
        if fmt == "csv"
        else pd.read_parquet(tmp_path / "queries.parquet")
    )
    assert list(queries.columns) == ["drive", "kind", "t_issue", "t_query"]
    key = pd.read_parquet(tmp_path / KEY_QUERIES)
    for drive, listed in zip(drives, man["drives"], strict=True):
        prep = prepare_drive(drive, cfg)
        t0 = input_start_s(drive, prep.gps)
        assert listed["t0_s"] == t0
        back = load_table(tmp_path / listed["inputs"])
        assert back.name == listed["drive"] == drive.name
        assert back.truth is None  # the answer key stays out of the inputs
        # exactly the fed fixes (after dropouts), IMU and speed, on the queries' clock
        np.testing.assert_array_equal(back.gps.t, prep.gps.t - t0)
        np.testing.assert_array_equal(back.gps.x, prep.gps.x)
        np.testing.assert_array_equal(back.gps.y, prep.gps.y)
        for s in ("imu", "speed"):
            a, b = getattr(back, s), getattr(drive, s)
            for f in a.__dataclass_fields__:
                want = b.t - t0 if f == "t" else getattr(b, f)
                np.testing.assert_array_equal(getattr(a, f), want, err_msg=f"{s}.{f}")
        mine = queries[queries.drive == listed["drive"]]
        kq = key[key.drive == drive.name]
        assert len(mine) == len(kq) == listed["queries"]
        np.testing.assert_allclose(
            mine.t_query.to_numpy() + t0, kq.t_query.to_numpy(), rtol=0, atol=1e-12
        )
        # every future query is issued at a fed fix; now queries are asked at their time
        fut = mine[mine.kind == "future"]
        np.testing.assert_array_equal(fut.t_issue.to_numpy(), back.gps.t)
        now = mine[mine.kind == "now"]
        np.testing.assert_array_equal(now.t_issue.to_numpy(), now.t_query.to_numpy())
    late = prepare_drive(drives[1], cfg).gps.t[0]
    assert man["drives"][1]["t0_s"] == late > 0  # the late drive's clock starts at its first fix


def test_drive_ids_are_file_names_and_unique():
    assert drive_ids(["a", "seg/40", "seg:40", "Seg_40", " x "]) == [
        "a",
        "seg_40",
        "seg_40-2",
        "Seg_40-3",
        "x",
    ]


# --------------------------------------------------------------- answers, matching, missing
@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A queries folder of two synthetic drives and cv's answers (from a replay)."""
    from posbench.predictors.registry import create
    from posbench.replay.loop import replay
    from posbench.replay.queries import query_frame

    d = tmp_path_factory.mktemp("small")
    drives = default_drives()[:2]
    cfg = RunConfig(predictors=(), gate=False)
    write_queries(drives, cfg, d / "q", command="test", data=[])
    rows = []
    for drive in drives:
        prep = prepare_drive(drive, cfg)
        res = replay(create("cv"), prep, cfg.horizon_s)
        for kind, xy in (("future", res.future_xy), ("now", res.now_xy)):
            q = query_frame(prep, kind)
            rows.append(
                pd.DataFrame(
                    {
                        "drive": drive.name,
                        "kind": kind,
                        "t_query": q.t_query,
                        "x": xy[:, 0],
                        "y": xy[:, 1],
                    }
                )
            )
    ans = pd.concat(rows, ignore_index=True)
    ans = ans[ans.x.notna()].reset_index(drop=True)
    ans.to_csv(d / "all.csv", index=False)
    return d, ans


def test_unanswered_queries_are_counted_as_missing_never_dropped(small, tmp_path):
    from posbench.pipeline.results import build_results
    from posbench.scoring.records import all_traces
    from posbench.scoring.schema import scored_mask

    d, ans = small
    folder = read_queries(d / "q")
    full = score_answers(folder, read_answers(d / "all.csv"), "cv")
    assert full.missing == 0 and full.answered == len(ans)
    tr = all_traces(full.runs)
    pick = tr[(tr.kind == "now") & scored_mask(tr) & (tr.index % 7 == 0)]
    gone = ans.merge(pick[["drive", "t_query"]].assign(kind="now"), how="left", indicator=True)
    gone["drive"] = gone["drive"].astype(str)
    some = gone[gone["_merge"] == "left_only"].drop(columns="_merge")
    assert len(some) == len(ans) - len(pick)
    some.to_csv(tmp_path / "some.csv", index=False)
    part = score_answers(folder, read_answers(tmp_path / "some.csv"), "cv")
    assert part.missing == len(pick) and part.answered == len(some)
    assert {n: m["now"] for n, m in part.unanswered.items()} == pick.groupby(
        "drive", observed=True
    ).size().to_dict()
    cfg = folder.config("cv")
    res = build_results(part.runs, cfg, [], "t", traces=all_traces(part.runs), models={})
    full_now = build_results(full.runs, cfg, [], "t", traces=tr, models={})["predictors"]["cv"][
        "now"
    ]
    now = res["predictors"]["cv"]["now"]
    assert now["missing"] == len(pick) and now["count"] == full_now["count"] - len(pick)
    assert res["predictors"]["cv"]["future"]["missing"] == 0
    notes = [n for r in part.runs for n in r.notes if "without an answer" in n]
    assert len(notes) == len(part.unanswered)


def test_times_match_within_a_microsecond(small, tmp_path):
    d, ans = small
    folder = read_queries(d / "q")
    a9 = ans.copy()
    a9.to_csv(tmp_path / "nine.csv", index=False, float_format="%.9f")
    s = score_answers(folder, read_answers(tmp_path / "nine.csv"), "cv")
    assert s.missing == 0  # 9 decimals: every answer still finds its query
    a9["t_query"] = a9["t_query"] + 2e-6
    a9.iloc[:3].to_csv(tmp_path / "off.csv", index=False)
    with pytest.raises(DataError, match=r"line 2: no query of drive .* within 1e-06 s"):
        score_answers(folder, read_answers(tmp_path / "off.csv"), "cv")


def test_latency_column_becomes_the_latency_figures(small, tmp_path):
    d, ans = small
    a = ans.assign(latency_us=np.where(ans.kind == "future", 250.0, 4.0))
    a.loc[a.index[:5], "latency_us"] = np.nan  # not timed
    a.to_csv(tmp_path / "lat.csv", index=False)
    s = score_answers(read_queries(d / "q"), read_answers(tmp_path / "lat.csv"), "cv")
    steps = np.concatenate([r.step_ns["cv"] for r in s.runs])
    queries = np.concatenate([r.query_ns["cv"] for r in s.runs])
    assert (steps == 250_000).all() and (queries == 4_000).all()
    assert steps.size + queries.size == len(a) - 5


# -------------------------------------------------------------- one-line errors, exit 2
def _answers(small, tmp_path, edit=None, text=None) -> Path:
    d, ans = small
    path = tmp_path / "answers.csv"
    if text is not None:
        path.write_text(text)
        return path
    a = ans.iloc[:6].copy()
    a = edit(a) if edit else a
    a.to_csv(path, index=False)
    return path


CASES = {
    "duplicate": (
        lambda a: pd.concat([a, a.iloc[[2]]]),
        ["line 8: a second answer to the query answered on line 4"],
    ),
    "nan x": (
        lambda a: a.assign(x=[0.0, 1.0, np.nan, 3.0, 4.0, 5.0]),
        ["line 4, column 'x': missing or non-finite", "leave the row out"],
    ),
    "inf y": (
        lambda a: a.assign(y=[0.0, np.inf, 2.0, 3.0, 4.0, 5.0]),
        ["line 3, column 'y': missing or non-finite"],
    ),
    "missing column": (
        lambda a: a.drop(columns=["y", "t_query"]),
        ["missing column(s) t_query, y"],
    ),
    "wrong type": (
        lambda a: a.assign(x=["0", "1", "2", "east", "4", "5"]),
        ["line 5, column 'x': not a number: 'east'"],
    ),
    "bad kind": (
        lambda a: a.assign(kind=["future"] * 5 + ["later"]),
        ["line 7, column 'kind': 'later' is not a query kind"],
    ),
    "negative latency": (
        lambda a: a.assign(latency_us=[1.0, 2.0, -3.0, 4.0, 5.0, 6.0]),
        ["line 4, column 'latency_us'", "not a duration >= 0"],
    ),
    "impossible latency": (  # exit 0 with a RuntimeWarning and a p50 of -9.2e15 us before
        lambda a: a.assign(latency_us=[1.0, 2.0, 3.0, 1e300, 5.0, 6.0]),
        ["line 5, column 'latency_us': 1e+300 us", "over 1e+09 us (1000 s)"],
    ),
    "latency past 1000 s": (
        lambda a: a.assign(latency_us=[1.0, 2.0, 3.0, 4.0, 5.0, 1.5e9]),
        ["line 7, column 'latency_us': 1.5e+09 us", "over 1e+09 us (1000 s)"],
    ),
    "unknown drive": (
        lambda a: a.assign(drive=["synthetic-mixed-s0"] * 5 + ["kitti-42"]),
        [
            "line 7: drive 'kitti-42' is not in the queries folder",
            "its drives: synthetic-mixed-s0, synthetic-turns-s0",
        ],
    ),
    "unknown query": (
        lambda a: a.assign(t_query=a.t_query + np.r_[0, 0, 0, 0.01, 0, 0]),
        ["line 5: no query of drive 'synthetic-mixed-s0'", "nearest:"],
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_answers_are_one_error_line(small, tmp_path, case):
    d, _ = small
    edit, needles = CASES[case]
    path = _answers(small, tmp_path, edit)
    r = bench("score", str(path), "--queries", str(d / "q"), "--out", str(tmp_path / "o"))
    assert_one_error_line(r, str(path), *needles)
    assert not (tmp_path / "o").exists()


def test_queries_folder_problems_are_one_error_line(small, tmp_path):
    import shutil

    d, _ = small
    path = _answers(small, tmp_path)
    out = str(tmp_path / "o")
    r = bench("score", str(path), "--queries", str(tmp_path), "--out", out)
    assert_one_error_line(r, "no manifest.json: not a folder written by `bench queries`")
    q = tmp_path / "q"
    shutil.copytree(d / "q", q)
    man = json.loads((q / MANIFEST).read_text())
    (q / MANIFEST).write_text(json.dumps({**man, "format_version": "2.0"}))
    r = bench("score", str(path), "--queries", str(q), "--out", out)
    assert_one_error_line(r, "format_version 2.0", "write the queries again")
    (q / MANIFEST).write_text(json.dumps(man))
    key = pd.read_parquet(q / KEY_QUERIES)
    key.loc[0, "x_ref"] += 1.0  # a "corrected" reference: the key no longer matches
    key.to_parquet(q / KEY_QUERIES, index=False)
    r = bench("score", str(path), "--queries", str(q), "--out", out)
    assert_one_error_line(r, "reference.parquet: changed since `bench queries` wrote it")
    r = bench("score", str(tmp_path / "nope.csv"), "--queries", str(d / "q"), "--out", out)
    assert_one_error_line(r, "nope.csv: no such file")
    r = bench("score", str(path), "--queries", str(d / "q"), "--name", "my node", "--out", out)
    assert_one_error_line(r, "--name 'my node'")
    r = bench("queries", "--gps-profile", "gold", "--out", out)
    assert_one_error_line(r, "--gps-profile must be one of")
    assert not (tmp_path / "o").exists()


# The offline-scoring example (queries -> answers -> score -> export) lives in
# docs/guides/offline-scoring.md and runs there as a docs example (docs/conftest.py).


def test_help_teaches_the_offline_commands():
    r = ok(bench("queries", "--help"))
    text = " ".join(r.stdout.split())
    for s in (
        "--data PATH",
        "--out DIR",
        "--dropouts PROFILE",
        "--horizon SECONDS",
        "--seed INT",
        "--file-format csv|parquet",
        "t_issue",
        "keep q/key/",
        "Example:",
    ):
        assert s in text, s
    r = ok(bench("score", "--help"))
    text = " ".join(r.stdout.split())
    for s in (
        "--queries DIR",
        "--name NAME",
        "--plot-format FORMATS",
        "within 1e-6 s",
        "9 decimals",
        "counted as missing",
        "look-ahead",
        "latency_us [us]",
        "Example:",
    ):
        assert s in text, s
    assert "<str>" not in text and "<path>" not in text


def test_answers_covariance_columns_checked(tmp_path):
    """cov_xx, cov_xy, cov_yy travel with the answers: all three or none, a covariance
    where given (empty = no uncertainty for that answer), else one error naming the row."""
    base = "drive,kind,t_query,x,y"
    ok_file = tmp_path / "ok.csv"
    ok_file.write_text(
        f"{base},cov_xx,cov_xy,cov_yy\nd,now,0.5,1,2,0.04,0.01,0.09\nd,now,1.0,1,2,,,\n"
    )
    frame = read_answers(ok_file).frame
    np.testing.assert_array_equal(frame["cov_xy"].to_numpy()[:1], [0.01])
    assert frame[["cov_xx", "cov_xy", "cov_yy"]].iloc[1].isna().all()
    partial = tmp_path / "partial.csv"
    partial.write_text(f"{base},cov_xx,cov_yy\nd,now,0.5,1,2,0.04,0.09\n")
    with pytest.raises(DataError, match="cov_xx, cov_yy without cov_xy"):
        read_answers(partial)
    not_psd = tmp_path / "not_psd.csv"
    not_psd.write_text(
        f"{base},cov_xx,cov_xy,cov_yy\nd,now,0.5,1,2,0.04,0.01,0.09\nd,now,1.0,1,2,0.01,0.5,0.01\n"
    )
    with pytest.raises(
        DataError, match="line 3, columns cov_xx, cov_xy, cov_yy: .* is not a covariance"
    ):
        read_answers(not_psd)
