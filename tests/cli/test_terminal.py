"""Terminal tables: never a cut cell, never a line wider than the terminal, piped output whole."""

from __future__ import annotations

import io

import numpy as np
import pytest
from helpers import bench
from rich.console import Console

from posbench.cli.terminal import column_widths, print_table, split_columns, table_width

HEADER = [
    "predictor",
    *(f"{m} {q} [m]" for m in ("along", "cross", "total") for q in ("p50", "p90", "p99", "max")),
]


def numeric_rows() -> list[list[str]]:
    rng = np.random.default_rng(3)
    names = ["cv", "poly", "kf", "kf-paper", "ekf", "lstm-authors"]
    return [[n, *(f"{v:.3f}" for v in 10.0 ** rng.uniform(-3, 5, 12))] for n in names]


def render(width: int | None, header=HEADER, rows=None, terminal: bool = True, **kw) -> str:
    buf = io.StringIO()
    console = Console(file=buf, width=width, force_terminal=terminal, color_system=None)
    print_table(console, header, numeric_rows() if rows is None else rows, **kw)
    return buf.getvalue()


def test_table_width_matches_rich() -> None:
    rows = numeric_rows()
    out = render(None, rows=rows, terminal=False)
    assert max(len(line) for line in out.splitlines()) == table_width(column_widths(HEADER, rows))


@pytest.mark.parametrize("width", [40, 60, 80, 100, 120, 200])
def test_cells_never_cut_and_lines_fit(width: int, monkeypatch) -> None:
    monkeypatch.delenv("COLUMNS", raising=False)
    rows = numeric_rows()
    out = render(width, rows=rows, title="errors")
    lines = out.splitlines()
    assert "…" not in out
    assert max(len(line) for line in lines) <= width
    # every cell whole, in its row's line of each table showing that column
    body = [line for line in lines if line.startswith("│")]
    for r in rows:
        row_lines = [line for line in body if line.split("│")[1].strip() == r[0]]
        assert row_lines, r[0]
        cells = [c.strip() for line in row_lines for c in line.split("│")[1:-1]]
        for c in r[1:]:
            assert c in cells, (c, width)
    n_tables = out.count("┏")
    if width >= table_width(column_widths(HEADER, rows)):
        assert n_tables == 1 and "(1/" not in out
    else:
        assert n_tables > 1 and f"errors (1/{n_tables})" in out
        assert f"errors ({n_tables}/{n_tables})" in out


def test_piped_prints_one_whole_table(monkeypatch) -> None:
    monkeypatch.delenv("COLUMNS", raising=False)
    rows = numeric_rows()
    out = render(None, rows=rows, terminal=False)
    assert out.count("┏") == 1 and "…" not in out
    assert max(len(line) for line in out.splitlines()) > 80  # not squeezed to rich's default


def test_columns_env_limits_piped_output(monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "70")
    out = render(None, terminal=False)
    assert out.count("┏") > 1 and max(len(line) for line in out.splitlines()) <= 70


def test_too_narrow_prints_header_value_lines(monkeypatch) -> None:
    monkeypatch.delenv("COLUMNS", raising=False)
    rows = [["synthetic-mixed-s1", "1234.567"], ["b", "2.000"]]
    out = render(20, header=["drive", "distance [m]"], rows=rows, title="2 drives")
    assert "┏" not in out and "…" not in out
    assert "drive: synthetic-mixed-s1" in out and "distance [m]: 1234.567" in out
    assert "distance [m]: 2.000" in out


def test_markup_like_text_is_printed_literally(monkeypatch) -> None:
    monkeypatch.delenv("COLUMNS", raising=False)
    out = render(80, header=["name", "dur [s]"], rows=[["[bold]x", "1.0"]])
    assert "┃ [s] ┃" in out and "│ [bold]x │" in out


def test_split_columns_rules() -> None:
    widths = [10, 8, 8, 8, 8]
    assert split_columns(widths, None) == [[0, 1, 2, 3, 4]]
    assert split_columns(widths, table_width(widths)) == [[0, 1, 2, 3, 4]]
    groups = split_columns(widths, 40)
    assert groups is not None and all(g[0] == 0 for g in groups)
    assert [j for g in groups for j in g[1:]] == [1, 2, 3, 4]  # consecutive, each once
    assert all(table_width(widths[j] for j in g) <= 40 for g in groups)
    # two key columns repeated; one key only when two do not fit beside a data column
    assert all(g[:2] == [0, 1] for g in split_columns(widths, 40, key_columns=2))
    assert split_columns([10, 20, 8, 8], 40, key_columns=2) == [[0, 1], [0, 2, 3]]
    assert split_columns([10, 30], 20) is None


def test_inspect_at_100_columns_cuts_nothing() -> None:
    from posbench.cli.inspect import inspect_rows
    from posbench.scenarios.summary import summarize_drive
    from posbench.scenarios.synthetic import default_drives

    r = bench("data", "inspect", columns=100)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert "…" not in r.stdout and max(len(line) for line in lines) <= 100
    _, rows = inspect_rows([summarize_drive(d) for d in default_drives(seed=0)])
    cells = {c.strip() for line in lines if line.startswith("│") for c in line.split("│")[1:-1]}
    for row in rows:
        for c in row:
            assert c in cells, c
    assert f"{len(rows)} drives" in r.stdout
