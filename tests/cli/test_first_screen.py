"""The first screen of ``bench run`` and ``bench score`` (issue 49): by default one table that
fits 100 columns and one line per warning or finding, pointing to report.md; ``--wide`` (or
``-v``) the full summary. Never a number cut, at any width."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pandas as pd
import pytest
from helpers import bench
from rich.cells import cell_len

from posbench.saved_run import load_run

#: a page of a table split to the terminal's width: "(1/3)" after its title
PAGE_MARK = re.compile(r"\(\d+/\d+\)")
MAX_ROWS = 30

# default_run (tests/conftest.py): `bench run --out DIR` at 100 columns, once per session


def screen_rows(text: str, width: int) -> int:
    """Rows ``text`` takes on a terminal ``width`` columns wide (a longer line wraps)."""
    return sum(max(1, math.ceil(cell_len(line) / width)) for line in text.splitlines())


def table_rows(stdout: str) -> dict[str, str]:
    """The body rows of the tables printed, by the text of their first cell."""
    return {
        line.split("│")[1].strip(): line
        for line in stdout.splitlines()
        if line.startswith("│") and line.count("│") > 2
    }


@pytest.mark.slow
def test_default_run_prints_at_most_30_rows_and_one_unpaged_table(default_run):
    r, res, _ = default_run
    assert screen_rows(r.stdout + r.stderr, 100) <= MAX_ROWS, r.stdout + r.stderr
    assert max(cell_len(line) for line in r.stdout.splitlines()) <= 100
    assert not PAGE_MARK.search(r.stdout), r.stdout
    assert r.stdout.count("┏") == 1  # one table
    assert "…" not in r.stdout
    for word in ("predictor", "future", "now", "mean", "x", "limit", "step", "p50"):
        assert re.search(rf"┃.*\b{re.escape(word)}\b", r.stdout), word
    rows = table_rows(r.stdout)
    for name, p in res["predictors"].items():
        row = next(v for k, v in rows.items() if k.split()[0] == name)
        for kind in ("future", "now"):
            s = p[kind]
            lo, hi = s["ci95"]["mean_m"]
            assert f"{s['mean_m']:.3f} [{lo:.3f}, {hi:.3f}]" in row, (name, kind, row)
        # x limit against the limit that applies: with IMU for a predictor reading it
        imu = res["limit"]["reads_imu"][name]
        ratio = res["limit"]["ratios"]["overall"][name]["future_imu" if imu else "future"]
        assert f" {ratio:.2f} " in row
        assert f" {p['latency_us']['p50']:.1f} " in row
    # the bound's rows, named without their model (the legend line names it)
    assert {"limit", "limit with IMU"} <= set(rows)
    assert rows["limit"].count(f"{res['limit']['overall']['future']['mean_m']:.3f} [") == 1
    assert f"{res['limit']['name']}: a bound under stated assumptions" in r.stdout


@pytest.mark.slow
def test_each_finding_is_one_line_and_marked_in_the_table(default_run):
    r, res, _ = default_run
    below = {b["predictor"] for b in res["limit"]["below"]}
    losses = {(x["predictor"], x["dataset"]) for x in res["sanity"]["losses"]}
    assert losses  # the default run has a loss to constant velocity (kf-paper)
    # and, each predictor held to the limit that applies to it, none below the limit
    assert not below
    out = r.stdout.splitlines()
    assert not [line for line in out if "below the limit" in line]
    assert "Likely:" not in r.stdout  # the reasons stay in report.md
    # each loss to constant velocity: one warning line, and nothing else on stderr
    err = r.stderr.splitlines()
    assert len(err) == len(losses), r.stderr
    for p, ds in losses:
        [line] = [x for x in err if f"{p} loses to constant velocity on {ds}:" in x]
        assert line.startswith("warning: ") and line.endswith("(report.md)")
    # the paired comparison: one line naming every predictor compared
    [paired] = [line for line in out if line.startswith(f"vs {res['paired']['baseline']}")]
    assert all(p in paired for p in res["paired"]["overall"])
    # the mark: ! beside every predictor report.md flags, and no other; its legend once
    flagged = below | {p for p, _ in losses}
    rows = table_rows(r.stdout)
    for name in res["predictors"]:
        cell = next(k for k in rows if k.split()[0] == name)
        assert (cell == f"{name} !") == (name in flagged), cell
    assert sum(line.startswith("! = report.md flags it") for line in out) == 1


def test_below_the_limit_is_one_line_naming_report_md():
    from posbench.report.first_screen import below_line

    res = {
        "limit": {
            "below": [
                {"predictor": "kf", "dataset": "a"},
                {"predictor": "ekf", "dataset": "a"},
                {"predictor": "kf", "dataset": "b"},
            ]
        }
    }
    line = below_line(res)
    assert line.startswith("below the limit: ") and "\n" not in line
    assert "kf, ekf on a" in line and "kf on b" in line
    assert '"Below the limit"' in line and "report.md" in line
    assert below_line({"limit": {"below": []}}) == ""


def _cells_whole(text: str, cells: list[list[str]]) -> None:
    """Every cell of ``cells`` is in ``text`` whole, in a table row."""
    rows = "\n".join(line for line in text.splitlines() if line.startswith("│"))
    for row in cells:
        for c in row:
            assert f" {c} " in rows, c


@pytest.mark.slow
@pytest.mark.parametrize("width", [60, 80, 100])
def test_no_number_is_cut_at_any_width(default_run, width, capsys, monkeypatch):
    """The saved default run printed again at 60, 80 and 100 columns, first screen and
    --wide: every cell of every table whole, no line wider than the terminal."""
    from posbench.cli import terminal
    from posbench.cli.summary import print_run_summary
    from posbench.pipeline.publish import Published
    from posbench.report.first_screen import flagged
    from posbench.tables.run_tables import first_screen_table, summary_table
    from posbench.tables.stat_tables import paired_table

    _, res, out = default_run
    run = load_run(out)
    monkeypatch.setenv("COLUMNS", str(width))
    monkeypatch.setattr(terminal.console, "_width", width)
    monkeypatch.setattr(terminal.err_console, "_width", width)
    for wide, tables in (
        (False, [first_screen_table(res, set(flagged(res)))]),
        (True, [summary_table(res, compact=True), paired_table(res)]),
    ):
        print_run_summary(Published(run), wide=wide)
        text = capsys.readouterr().out
        assert "…" not in text
        assert max(cell_len(line) for line in text.splitlines()) <= width
        for t in tables:
            _cells_whole(text, t.cells())
        if width == 100 and not wide:
            assert not PAGE_MARK.search(text)


@pytest.mark.slow
def test_wide_and_verbose_print_the_full_table(tmp_path):
    """--wide, and -v, print every column of the full headline (median, RMSE, p95, max,
    counts, missing, latency p99, ...), the paired table and the notes in full."""
    from posbench.tables.run_tables import summary_table

    args = ("run", "--synthetic-duration", "30", "-p", "cv,kf", "--drive-plots", "0")
    for flag in ("--wide", "-v"):
        out = tmp_path / flag.strip("-")
        r = bench(*args, "--out", out, flag, columns=100)
        assert r.returncode == 0, r.stderr
        full = summary_table(load_run(out).results, compact=True)
        header = " ".join(line for line in r.stdout.splitlines() if line.startswith("┃")).split()
        for label in full.header():
            for word in label.split():
                assert word in header, (flag, label)
        for label in ("median", "RMSE", "p95", "max", "missing", "p99"):
            assert label in header, (flag, label)
        _cells_whole(r.stdout, full.cells())
        assert "Δ mean error [m]" in r.stdout  # the paired table
        assert "Excluded from these figures, per predictor:" in r.stdout
        assert "every column: --wide" not in r.stdout


@pytest.mark.slow
def test_bench_score_prints_the_same_first_screen(tmp_path):
    """bench score: the first screen by default (one table, no pages at 100 columns), the
    full table with --wide."""
    q = tmp_path / "q"
    r = bench("queries", "--synthetic-duration", "30", "--out", q)
    assert r.returncode == 0, r.stderr
    ref = pd.read_parquet(q / "key" / "reference.parquet").dropna(subset=["x_ref", "y_ref"])
    answers = ref[["drive", "kind", "t_query"]].assign(x=ref.x_ref + 0.05, y=ref.y_ref)
    answers.to_csv(tmp_path / "answers.csv", index=False)
    score = ("score", tmp_path / "answers.csv", "--queries", q, "--drive-plots", "0")
    first = bench(*score, "--out", tmp_path / "a", columns=100)
    assert first.returncode == 0, first.stderr
    assert first.stdout.count("┏") == 1 and not PAGE_MARK.search(first.stdout)
    assert "every column: --wide" in " ".join(first.stdout.split())  # a title may wrap
    assert "median" not in first.stdout
    assert screen_rows(first.stdout + first.stderr, 100) <= MAX_ROWS
    row = table_rows(first.stdout)["answers"]
    assert row.count("0.050 [0.050, 0.050]") == 2  # future and now mean, 5 cm off
    wide = bench(*score, "--out", tmp_path / "b", "--wide", columns=100)
    assert wide.returncode == 0, wide.stderr
    assert "median" in wide.stdout and "RMSE" in wide.stdout and "p99" in wide.stdout


def test_written_files_counted_on_the_first_screen(tmp_path: Path):
    from posbench.cli.summary import written_summary

    names = ["error_cdf.png", "path.png", "report.md", "results.json"]
    written = [tmp_path / n for n in names] + [tmp_path / "drives" / "a.png"]
    assert written_summary(tmp_path, written, [], wide=False) == (
        f"wrote {tmp_path}/: report.md, results.json, 2 figures, 1 per-drive plot in drives/"
    )
    assert written_summary(tmp_path, written, []).startswith(
        f"wrote {tmp_path}/: error_cdf.png, path.png, report.md"
    )
