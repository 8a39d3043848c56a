"""The Python API (``posbench.run``, ``score``, ``load``, ``compare``, ``check``) is the command
line's own code: the same options give the same figures, the same mistakes the same one-line
errors, and what it returns is small to print and easy to use."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pandas as pd
import pytest
from helpers import bench as run_bench

import posbench
from posbench.errors import UsageError
from posbench.scenarios.errors import DataError

#: figures that differ between two runs of the same code (timings) or name the run
VOLATILE = ("latency_us", "query_us", "covariance_us")


def bench(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``bench ARGS`` in this process, output piped (no terminal width)."""
    return run_bench(*args, cwd=cwd, columns=None)


def _figures(res: dict) -> dict:
    """results.json's figures without timings and provenance."""
    drop = {"command", "versions", "git_commit", "outputs", "data"}
    preds = {
        p: {k: v for k, v in e.items() if k not in VOLATILE} for p, e in res["predictors"].items()
    }
    return {**{k: v for k, v in res.items() if k not in drop | {"predictors"}}, "predictors": preds}


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "run"
    r = bench(
        "run",
        "-p",
        "cv",
        "-p",
        "kf",
        "--workers",
        "1",
        "--dropouts",
        "outages",
        "--out",
        str(out),
        "--plot-format",
        "none",
    )
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.slow
def test_run_in_memory_gives_the_commands_figures(cli_run: Path):
    run = posbench.run(predictors=("cv", "kf"), workers=1, dropouts="outages")
    assert run.folder is None and run.predictors == ["cv", "kf"]
    cli = json.loads((cli_run / "results.json").read_text())
    assert _figures(run.results) == _figures(cli)
    assert run.results["command"] == (
        "posbench.run(predictors=('cv', 'kf'), workers=1, dropouts='outages')"
    )


def test_summary_is_a_table_per_predictor_and_kind(cli_run: Path):
    run = posbench.load(cli_run)
    table = run.summary()
    assert isinstance(table, pd.DataFrame)
    assert list(table.index) == [("cv", "future"), ("cv", "now"), ("kf", "future"), ("kf", "now")]
    for col in ("count", "missing", "mean_m", "median_m", "p95_m", "mean_m_lo", "mean_m_hi"):
        assert col in table.columns
    res = run.results["predictors"]["kf"]["now"]
    assert table.loc[("kf", "now"), "mean_m"] == res["mean_m"]
    assert table.loc[("kf", "now"), "mean_m_lo"] == res["ci95"]["mean_m"][0]
    future = run.summary("future")  # one kind: the table of schema 1.x, by predictor
    assert (
        list(future.index) == ["cv", "kf"]
        and future.loc["kf", "mean_m"] == run.results["predictors"]["kf"]["future"]["mean_m"]
    )


def test_repr_is_a_few_lines(cli_run: Path):
    text = repr(posbench.load(cli_run))
    assert len(text.splitlines()) <= 3 and len(text) < 400, text
    assert text.startswith(f"Run({cli_run}: 4 drives (synthetic), 2 predictors")
    assert "kf 0." in text


@pytest.mark.slow
def test_run_writes_the_commands_folder_and_save_report_write_one(tmp_path: Path, cli_run: Path):
    run = posbench.run(
        predictors="cv,kf", out=tmp_path / "a", workers=1, dropouts="outages", drive_plots=0
    )
    assert run.folder == tmp_path / "a"
    for name in ("report.md", "results.json", "traces.parquet", "error_cdf.png"):
        assert (tmp_path / "a" / name).is_file(), name
    assert _figures(posbench.load(tmp_path / "a").results) == _figures(
        json.loads((cli_run / "results.json").read_text())
    )
    loaded = posbench.load(cli_run)
    written = loaded.save(tmp_path / "b")
    assert {p.name for p in written} == {"results.json", "traces.parquet"}
    pd.testing.assert_frame_equal(posbench.load(tmp_path / "b").traces, loaded.traces)
    files = loaded.report(tmp_path / "c", drive_plots=0, table_formats=("csv",))
    assert (tmp_path / "c" / "report.md") in files and (tmp_path / "c" / "tables").is_dir()


