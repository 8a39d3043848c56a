"""LaTeX that pdflatex takes as written: every ``.tex`` posbench writes (the report tables,
``bench compare --table-format latex``) is pure ASCII, with numbers right-aligned (``r``)
and text left-aligned (``l``).

All LaTeX goes through one escaping, :func:`posbench.tables.table.tex_escape`; a character
it does not know warns (:class:`TexWarning`), which every test here turns into an error,
and the source of the package may hold no non-ASCII character it does not know.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import unicodedata
import warnings
from pathlib import Path

import pytest
from helpers import ROOT, bench, missing

from posbench.tables.table import TEX_CHARACTERS, Table, TexWarning, tex_escape

pytestmark = pytest.mark.filterwarnings("error::posbench.tables.table.TexWarning")


_NUM = r"[+-]?\d+(?:\.\d+)?%?"
#: a cell holding one figure, as the tables write them (``0.066 [0.060, 0.072] *``,
#: ``7.9 [7.7, 8.0] (917)``, ``0/4``, ``+0.000``)
FIGURE = re.compile(rf"{_NUM}(?:/{_NUM})?(?: \[{_NUM}, {_NUM}\])?(?: [*?])?(?: \({_NUM}\))?\Z")
#: a cell of a figure column without a figure (``-``, ``- (0)``)
NO_FIGURE = re.compile(rf"-(?: \({_NUM}\))?\Z")
#: a LaTeX row: cells split on unescaped ``&``, ending in ``\\``
ROW_END = " \\\\"


def _tabulars(tex: str) -> list[tuple[str, list[str], list[list[str]]]]:
    """Every ``tabular`` in ``tex``: (column spec, header cells, body rows)."""
    out = []
    for m in re.finditer(
        r"\\begin\{tabular\}\{([a-z]*)\}\n\\toprule\n(.*?)\n\\midrule\n(.*?)"
        r"\\bottomrule\n\\end\{tabular\}",
        tex,
        re.S,
    ):
        spec, head, body = m.groups()

        def cells(line: str) -> list[str]:
            assert line.endswith(ROW_END), line
            return [c.strip() for c in re.split(r"(?<!\\)&", line[: -len(ROW_END)])]

        out.append((spec, cells(head), [cells(r) for r in body.splitlines() if r]))
    return out


def check_tex(tex: str, where: str) -> int:
    """``tex`` is ASCII and each of its tables right-aligns the columns of figures and
    left-aligns the columns of names; returns the number of tables."""
    bad = sorted({f"{ch!r} U+{ord(ch):04X}" for ch in tex if not ch.isascii()})
    assert not bad, f"{where}: raw non-ASCII in LaTeX: {', '.join(bad)}"
    tables = _tabulars(tex)
    assert tables and tex.count("\\begin{tabular}") == len(tables), where
    for spec, head, rows in tables:
        assert len(head) == len(spec), (where, spec, head)
        for j, align in enumerate(spec):
            column = [r[j] for r in rows]
            assert all(len(r) == len(spec) for r in rows), (where, rows)
            figures = [FIGURE.match(c) is not None for c in column]
            if any(figures) and all(
                f or NO_FIGURE.match(c) for f, c in zip(figures, column, strict=True)
            ):
                assert align == "r", f"{where}: numbers in '{head[j]}' not right-aligned ({spec})"
            elif not any(figures) and any(re.search("[A-Za-z]", c) for c in column):
                assert align == "l", f"{where}: text in '{head[j]}' not left-aligned ({spec})"
    return len(tables)


# --- the escaping -----------------------------------------------------------------------


def test_tex_escape_maps_symbols_units_and_letters_to_ascii() -> None:
    cases = {
        "Δ mean": r"$\Delta$ mean",
        "±0.5": r"$\pm$0.5",
        "12°": r"12$^\circ$",
        "m/s²": r"m/s$^2$",
        "µs": r"$\mu$s",
        "μs": r"$\mu$s",
        "0–5 s": "0--5 s",
        "≤ 2": r"$\leq$ 2",
        "≥ 2": r"$\geq$ 2",
        "a—b": "a---b",
        "2 × 3": r"2 $\times$ 3",
        "−1": "$-$1",
        "σ": r"$\sigma$",
        "Ω": r"$\Omega$",
        "Α": "A",
        "50 %": r"50 \%",
        "a_b & c#d": r"a\_b \& c\#d",
        "<0.5 m/s": "$<$0.5 m/s",
        "m^2": r"m\textasciicircum{}2",
        "x\\y": r"x\textbackslash{}y",
        "{~$}": r"\{\textasciitilde{}\$\}",
        "Straße": r"Stra\ss{}e",
        "café": r"caf\'{e}",
        "Zürich": r"Z\"{u}rich",
        "Ñandú": r"\~{N}and\'{u}",
        "ï": r"\"{\i{}}",
        "ﬁx": "fix",
        "Ｋ": "K",
        # adjacent symbols share one math run: never ``$$`` (display math) nor ``^a^b``
        "<−1": "$<{}-$1",
        "°²": r"$^\circ{}^2$",
        "$Δ": r"\$$\Delta$",
        "Δ|": r"$\Delta{}|$",
    }
    for text, tex in cases.items():
        assert tex_escape(text) == tex, text
    for ch, tex in TEX_CHARACTERS.items():
        assert tex.isascii() and tex_escape(ch) == tex, ch
        assert "$$" not in tex_escape(ch * 3), ch


def test_an_unknown_character_fails_loudly() -> None:
    with pytest.raises(TexWarning, match="U\\+4E2D"):
        tex_escape("drive 中")
    with warnings.catch_warnings(record=True) as caught:  # outside the tests: '?' and a warning
        warnings.simplefilter("always")
        assert tex_escape("drive 中") == "drive ?"
    assert [w.category for w in caught] == [TexWarning]


def test_every_non_ascii_character_of_the_package_has_latex() -> None:
    """A label, unit or note added with a new character must get its LaTeX too."""
    missing: dict[str, set[str]] = {}
    for folder in ("bench", "predictors", "scenarios", "metrics"):
        for path in (ROOT / folder).rglob("*.py"):
            for ch in set(path.read_text(encoding="utf-8")):
                if ch.isascii():
                    continue
                with warnings.catch_warnings():
                    warnings.simplefilter("error", TexWarning)
                    try:
                        tex_escape(ch)
                    except TexWarning:
                        name = unicodedata.name(ch, "?")
                        missing.setdefault(f"{ch!r} {name}", set()).add(str(path.relative_to(ROOT)))
    assert not missing, f"add to TEX_CHARACTERS in posbench/tables/table.py: {missing}"


def test_value_columns_are_right_aligned_in_latex_and_markdown() -> None:
    import pandas as pd

    frame = pd.DataFrame(
        {
            "name": ["a", "b"],
            "x": [1.0, float("nan")],
            "won": ["1/2", "0/2"],
            "paper": ["16.6", "11 (LSTM), 46 (Kalman)"],
            "note": ["ok", "-"],
            "pre": ["0.1 [0.0, 0.2] *", "-"],
        }
    )
    t = Table(frame, "t", {"x": "Δ x"}, digits={"paper": 1})
    assert t.alignment() == "lrrrlr"
    assert t.markdown().splitlines()[1] == "|---|---:|---:|---:|---|---:|"
    tex = t.latex()
    assert tex.startswith("\\begin{tabular}{lrrrlr}") and "$\\Delta$ x" in tex
    check_tex(tex, "toy")
    assert Table(frame[["name", "note"]], "t", figures=["note"]).alignment() == "lr"


# --- every table posbench writes ----------------------------------------------------------


def test_report_tables_of_the_committed_reports() -> None:
    """Every report table of every committed run, rendered by the code as it is now."""
    from posbench.report.table_files import report_tables

    runs = sorted(ROOT.glob("reports/*/results.json"))
    assert runs
    n = 0
    for path in runs:
        res = json.loads(path.read_text())
        for t in report_tables(res):
            where = f"{path.parent.name}/{t.name}.tex"
            n += check_tex(t.latex(), where)
            assert t.alignment()[0] == "l", where  # a name first
            rule = t.markdown().splitlines()[1]
            assert (
                rule == "|" + "|".join("---:" if a == "r" else "---" for a in t.alignment()) + "|"
            ), where
        for t in report_tables(res):  # the paper's column, text in its last row, is figures
            if t.name.startswith("route-type-") and "paper LSTM [cm]" in t.frame.columns:
                assert t.alignment().endswith("r"), t.name
    assert n > 50


@pytest.fixture(scope="module")
def small_run(cv_kf_run: Path) -> Path:
    """The session's cv,kf run (conftest), read only."""
    return cv_kf_run


