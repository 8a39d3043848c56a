"""What a run scores and writes: warm-up kept out of the headline, honest counts, model
names and aliases, trained-on marks, the output folder, every drive skipped."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import bench as run_bench
from helpers import without_timings

from posbench.config import RunConfig
from posbench.pipeline.results import build_results
from posbench.replay.runner import run, run_drive
from posbench.report.markdown import render_markdown
from posbench.scenarios.synthetic import default_drives
from posbench.scoring.schema import scored_mask
from posbench.tables.breakdown_tables import label_table


def bench(*args: str, cwd: Path | None = None, columns: int = 200) -> subprocess.CompletedProcess:
    """``bench ARGS`` in this process, at a terminal ``columns`` wide."""
    return run_bench(*args, cwd=cwd, columns=columns)


@pytest.fixture(scope="module")
def cv_kf_result():
    drives = default_drives()
    cfg = RunConfig(predictors=("cv", "kf"))
    runs = run(drives, cfg)
    return runs, build_results(runs, cfg, [], "test")


def test_warmup_is_the_queries_before_the_second_fix():
    r = run_drive(default_drives()[0], RunConfig(predictors=("cv",)))
    tr = r.traces
    fut = tr[tr.kind == "future"].sort_values("t_issue")
    second_fix = fut.t_issue.iloc[1]
    assert fut.warmup.iloc[0] and not fut.warmup.iloc[1:].any()
    now = tr[tr.kind == "now"]
    assert (now.warmup == (now.t_issue < second_fix)).all()
    assert now.warmup.sum() >= 1


def test_headline_excludes_the_cold_start(cv_kf_result):
    runs, res = cv_kf_result
    # the cold start (one fix, no velocity) scored ~3 m max on every drive; past warm-up it is gone
    for p in ("cv", "kf"):
        assert res["predictors"][p]["future"]["max_m"] < 1.0, res["predictors"][p]["future"]
        warm = res["excluded"]["warmup"][p]
        assert warm["future"]["count"] == len(runs)  # one future query per drive: at its first fix
        assert warm["future"]["max_m"] > 1.0  # ... and that is where the 3 m errors went
    total = sum(len(r.traces[r.traces.predictor == "cv"]) for r in runs)
    counted = sum(
        res["predictors"]["cv"][k]["count"] + res["predictors"]["cv"][k]["missing"]
        for k in ("future", "now")
    )
    excluded = sum(
        res["excluded"]["warmup"]["cv"][k]["count"] + res["excluded"]["warmup"]["cv"][k]["missing"]
        for k in ("future", "now")
    ) + sum(res["excluded"]["no_reference"]["cv"].values())
    assert counted + excluded == total  # every query is in exactly one place


def test_missing_counts_only_unanswered_queries_with_a_reference():
    tr = pd.DataFrame(
        {
            "x_ref": [0.0, np.nan, 1.0, 2.0],
            "y_ref": [0.0, 0.0, 1.0, 2.0],
            "warmup": [False, False, True, False],
        }
    )
    assert scored_mask(tr).tolist() == [True, False, False, True]


def test_now_route_table_has_no_paper_column(cv_kf_result):
    _, res = cv_kf_result
    fut = label_table(res, "synthetic", "future").markdown()
    now = label_table(res, "synthetic", "now").markdown()
    assert "paper LSTM" in fut and "46 (Kalman)" in fut
    assert "paper" not in now and "46" not in now.splitlines()[-1]


def test_report_explains_missing_and_exclusions(cv_kf_result):
    _, res = cv_kf_result
    md = render_markdown(res, [])
    assert "`missing`:" in md and "warm-up queries" in md
    assert "## Warm-up queries (left out above)" in md


def test_alias_runs_a_second_instance_under_its_own_name():
    from posbench.predictors.registry import create
    from posbench.replay.predictor_setup import validate_predictors, with_model_aliases

    names = with_model_aliases(("cv", "kf"), {"kf@b": {}})
    assert names == ("cv", "kf", "kf@b")
    assert validate_predictors(names, {"kf@b": {}}) == {"kf@b": {}}
    assert type(create("kf@b")) is type(create("kf"))
    d = default_drives()[2]
    res = run_drive(d, RunConfig(predictors=("kf", "kf@b")))
    a = res.traces[res.traces.predictor == "kf"].error_m.to_numpy()
    b = res.traces[res.traces.predictor == "kf@b"].error_m.to_numpy()
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("bad", ["nope@x", "kf@", "kf@b,nope"])
def test_alias_of_unknown_predictor_is_refused(bad):
    from posbench.checks import parse_predictor_names
    from posbench.errors import UsageError
    from posbench.replay.predictor_setup import validate_predictors

    with pytest.raises(UsageError, match="unknown predictor"):
        validate_predictors(parse_predictor_names(bad), {})


def test_model_for_a_predictor_not_in_the_run_is_refused():
    from posbench.errors import UsageError
    from posbench.replay.predictor_setup import validate_predictors, with_model_aliases

    opts = {"lstm": {"model": "x"}}
    with pytest.raises(UsageError, match="lstm@NAME=PATH"):
        validate_predictors(with_model_aliases(("cv",), opts), opts)


def _model_copy(tmp_path: Path, train_drives: list[str]) -> Path:
    from posbench.predictors.lstm.predictor import bundled_model

    src = bundled_model().parent
    dst = tmp_path / "my-model"
    shutil.copytree(src, dst)
    info = json.loads((dst / "model.json").read_text())
    info.setdefault("data", {})["train_drives"] = train_drives
    (dst / "model.json").write_text(json.dumps(info))
    return dst


@pytest.mark.slow
def test_two_models_of_one_predictor_named_and_marked(tmp_path):
    """--model lstm@mine=DIR beside the bundled lstm: both in the tables, the report names
    each model, rows trained on some of the run's drives are marked and a held-out table
    follows in the terminal too."""
    model = _model_copy(tmp_path, ["synthetic-mixed-s0", "synthetic-turns-s0"])
    out = tmp_path / "o"
    r = bench(
        "run",
        "-p",
        "cv,lstm",
        "--model",
        f"lstm@mine={model}",
        "--out",
        str(out),
        "--workers",
        "1",
        "--plot-format",
        "none",
    )
    assert r.returncode == 0, r.stderr
    res = json.loads((out / "results.json").read_text())
    assert list(res["predictors"]) == ["cv", "lstm", "lstm@mine"]
    assert res["models"]["lstm@mine"]["model"] == str(model / "model.onnx")
    assert res["models"]["lstm"]["bundled"]
    assert "lstm@mine *" in r.stdout
    assert "* lstm@mine (model " + str(model / "model.onnx") in r.stdout.replace("\n", " ")
    assert "held-out 2 drives" in r.stdout
    md = (out / "report.md").read_text()
    assert "`lstm@mine` (model " + str(model / "model.onnx") + ") was trained on" in md
    assert "The bundled `lstm` was trained" not in md
    # identical weights: the alias scores exactly what the bundled model scores
    assert res["predictors"]["lstm"]["future"] == res["predictors"]["lstm@mine"]["future"]


@pytest.mark.slow
def test_rerun_into_the_same_folder_replaces_only_its_own_files(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "my-notes.txt").write_text("keep me")
    (out / "results.json").write_text(
        json.dumps({"outputs": ["old_plot.png", "../outside.txt", "drives/x.png"]})
    )
    (out / "old_plot.png").write_bytes(b"x")
    (out / "drives").mkdir()
    (out / "drives" / "x.png").write_bytes(b"x")
    (tmp_path / "outside.txt").write_text("not the run's")
    r = bench("run", "-p", "cv", "--out", str(out), "--workers", "1")
    assert r.returncode == 0, r.stderr
    assert not (out / "old_plot.png").exists() and not (out / "drives" / "x.png").exists()
    assert (out / "my-notes.txt").read_text() == "keep me"
    assert (tmp_path / "outside.txt").exists()
    res = json.loads((out / "results.json").read_text())
    assert "report.md" in res["outputs"] and "results.json" in res["outputs"]
    assert all((out / f).is_file() for f in res["outputs"])
    assert "removed 2 files of an earlier run" in " ".join(r.stdout.split())  # lines wrap
    assert "wrote " in r.stdout and "report.md" in r.stdout


def test_every_drive_skipped_writes_the_report_and_fails(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    import posbench.cli.app as cli
    import posbench.replay.executors as ex
    from posbench.scoring.records import DriveRun

    def all_skipped(drives, cfg, *a, **k):
        return [
            DriveRun(d.name, "synthetic", "", [], [], pd.DataFrame(), skipped="poor truth")
            for d in drives
        ]

    monkeypatch.setattr(ex, "run_drives", all_skipped)
    out = tmp_path / "o"
    r = CliRunner().invoke(cli.app, ["run", "-p", "cv", "--out", str(out)])
    assert r.exit_code == 2
    assert "every drive was skipped (4 drives)" in r.output
    md = (out / "report.md").read_text()
    assert md.count("skipped: poor truth") == 4
    assert not (out / "traces.parquet").exists()
    assert "traces.parquet" not in r.output


def test_thin_drive_still_gets_a_report(tmp_path):
    """A GPS-only CSV with 3 fixes scores nothing: report.md is written with the reason for
    each missing figure, and the run fails in one line saying why (exit 2: a CI job can
    tell)."""
    csv = tmp_path / "three.csv"
    csv.write_text("stream,t,x,y\ngps,0,0,0\ngps,0.2,1,0\ngps,0.4,2,0\n")
    out = tmp_path / "o"
    r = bench("run", "--data", str(csv), "-p", "cv,kf", "--out", str(out), "--workers", "1")
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: no query of any drive could be scored")
    assert "without a reference position" in err[0] and "report.md" in err[0]
    md = (out / "report.md").read_text()
    assert "Not drawn:" in md and "error_cdf:" in md


def test_one_fix_csv_exits_2_naming_the_drive(tmp_path):
    """The issue's case: a one-fix CSV scores nothing; the error names the drive and its one
    fix, report.md is still written."""
    csv = tmp_path / "one.csv"
    csv.write_text("t,lat,lon\n0.0,48.0,11.0\n")
    out = tmp_path / "o"
    r = bench("run", "--data", str(csv), "-p", "cv", "--out", str(out), "--workers", "1")
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "drive one was fed 1 fix" in r.stderr
    assert (out / "report.md").exists()


@pytest.mark.slow
def test_run_table_fits_100_columns_and_cuts_no_number(tmp_path):
    """The full table (--wide), split into pages of at most 100 columns."""
    out = tmp_path / "o"
    r = bench(
        "run",
        "-p",
        "cv,kf-paper",
        "--out",
        str(out),
        "--workers",
        "1",
        "--wide",
        "--plot-format",
        "none",
        columns=100,
    )
    assert r.returncode == 0, r.stderr
    assert "…" not in r.stdout
    assert max(len(line) for line in r.stdout.splitlines()) <= 100
    res = json.loads((out / "results.json").read_text())
    for p in ("cv", "kf-paper"):
        assert f"{res['predictors'][p]['future']['mean_m']:.3f}" in r.stdout
        assert f"{res['predictors'][p]['latency_us']['p99']:.1f}" in r.stdout
    assert "kf-paper" in r.stdout


@pytest.mark.slow
def test_plot_formats(tmp_path):
    out = tmp_path / "o"
    r = bench("run", "-p", "cv", "--out", str(out), "--workers", "1", "--plot-format", "svg,pdf")
    assert r.returncode == 0, r.stderr
    assert (out / "error_cdf.svg").is_file() and (out / "error_cdf.pdf").is_file()
    assert not (out / "error_cdf.png").exists()
    assert "![error_cdf.svg](error_cdf.svg)" in (out / "report.md").read_text()
    res = json.loads((out / "results.json").read_text())
    assert "error_cdf.pdf" in res["outputs"]
    bad = bench("run", "-p", "cv", "--out", str(tmp_path / "b"), "--plot-format", "png,gif")
    assert bad.returncode == 2 and bad.stderr.startswith("error: --plot-format")
    assert not (tmp_path / "b").exists()


@pytest.mark.slow
def test_plot_format_none_writes_every_output_but_the_figures(tmp_path):
    """--plot-format none: results.json, report.md, tables and traces as with figures (the
    same figures to the bit), no figure file (not even the paper's, with lstm in the run),
    and the report says why."""
    runs = {}
    for fmt in ("png", "none"):
        out = tmp_path / fmt
        r = bench("run", "-p", "cv,lstm", "--out", str(out), "--plot-format", fmt)
        assert r.returncode == 0, r.stderr
        runs[fmt] = out
    drawn = {p.name for p in runs["png"].rglob("*.png")}
    assert {"error_cdf.png", "paper_fig_prediction.png"} <= drawn
    assert not list(runs["none"].rglob("*.png")) and not list(runs["none"].rglob("*.svg"))
    assert (
        "- figures: --plot-format none (no figure asked for)"
        in (runs["none"] / "report.md").read_text()
    )
    with_figures, without = (
        without_timings(json.loads((runs[f] / "results.json").read_text())) for f in runs
    )
    for res in (with_figures, without):
        for key in ("outputs", "paper_figures", "command", "config", "provenance"):
            res.pop(key, None)
    assert json.dumps(with_figures, sort_keys=True) == json.dumps(without, sort_keys=True)
    assert {p.name for p in (runs["none"] / "tables").iterdir()} == {
        p.name for p in (runs["png"] / "tables").iterdir()
    }


@pytest.mark.slow
def test_report_formats_choose_the_table_files(tmp_path):
    """--table-format md,csv: report.md and tables/*.csv (no .tex); --table-format md: no
    tables/ at all; the CSV holds the interval bounds as numbers in their own columns."""
    out = tmp_path / "o"
    r = bench(
        "run",
        "-p",
        "cv,kf",
        "--out",
        str(out),
        "--workers",
        "1",
        "--table-format",
        "md,csv",
        "--drive-plots",
        "0",
    )
    assert r.returncode == 0, r.stderr
    csvs = sorted(p.name for p in (out / "tables").iterdir())
    assert "summary.csv" in csvs and all(n.endswith(".csv") for n in csvs), csvs
    import pandas as pd

    summary = pd.read_csv(out / "tables" / "summary.csv")
    lo = [c for c in summary.columns if "lo" in c and "future" in c.lower()]
    assert lo and pd.api.types.is_float_dtype(summary[lo[0]]), summary.columns
    out2 = tmp_path / "p"
    r = bench(
        "run",
        "-p",
        "cv",
        "--out",
        str(out2),
        "--workers",
        "1",
        "--table-format",
        "md",
        "--drive-plots",
        "0",
    )
    assert r.returncode == 0, r.stderr
    assert (out2 / "report.md").is_file() and not (out2 / "tables").exists()
    bad = bench("run", "-p", "cv", "--out", str(tmp_path / "b"), "--table-format", "md,xlsx")
    assert bad.returncode == 2 and bad.stderr.startswith(
        "error: --table-format: unknown format 'xlsx'"
    )
    assert not (tmp_path / "b").exists()


def test_tables_are_numeric_until_rendered(cv_kf_result, tmp_path):
    """One table, four forms: terminal cells and Markdown agree, CSV keeps full precision
    and counts in their own columns, LaTeX escapes text; every report table is written."""
    import io

    from rich.console import Console

    from posbench.cli.terminal import print_table
    from posbench.report.table_files import report_tables, write_tables
    from posbench.tables.breakdown_tables import label_table
    from posbench.tables.run_tables import summary_table

    _, res = cv_kf_result
    t = summary_table(res)
    assert t.frame["future_mean"].dtype == float and t.frame["future_n"].dtype.kind == "i"
    md = t.markdown()
    for row in t.cells():
        assert "| " + " | ".join(row) + " |" in md
    buf = io.StringIO()
    print_table(Console(file=buf, width=300), t.header(), t.cells())
    assert f"{res['predictors']['kf']['future']['mean_m']:.3f}" in buf.getvalue()
    csv = pd.read_csv(io.StringIO(label_table(res, "synthetic", "future").csv()))
    assert csv.loc[4, "kf [cm]"] == pytest.approx(
        100 * res["by_dataset"]["synthetic"]["kf"]["future"]["mean_m"]
    )
    assert csv.loc[4, "kf n"] == res["by_dataset"]["synthetic"]["kf"]["future"]["count"]
    tex = label_table(res, "synthetic", "future").latex()
    assert tex.startswith("\\begin{tabular}{l") and "Starting / stopping" in tex
    written = write_tables(res, tmp_path)
    assert len(written) == 2 * len(report_tables(res))
    assert (tmp_path / "summary.csv").is_file() and (tmp_path / "summary.tex").is_file()
