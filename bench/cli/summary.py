"""What ``bench run`` and ``bench score`` print when the run is done: the headline tables
(errors with their intervals, the paired comparison, seeds, held-out drives), their notes and
one line naming what was written. All from the saved :class:`~posbench.saved_run.run.Run`."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from posbench.cli.terminal import QUIET, VERBOSE, console, print_table, say, verbosity, warn
from posbench.naming import plural
from posbench.pipeline.publish import Published


def print_run_summary(published: Published, wide: bool = False) -> None:
    """What a finished run prints (nothing but its warnings when quiet): by default the first
    screen (:func:`print_first_screen`); ``wide`` (``--wide``, implied by ``-v``) the full
    summary (:func:`print_wide_summary`). Then the ``wrote ...`` line."""
    from posbench.report.first_screen import sanity_short_lines
    from posbench.report.notes import sanity_lines

    res = published.run.results
    wide = wide or verbosity() >= VERBOSE
    if verbosity() <= QUIET:
        for line in sanity_lines(res) if wide else sanity_short_lines(res):
            warn(line)
        return
    if wide:
        print_wide_summary(published)
    else:
        print_first_screen(published)
    if published.run.folder is not None:
        say(written_summary(published.run.folder, published.written, published.removed, wide))
    if published.recording is not None:
        say(f"wrote {published.recording} (open it with: bench view {published.recording})")


def print_first_screen(published: Published) -> None:
    """The summary read at a glance: each data set's reference, one table (future and now
    mean with their intervals, x limit, median step; ``!`` beside a predictor report.md
    flags), then at most one line per warning or finding, each naming where report.md has it
    in full. The held-out drives and the seeds, where the run has them, get a narrow table
    each."""
    from posbench.report.first_screen import (
        below_line,
        excluded_line,
        flagged,
        limit_legend,
        mark_legend,
        paired_line,
        sanity_short_lines,
    )
    from posbench.report.notes import excluded_counts, fixes_scored, trained_note
    from posbench.scoring.reference import reference_lines
    from posbench.tables.run_tables import first_screen_table
    from posbench.tables.stat_tables import seeds_table
    from posbench.tables.table import Table

    res = published.run.results
    scored = sum(1 for d in res["drives"] if not d["skipped"])
    for line in reference_lines(res, fixes_scored(res)):
        say(line.replace("`", ""))  # one line per data set, wrapped to the terminal's width
    flags = set(flagged(res))
    headline = first_screen_table(res, flags)
    print_table(
        console,
        headline.header(),
        headline.cells(),
        title=f"{plural(scored, 'drive')} - errors in metres [95 % CI], latency [us]; "
        "every column: --wide",
    )
    for note in (trained_note(res), limit_legend(res), mark_legend(res)):
        if note:
            say(note)
    for line in sanity_short_lines(res):
        warn(line)
    notes = [below_line(res), paired_line(res)]
    if res["predictors"]:
        notes.append(excluded_line(*excluded_counts(res)))
    for note in notes:
        if note:
            say(note)
    if res.get("held_out_all"):
        ho = res["held_out_all"]
        held = first_screen_table(res, flags, held_out=True)
        print_table(
            console,
            held.header(),
            held.cells(),
            title=held_out_title(ho),
        )
        note = paired_line(res, held_out=True)
        if note:
            say(note)
    if res.get("seeds"):
        st = seeds_table(res)
        spread = [c for c in st.frame.columns if c.endswith(("_seeds_mean", "_sd"))]
        narrow = Table(
            st.frame[["predictor", *(c for c in spread if "_diff_" not in c)]], st.name, st.labels
        )
        print_table(
            console,
            narrow.header(),
            narrow.cells(),
            title=f"over seeds {', '.join(map(str, res['seeds']['seeds']))}: mean error [m]",
        )


def print_wide_summary(published: Published) -> None:
    """The full summary: every column of the headline table (paged to the terminal's width),
    each note in full and the paired tables."""
    from posbench.report.limit import limit_terminal_lines
    from posbench.report.notes import (
        excluded_note,
        fixes_scored,
        has_held_out_paired,
        has_paired,
        sanity_lines,
        trained_note,
    )
    from posbench.scoring.reference import reference_lines
    from posbench.tables.run_tables import summary_table
    from posbench.tables.stat_tables import paired_table, seeds_table

    res = published.run.results
    for line in sanity_lines(res):
        warn(line)
    scored = sum(1 for d in res["drives"] if not d["skipped"])
    for line in reference_lines(res, fixes_scored(res)):
        say(line.replace("`", ""))  # one line per data set, wrapped to the terminal's width
    headline = summary_table(res, compact=True)
    print_table(
        console,
        headline.header(),
        headline.cells(),
        title=f"{plural(scored, 'drive')} - errors in metres [95 % CI], latency in microseconds",
    )
    for note in (trained_note(res), excluded_note(res), *limit_terminal_lines(res)):
        if note:
            say(note)
    if has_paired(res):
        paired = paired_table(res)
        print_table(
            console,
            paired.header(),
            paired.cells(),
            title=f"vs {res['paired']['baseline']}: Δ mean error [m], same queries "
            f"[95 % CI]; * CI excludes 0",
        )
    if res.get("seeds"):
        st = seeds_table(res)
        print_table(
            console,
            st.header(),
            st.cells(),
            title=f"over seeds {', '.join(map(str, res['seeds']['seeds']))}: mean error "
            f"[m] (figures and traces: seed {res['seeds']['traces_seed']})",
        )
    if res.get("held_out_all"):
        ho = res["held_out_all"]
        held = summary_table(res, held_out=True, compact=True)
        print_table(
            console,
            held.header(),
            held.cells(),
            title=held_out_title(ho),
        )
        if has_held_out_paired(res):
            hp = paired_table(res, held_out=True)
            print_table(
                console,
                hp.header(),
                hp.cells(),
                title=f"held-out drives vs {res['paired']['baseline']}: Δ mean error [m] "
                f"[95 % CI]; * CI excludes 0",
            )


#: the suffixes of the figures a run writes (``--plot-format``)
FIGURE_SUFFIXES = (".png", ".svg", ".pdf")


def held_out_title(held_out: Mapping[str, Any]) -> str:
    """The title of the held-out drives' table (``held_out``: results.json's
    ``held_out_all``)."""
    return (
        f"held-out {plural(len(held_out['drives']), 'drive')} (no predictor trained or tuned "
        "on them) - errors in metres"
    )


def written_summary(out: Path, written: list[Path], removed: list[Path], wide: bool = True) -> str:
    """One line naming what the run wrote into ``out`` (and removed of an earlier run);
    unless ``wide``, its figures counted rather than named."""
    top = [p.name for p in written if p.parent == out]
    if not wide:
        figures = [n for n in top if n.endswith(FIGURE_SUFFIXES)]
        top = [n for n in top if n not in figures]
        if figures:
            top.append(plural(len(figures), "figure"))
    text = f"wrote {out}/: " + ", ".join(top)
    nested: dict[str, int] = {}
    for p in written:
        if p.parent != out:
            folder = p.relative_to(out).parts[0]
            nested[folder] = nested.get(folder, 0) + 1
    what = {"drives": "per-drive plot", "tables": "table file"}
    for folder, n in nested.items():
        text += f", {plural(n, what.get(folder, 'file'))} in {folder}/"
    if removed:
        text += f" (removed {plural(len(removed), 'file')} of an earlier run there)"
    return text
