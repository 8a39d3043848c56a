"""Every table of a run, built once as a numeric frame and rendered at the last moment.

A :class:`Table` holds a DataFrame (numbers stay numbers; NaN/None = no figure), how many
decimals each float column shows, which columns are shown as ``value (count)``, which carry
a 95 % interval (``value [lo, hi]``) and which a marker (``*`` conclusive, ``?`` not). One
renderer writes each form: terminal cells (:meth:`Table.cells`, printed by
:func:`posbench.cli.terminal.print_table`), Markdown, CSV (full precision; counts, interval bounds
and markers as their own columns) and LaTeX (pure ASCII: every text through
:func:`tex_escape`). Value columns are right-aligned in each form. The builders
(:mod:`posbench.tables.run_tables`, ...) read a run's ``results`` (see
:mod:`posbench.saved_run.run`); nothing else formats a figure.
"""

from __future__ import annotations

import math
import re
import unicodedata
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from posbench.scenarios.text import fixed


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
        figures: text columns that hold figures already written as text (right-aligned like
            numeric columns; see :meth:`value_columns`).
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
    figures: Sequence[str] = ()

    def shown_columns(self) -> list[str]:
        hidden = (
            set(self.counts.values())
            | {c for b in self.ci.values() for c in b}
            | set(self.marks.values())
            | set(self.hidden)
        )
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

    def value_columns(self, cells: Sequence[Sequence[str]] | None = None) -> list[str]:
        """The shown columns that hold figures, right-aligned in every form: numeric columns,
        those shown with a count, an interval, a marker or their own decimals, those named in
        ``figures``, and text columns whose every cell reads as a figure (``0/4``,
        ``+0.012 [-0.003, 0.020] *``, ``-``). ``cells``: :meth:`cells`, when at hand."""
        cols = self.shown_columns()
        rows = self.cells() if cells is None else cells
        out = []
        for j, c in enumerate(cols):
            if (
                c in self.counts
                or c in self.ci
                or c in self.marks
                or c in self.digits
                or c in self.figures
                or pd.api.types.is_numeric_dtype(self.frame[c])
            ):
                out.append(c)
                continue
            texts = [r[j] for r in rows]
            if any(_FIGURE.match(t) for t in texts) and all(
                _FIGURE.match(t) or _NO_FIGURE.match(t) for t in texts
            ):
                out.append(c)
        return out

    def alignment(self, cells: Sequence[Sequence[str]] | None = None) -> str:
        """One letter per shown column: ``r`` for a value column, ``l`` for text."""
        values = set(self.value_columns(cells))
        return "".join("r" if c in values else "l" for c in self.shown_columns())

    def markdown(self) -> str:
        """A pipe table; value columns right-aligned (``---:``)."""
        header, rows = self.header(), self.cells()
        rule = ["---:" if a == "r" else "---" for a in self.alignment(rows)]
        lines = ["| " + " | ".join(header) + " |", "|" + "|".join(rule) + "|"]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(lines)

    def csv(self) -> str:
        """Full-precision numbers, counts in their own columns, empty for no figure."""
        labels = {c: h for c, h in self.labels.items() if c not in self.counts}
        for c, (lo, hi) in self.ci.items():
            name = self.labels.get(c, c) if c not in self.counts else c
            labels[lo], labels[hi] = f"{name} ci95 lo", f"{name} ci95 hi"
        text: str = self.frame.rename(columns=labels).to_csv(index=False)
        return text

    def latex(self) -> str:
        """A booktabs ``tabular``, figures as in the Markdown form, value columns ``r`` and
        text columns ``l``; every text through :func:`tex_escape` (pure ASCII out)."""
        rows = self.cells()
        lines = [
            f"\\begin{{tabular}}{{{self.alignment(rows)}}}",
            "\\toprule",
            " & ".join(tex_escape(h) for h in self.header()) + " \\\\",
            "\\midrule",
        ]
        lines += [" & ".join(tex_escape(c) for c in row) + " \\\\" for row in rows]
        lines += ["\\bottomrule", "\\end{tabular}"]
        return "\n".join(lines) + "\n"