def test_a_run_writes_ascii_tex_with_numbers_right(small_run: Path) -> None:
    written = sorted((small_run / "tables").glob("*.tex"))
    assert len(written) >= 10
    for path in written:
        check_tex(path.read_text(), path.name)
    paired = (small_run / "tables" / "paired.tex").read_text()
    assert "$\\Delta$ mean vs kf" in paired
    spec, head, _ = _tabulars(paired)[0]
    assert spec == "l" + "r" * (len(head) - 1)  # drives won (0/4) too
    summary = (small_run / "report.md").read_text()
    assert "|---|---:|" in summary


def test_bench_compare_latex_is_ascii_and_right_aligned(small_run: Path, tmp_path: Path) -> None:
    new = tmp_path / "new"
    shutil.copytree(small_run, new)
    out = tmp_path / "cmp"
    r = bench(
        "compare",
        str(small_run),
        str(new),
        "--table-format",
        "latex",
        "--uncertainty",
        "--scope",
        "all,dataset,route",
        "--out",
        str(out),
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert check_tex(r.stdout, "bench compare stdout") == 2
    spec, head, rows = _tabulars(r.stdout)[0]
    assert head[-1] == "$\\Delta$ new - old"
    assert spec == "llllrrrrr", spec  # scope, data set, route, predictor | old, n, new, n, delta
    for name in ("comparison.tex", "uncertainty_comparison.tex"):
        check_tex((out / name).read_text(), name)
    assert (out / "comparison.tex").read_text() == "".join(
        r.stdout.partition("\\end{tabular}\n")[:2]
    )


def test_pdflatex_compiles_the_tables(small_run: Path, tmp_path: Path) -> None:
    """Every table of a run, and one of every character the escaping knows, in a minimal
    document (booktabs; the default OT1 font encoding). `.ci/run` installs pdflatex (TeX
    Live), so under CI its absence fails; elsewhere the test is skipped without it."""
    import pandas as pd

    if shutil.which("pdflatex") is None:
        missing("no pdflatex (.ci/run installs texlive-latex-base and texlive-latex-recommended)")

    symbols = Table(
        pd.DataFrame({"char": [f"a{c}b" for c in TEX_CHARACTERS], "n": range(len(TEX_CHARACTERS))}),
        "symbols",
    )
    tables = [p.read_text() for p in sorted((small_run / "tables").glob("*.tex"))]
    doc = (
        "\\documentclass{article}\n\\usepackage{booktabs}\n\\begin{document}\n"
        + "\n\\bigskip\n".join([*tables, symbols.latex()])
        + "\\end{document}\n"
    )
    (tmp_path / "t.tex").write_text(doc)
    r = subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "t.tex"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stdout[-3000:]
    assert (tmp_path / "t.pdf").is_file()
