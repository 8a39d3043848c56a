"""Every table of a run, built once as a numeric frame and rendered at the last moment.

A :class:`Table` holds a DataFrame (numbers stay numbers; NaN/None = no figure), how many
decimals each float column shows, which columns are shown as ``value (count)``, which carry
a 95 % interval (``value [lo, hi]``) and which a marker (``*`` conclusive, ``?`` not). One
renderer writes each form: terminal cells (:meth:`Table.cells`, printed by
:func:`posbench.cli.terminal.print_table`), Markdown, CSV (full precision; counts, interval bounds
and markers as their own columns) and LaTeX. The builders (:mod:`posbench.tables.run_tables`, ...) read a run's
``results`` (see :mod:`posbench.saved_run.run`); nothing else formats a figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd


def as_float(v: Any) -> float:
    """A figure of results.json as a float: None (no figure) is NaN."""
    return float("nan") if v is None else float(v)


@dataclass
class Table:
    """A table kept numeric until rendered.

    Attributes:
        frame: the columns in display order (unique names; text columns hold str).
        name: a file stem for the CSV / LaTeX forms (e.g. ``summary``).
        labels: column -> header text (default: the column name).
        digits: float column -> decimals shown (default 3).
        counts: value column -> the column holding its query count, shown as ``v (n)``.
        title: a caption.
        ci: value column -> its (lo, hi) columns, shown as ``v [lo, hi]`` (same decimals).
        marks: value column -> a text column whose content follows the value (``*``, ``?``).
        hidden: further columns kept for the CSV form only.
    """

    frame: pd.DataFrame
    name: str
    labels: Mapping[str, str] = field(default_factory=dict)
    digits: Mapping[str, int] = field(default_factory=dict)
    counts: Mapping[str, str] = field(default_factory=dict)
    title: str = ""
    ci: Mapping[str, tuple[str, str]] = field(default_factory=dict)
    marks: Mapping[str, str] = field(default_factory=dict)
    hidden: Sequence[str] = ()

    def shown_columns(self) -> list[str]:
        hidden = (set(self.counts.values()) | {c for b in self.ci.values() for c in b}
                  | set(self.marks.values()) | set(self.hidden))
        return [c for c in self.frame.columns if c not in hidden]

    def header(self) -> list[str]:
        """Header texts of the shown columns (count columns fold into their values)."""
        return [self.labels.get(c, c) for c in self.shown_columns()]

    def cells(self) -> list[list[str]]:
        """Every shown cell as text: floats to their decimals, NaN/None as ``-``."""
        out = []
        for _, row in self.frame.iterrows():
            cells = []
            for c in self.shown_columns():
                digits = self.digits.get(c, 3)
                text = fmt(row[c], digits)
                if c in self.ci and text != "-":
                    lo, hi = (row[b] for b in self.ci[c])
                    if is_finite(lo) and is_finite(hi):
                        text += f" [{fmt(lo, digits)}, {fmt(hi, digits)}]"
                if c in self.marks and row[self.marks[c]] and text != "-":
                    text += f" {row[self.marks[c]]}"
                if c in self.counts:
                    n = row[self.counts[c]]
                    text = f"{'-' if not n else text} ({fmt(n)})"
                cells.append(text)
            out.append(cells)
        return out

    def markdown(self) -> str:
        header = self.header()
        lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
        lines += ["| " + " | ".join(r) + " |" for r in self.cells()]
        return "\n".join(lines)

    def csv(self) -> str:
        """Full-precision numbers, counts in their own columns, empty for no figure."""
        labels = {c: h for c, h in self.labels.items() if c not in self.counts}
        for c, (lo, hi) in self.ci.items():
            name = self.labels.get(c, c) if c not in self.counts else c
            labels[lo], labels[hi] = f"{name} ci95 lo", f"{name} ci95 hi"
        return self.frame.rename(columns=labels).to_csv(index=False)

    def latex(self) -> str:
        """A booktabs ``tabular`` (text escaped), figures as in the Markdown form."""
        cols = self.shown_columns()
        align = "".join("r" if c in self.counts or pd.api.types.is_numeric_dtype(self.frame[c])
                        else "l" for c in cols)
        lines = [f"\\begin{{tabular}}{{{align}}}", "\\toprule",
                 " & ".join(_tex(h) for h in self.header()) + " \\\\", "\\midrule"]
        lines += [" & ".join(_tex(c) for c in row) + " \\\\" for row in self.cells()]
        lines += ["\\bottomrule", "\\end{tabular}"]
        return "\n".join(lines) + "\n"


def is_finite(v: Any) -> bool:
    try:
        return v is not None and math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def fmt(v: Any, digits: int = 3) -> str:
    """One figure as text: ``-`` for None/NaN, integers as is, floats to ``digits``."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int) or (hasattr(v, "is_integer") and not isinstance(v, float)):
        return str(int(v))
    try:
        return f"{float(v):.{digits}f}"
    except (TypeError, ValueError):
        return str(v)


_TEX = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
        "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}


def _tex(text: str) -> str:
    return "".join(_TEX.get(ch, ch) for ch in text)


def rows_frame(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> pd.DataFrame:
    return pd.DataFrame(list(rows), columns=list(columns))