def is_finite(v: Any) -> bool:
    try:
        return v is not None and math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def fmt(v: Any, digits: int = 3) -> str:
    """One figure as text: ``-`` for None/NaN, integers as is, floats to ``digits`` decimals
    (in scientific notation from 1e9 on, :func:`~posbench.scenarios.text.fixed`, so that a
    huge figure stays short)."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int) or (hasattr(v, "is_integer") and not isinstance(v, float)):
        return str(int(v))
    try:
        return fixed(float(v), digits)
    except (TypeError, ValueError):
        return str(v)


_NUM = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[+-]?\d+)?%?"
#: a cell that is one figure: ``v``, ``w/n``, with ``[lo, hi]``, a marker, ``(count)``
_FIGURE = re.compile(rf"{_NUM}(?:/{_NUM})?(?: \[{_NUM}, {_NUM}\])?(?: [*?])?(?: \({_NUM}\))?\Z")
#: a cell of a value column without a figure
_NO_FIGURE = re.compile(rf"(?:-|)(?: \({_NUM}\))?\Z")


class TexWarning(UserWarning):
    """A character :func:`tex_escape` has no LaTeX for (written as ``?``); the tests turn
    it into an error, so that a new one gets its LaTeX rather than slipping through."""


#: every character with a meaning of its own to LaTeX, and every non-ASCII character a table
#: may hold (labels, units, run and drive names), as pdflatex takes it in any font encoding
TEX_CHARACTERS: dict[str, str] = {
    # special to TeX, or wrong glyphs in the OT1 encoding
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "<": r"$<$",
    ">": r"$>$",
    "|": r"$|$",
    # signs, units and punctuation
    "\u00b1": r"$\pm$",
    "\u00b0": r"$^\circ$",
    "\u00b9": r"$^1$",
    "\u00b2": r"$^2$",
    "\u00b3": r"$^3$",
    "\u00b5": r"$\mu$",
    "\u00d7": r"$\times$",
    "\u00f7": r"$\div$",
    "\u00b7": r"$\cdot$",
    "\u2022": r"$\bullet$",
    "\u2212": r"$-$",
    "\u2013": "--",
    "\u2014": "---",
    "\u2010": "-",
    "\u2011": "-",
    "\u2026": r"\ldots{}",
    "\u2018": "`",
    "\u2019": "'",
    "\u201c": "``",
    "\u201d": "''",
    "\u00ab": r"$\ll$",
    "\u00bb": r"$\gg$",
    "\u00a0": "~",
    "\u2009": r"\,",
    "\u202f": r"\,",
    "\u200b": "",
    "\u2030": r"\textperthousand{}",
    "\u00a7": r"\S{}",
    "\u00b6": r"\P{}",
    "\u00a9": r"\copyright{}",
    "\u00ae": r"\textregistered{}",
    "\u2122": r"\texttrademark{}",
    "\u20ac": "EUR",
    "\u00a3": r"\pounds{}",
    "\u221e": r"$\infty$",
    "\u221a": r"$\surd$",
    "\u2264": r"$\leq$",
    "\u2265": r"$\geq$",
    "\u2260": r"$\neq$",
    "\u2248": r"$\approx$",
    "\u2243": r"$\simeq$",
    "\u223c": r"$\sim$",
    "\u2261": r"$\equiv$",
    "\u221d": r"$\propto$",
    "\u2190": r"$\leftarrow$",
    "\u2192": r"$\rightarrow$",
    "\u2191": r"$\uparrow$",
    "\u2193": r"$\downarrow$",
    "\u2194": r"$\leftrightarrow$",
    "\u21d2": r"$\Rightarrow$",
    "\u2202": r"$\partial$",
    "\u2207": r"$\nabla$",
    "\u2211": r"$\sum$",
    "\u220f": r"$\prod$",
    "\u222b": r"$\int$",
    "\u2208": r"$\in$",
    "\u2205": r"$\emptyset$",
    "\u2206": r"$\Delta$",
    "\u2032": r"$'$",
    "\u2033": r"$''$",
    "\u2713": r"$\surd$",
    # letters without a composed form
    "\u00df": r"\ss{}",
    "\u00f8": r"\o{}",
    "\u00d8": r"\O{}",
    "\u00e6": r"\ae{}",
    "\u00c6": r"\AE{}",
    "\u0153": r"\oe{}",
    "\u0152": r"\OE{}",
    "\u0142": r"\l{}",
    "\u0141": r"\L{}",
    "\u0131": r"\i{}",
    "\u00bf": r"?`",
    "\u00a1": r"!`",
}
# Greek: the letters with a macro of their own (the capitals that look Latin are Latin)
for _name, _tex in (
    ("ALPHA", "alpha"),
    ("BETA", "beta"),
    ("GAMMA", "gamma"),
    ("DELTA", "delta"),
    ("EPSILON", "epsilon"),
    ("ZETA", "zeta"),
    ("ETA", "eta"),
    ("THETA", "theta"),
    ("IOTA", "iota"),
    ("KAPPA", "kappa"),
    ("LAMDA", "lambda"),
    ("MU", "mu"),
    ("NU", "nu"),
    ("XI", "xi"),
    ("OMICRON", "o"),
    ("PI", "pi"),
    ("RHO", "rho"),
    ("SIGMA", "sigma"),
    ("FINAL SIGMA", "varsigma"),
    ("TAU", "tau"),
    ("UPSILON", "upsilon"),
    ("PHI", "phi"),
    ("CHI", "chi"),
    ("PSI", "psi"),
    ("OMEGA", "omega"),
):
    TEX_CHARACTERS[unicodedata.lookup(f"GREEK SMALL LETTER {_name}")] = f"$\\{_tex}$"
    if _name != "FINAL SIGMA":
        _cap = _tex.capitalize()
        TEX_CHARACTERS[unicodedata.lookup(f"GREEK CAPITAL LETTER {_name}")] = (
            f"$\\{_cap}$"
            if _cap
            in (
                "Gamma",
                "Delta",
                "Theta",
                "Lambda",
                "Xi",
                "Pi",
                "Sigma",
                "Upsilon",
                "Phi",
                "Psi",
                "Omega",
            )
            else {
                "Alpha": "A",
                "Beta": "B",
                "Epsilon": "E",
                "Zeta": "Z",
                "Eta": "H",
                "Iota": "I",
                "Kappa": "K",
                "Mu": "M",
                "Nu": "N",
                "O": "O",
                "Rho": "P",
                "Tau": "T",
                "Chi": "X",
            }[_cap]
        )

#: combining accents -> the LaTeX accent commands of the OT1 encoding (``é`` -> ``\'{e}``)
_TEX_ACCENTS = {
    "\u0300": "`",
    "\u0301": "'",
    "\u0302": "^",
    "\u0303": "~",
    "\u0304": "=",
    "\u0306": "u",
    "\u0307": ".",
    "\u0308": '"',
    "\u030a": "r",
    "\u030b": "H",
    "\u030c": "v",
    "\u0327": "c",
}


def _tex_char(ch: str) -> str | None:
    """One non-ASCII character as LaTeX, or None where there is none."""
    if ch in TEX_CHARACTERS:
        return TEX_CHARACTERS[ch]
    decomposed = unicodedata.normalize("NFD", ch)  # the base letter, then combining marks
    base, marks = decomposed[0], decomposed[1:]
    if marks and base.isascii() and base.isalpha() and all(m in _TEX_ACCENTS for m in marks):
        out = {"i": r"\i{}", "j": r"\j{}"}.get(base, base)
        for m in marks:  # innermost accent first
            cmd = _TEX_ACCENTS[m]
            out = f"\\{cmd}{{{out}}}"
        return out
    compat = unicodedata.normalize("NFKC", ch)  # ligatures, full-width forms, ...
    if compat != ch and all(c.isascii() or _tex_char(c) is not None for c in compat):
        return tex_escape(compat)
    return None


def tex_escape(text: str) -> str:
    r"""``text`` as LaTeX that pdflatex takes as is: pure ASCII (``Δ`` -> ``$\Delta$``,
    ``±`` -> ``$\pm$``, en dash -> ``--``, ``é`` -> ``\'{e}``, ``_`` -> ``\_``). The one
    escaping of every LaTeX this package writes. A character it has no LaTeX for is written
    ``?`` with a :class:`TexWarning`."""
    out: list[str] = []
    for ch in str(text):
        tex = TEX_CHARACTERS.get(ch, ch) if ch.isascii() else _tex_char(ch)
        if tex is None:
            warnings.warn(
                f"no LaTeX for {ch!r} (U+{ord(ch):04X} "
                f"{unicodedata.name(ch, 'unnamed')}) in {text!r}: written as '?'",
                TexWarning,
                stacklevel=2,
            )
            tex = "?"
        if out and tex.startswith("$") and out[-1].endswith("$") and out[-1] != r"\$":
            # one math run, never ``$$`` (display math); ``{}`` between two superscripts
            out[-1] = out[-1][:-1] + "{}" + tex[1:]
        else:
            out.append(tex)
    return "".join(out)


def rows_frame(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> pd.DataFrame:
    return pd.DataFrame(list(rows), columns=list(columns))