@pytest.mark.slow
def test_compare_and_its_gate(cli_run: Path, tmp_path: Path):
    other = posbench.run(
        predictors="cv,kf",
        workers=1,
        dropouts="outages",
        options={"kf": {"jerk_psd": 2000.0}},
        out=tmp_path / "worse",
        plot_formats="none",
    )
    cmp = posbench.compare(cli_run, other, gates=["kf:future.mean_m:1%"], allow_config_change=True)
    assert cmp.labels[0] != cmp.labels[1] and len(cmp.gates) == 1
    assert cmp.differences and "options of kf" in cmp.differences[0]
    kf = cmp.frame[(cmp.frame["scope"] == "all") & (cmp.frame["predictor"] == "kf")].iloc[0]
    assert kf[f"delta {cmp.labels[1]}"] == pytest.approx(
        other.results["predictors"]["kf"]["future"]["mean_m"]
        - posbench.load(cli_run).results["predictors"]["kf"]["future"]["mean_m"]
    )
    assert cmp.passed == (not cmp.gates[0].failed)
    assert repr(cmp).startswith("Comparison of 2 runs")
    same = posbench.compare(cli_run, cli_run)
    assert same.passed and same.frame[f"delta {same.labels[1]}"].abs().max() == 0


def test_check_returns_a_report():
    report = posbench.check("cv")
    assert report.passed and report.gated and len(report.clauses) == 9
    assert repr(report) == "ContractReport(cv behind the gate: 9 of 9 clauses pass)"
    one = posbench.check("cv", gate=False, clauses=["reset", "deterministic"])
    assert [c.clause for c in one.clauses] == ["reset", "deterministic"] and not one.gated


def test_score_as_the_command_does(tmp_path: Path):
    q = tmp_path / "q"
    r = bench("queries", "--out", str(q), "--synthetic-duration", "60")
    assert r.returncode == 0, r.stderr
    key = pd.read_parquet(q / "key" / "reference.parquet")
    public = pd.read_csv(q / "queries.csv")
    answers = public.assign(x=key["x_ref"].to_numpy() + 0.1, y=key["y_ref"].to_numpy())
    answers = answers.dropna(subset=["x", "y"])[["drive", "kind", "t_query", "x", "y"]]
    answers.to_csv(tmp_path / "a.csv", index=False)
    run = posbench.score(tmp_path / "a.csv", q, name="shifted")
    assert run.predictors == ["shifted"]
    assert run.results["predictors"]["shifted"]["future"]["mean_m"] == pytest.approx(0.1)
    r = bench(
        "score",
        str(tmp_path / "a.csv"),
        "--queries",
        str(q),
        "--name",
        "shifted",
        "--out",
        str(tmp_path / "s"),
    )
    assert r.returncode == 0, r.stderr
    cli = json.loads((tmp_path / "s" / "results.json").read_text())
    assert _figures(run.results) == _figures({**cli, "paper_figures": []})


def test_mistakes_are_the_commands_errors(tmp_path: Path):
    with pytest.raises(UsageError, match="--horizon must be more than 0 s"):
        posbench.run(horizon_s=-1)
    with pytest.raises(UsageError, match="unknown predictor"):
        posbench.run(predictors="nosuch")
    with pytest.raises(
        UsageError,
        match=r"options=\{'kf': \{'bogus': 1\}\}: predictor kf has no "
        r"option 'bogus'",
    ):
        posbench.run(predictors="kf", options={"kf": {"bogus": 1}})
    with pytest.raises(TypeError, match="unknown option.*horizon"):
        posbench.run(horizon=0.2)
    with pytest.raises(DataError, match="no such file"):
        posbench.load(tmp_path)
    with pytest.raises(UsageError, match="--metric"):
        posbench.compare(tmp_path, tmp_path, metric="future.bogus")
