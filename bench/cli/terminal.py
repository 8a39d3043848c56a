"""What ``bench`` shows in the terminal: the consoles, the one-line error, how loud a command
is (``-q``, ``-v``), progress (:func:`reporter`) and tables that fit the terminal
without ever shortening a cell.

A column is exactly as wide as its longest cell (or the longest single word of its header:
headers may wrap at spaces, cells never wrap and never get an ellipsis). A table wider than
the terminal is split into several consecutive tables, each repeating the key columns (the
drive or predictor name); if even one key column and one data column do not fit, the rows
are printed as ``header: value`` lines. Piped output (no terminal, ``COLUMNS`` unset) has no
width limit: the table is printed whole, at its natural width.

:func:`column_widths` and :func:`split_columns` are pure (no rich) and decide the layout;
:func:`print_table` renders it.

Loudness: ``-q`` keeps a command's own output (a table it was asked for) and warnings and
drops progress and notes; ``-v`` adds a line per finished step and the details a command has.
Errors are always one line on stderr.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

import typer
from rich.console import Console, ConsoleOptions, RenderableType, RenderResult

from posbench.pipeline.reporter import INFO, Reporter, RichReporter

if TYPE_CHECKING:
    from rich.table import Table

console = Console()
err_console = Console(stderr=True)

QUIET, NORMAL, VERBOSE = -1, 0, 1  # -q, neither, -v
_level = [NORMAL]


def set_verbosity(level: int) -> None:
    """How loud the commands of this process are: :data:`QUIET`, :data:`NORMAL`, :data:`VERBOSE`."""
    _level[0] = level


def verbosity() -> int:
    """The level :func:`set_verbosity` set (:data:`NORMAL` by default)."""
    return _level[0]


def fail(msg: str) -> typer.Exit:
    """Print ``error: msg`` as one line on stderr; return the exit (status 2) to raise."""
    from rich.markup import escape  # "posbench-harness[ray]" is text, not markup

    err_console.print(
        f"[bold red]error:[/] {escape(msg)}", highlight=False, soft_wrap=True, emoji=False
    )
    return typer.Exit(2)


def warn(msg: str) -> None:
    """One line ``warning: msg`` on stderr, whatever the verbosity (deprecations)."""
    from rich.markup import escape

    err_console.print(
        f"[yellow]warning:[/] {escape(msg)}", highlight=False, soft_wrap=True, emoji=False
    )


def say(text: str, level: int = INFO) -> None:
    """Print one plain line on stdout if the verbosity shows ``level`` (:data:`WARNING`
    lines always, :data:`INFO` unless quiet, :data:`DETAIL` only verbose)."""
    reporter().line(text, level)


def reporter() -> Reporter:
    """The reporter of a command: progress and lines on :data:`console`, as loud as
    :func:`verbosity` says."""
    return RichReporter(console, verbosity())


CELL_OVERHEAD = 3
"""Characters a rich table adds per column with the default box and padding (1 + 1 padding
and one border) ..."""
EDGE_OVERHEAD = 1
"""... plus the closing border of the row."""


def column_widths(
    header: Sequence[str], rows: Sequence[Sequence[str]], measure: Callable[[str], int] = len
) -> list[int]:
    """Width [characters] of each column: its longest cell or longest header word, at least 1.

    ``measure`` gives a string's width on screen (``len``; rich's ``cell_len`` for wide glyphs).
    """
    widths = []
    for j, h in enumerate(header):
        words = [measure(w) for w in h.split()]
        cells = [measure(r[j]) for r in rows]
        widths.append(max([1, *words, *cells]))
    return widths


def table_width(widths: Iterable[int]) -> int:
    """Rendered width [characters] of a rich table whose columns are ``widths`` wide."""
    ws = list(widths)
    return sum(ws) + CELL_OVERHEAD * len(ws) + EDGE_OVERHEAD


def _greedy(widths: Sequence[int], keys: list[int], limit: int) -> list[list[int]]:
    base = table_width(widths[k] for k in keys)
    groups: list[list[int]] = []
    cur: list[int] = []
    used = base
    for j in range(len(keys), len(widths)):
        w = widths[j] + CELL_OVERHEAD
        if cur and used + w > limit:
            groups.append(keys + cur)
            cur, used = [], base
        cur.append(j)
        used += w
    groups.append(keys + cur)
    return groups


def split_columns(
    widths: Sequence[int], limit: int | None, key_columns: int = 1
) -> list[list[int]] | None:
    """Column indices of each table to print so that every table is at most ``limit`` wide.

    One table with every column when it fits (or ``limit`` is None). Otherwise consecutive
    groups of the data columns, each preceded by the first ``key_columns`` columns, as few
    tables as possible and their widths as even as possible. If a data column cannot fit
    beside all key columns, only the first key column is repeated; None when even that does
    not fit (print ``header: value`` lines instead).
    """
    n = len(widths)
    if limit is None or table_width(widths) <= limit:
        return [list(range(n))]
    for k in dict.fromkeys((min(key_columns, n), min(key_columns, n, 1))):
        if k >= n:
            continue
        keys = list(range(k))
        base = table_width(widths[i] for i in keys)
        if base + max(widths[k:]) + CELL_OVERHEAD > limit:
            continue
        n_tables = len(_greedy(widths, keys, limit))
        # the narrowest limit that still needs no more tables evens the tables out
        narrowest = base + max(widths[k:]) + CELL_OVERHEAD
        for lim in range(narrowest, limit + 1):
            groups = _greedy(widths, keys, lim)
            if len(groups) <= n_tables:
                return groups
    return None


def width_limit(console: Console) -> int | None:
    """Characters available per line: the console's width on a terminal or with ``COLUMNS``
    set; None (no limit) for piped output without ``COLUMNS``."""
    if console.is_terminal or os.environ.get("COLUMNS", "").strip().isdigit():
        return console.width
    return None


class _AtWidth:
    """Render ``renderable`` at exactly ``width`` characters, wider than the console if need be."""

    def __init__(self, renderable: RenderableType, width: int) -> None:
        self.renderable = renderable
        self.width = width

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        yield from console.render(self.renderable, options.update_width(self.width))


def _rich_table(
    header: Sequence[str],
    rows: Sequence[Sequence[str]],
    cols: Sequence[int],
    widths: Sequence[int],
    title: str | None,
    left: int,
) -> Table:
    from rich.cells import cell_len
    from rich.table import Table
    from rich.text import Text

    def cell(j: int, s: str) -> Text:
        # justified here: rich skips justification for overflow="ignore", the one overflow
        # mode that can never shorten a cell
        pad = " " * (widths[j] - cell_len(s))
        return Text(s + pad if j < left else pad + s, no_wrap=True, overflow="ignore")

    t = Table(title=Text(title) if title else None)
    for j in cols:
        # fixed width = longest cell: headers wrap at spaces, cells fit exactly
        t.add_column(
            Text(header[j]),
            justify="left" if j < left else "right",
            width=widths[j],
            min_width=widths[j],
            overflow="fold",
        )
    for r in rows:
        t.add_row(*(cell(j, r[j]) for j in cols))
    return t


def print_table(
    console: Console,
    header: Sequence[str],
    rows: Sequence[Sequence[str]],
    title: str | None = None,
    key_columns: int = 1,
    left_columns: int | None = None,
) -> None:
    """Print ``rows`` under ``header`` so that no cell is ever cut, wrapped or ellipsised.

    Args:
        console: where to print; its width is the limit (see :func:`width_limit`).
        header: column titles (may wrap at spaces).
        rows: cell strings, one sequence per row, as long as ``header``.
        title: printed above the table; split tables get " (1/2)", " (2/2)", ...
        key_columns: leading columns repeated in every split table (names).
        left_columns: leading columns that are left-justified (default ``key_columns``); the
            others are right-justified (numbers).
    """
    from rich.cells import cell_len

    header = [str(h) for h in header]
    rows = [[str(c) for c in r] for r in rows]
    for r in rows:
        if len(r) != len(header):
            raise ValueError(f"row has {len(r)} cells, header {len(header)}: {r!r}")
    left = key_columns if left_columns is None else left_columns
    widths = column_widths(header, rows, cell_len)
    limit = width_limit(console)
    groups = split_columns(widths, limit, key_columns)
    if groups is None:
        _print_lines(console, header, rows, title)
        return
    for i, cols in enumerate(groups):
        part = f"({i + 1}/{len(groups)})" if len(groups) > 1 else ""
        t = _rich_table(
            header, rows, cols, widths, " ".join(s for s in (title, part) if s) or None, left
        )
        if limit is None:
            console.print(_AtWidth(t, table_width(widths[j] for j in cols)), crop=False)
        else:
            console.print(t)


def _print_lines(
    console: Console, header: Sequence[str], rows: Sequence[Sequence[str]], title: str | None
) -> None:
    """The narrow-terminal fallback: one ``header: value`` line per cell (the value alone under
    an empty header), rows apart."""
    if title:
        console.print(title, markup=False, highlight=False, soft_wrap=True)
    for i, r in enumerate(rows):
        if i or title:
            console.print()
        for h, c in zip(header, r, strict=True):
            console.print(
                f"{h}: {c}" if h.strip() else c, markup=False, highlight=False, soft_wrap=True
            )
