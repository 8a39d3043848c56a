"""What ``bench run`` and ``bench score`` print when the run is done: the headline tables
(errors with their intervals, the paired comparison, seeds, held-out drives), their notes and
one line naming what was written. All from the saved :class:`~posbench.saved_run.run.Run`."""

from __future__ import annotations

from pathlib import Path

from posbench.cli.terminal import QUIET, console, print_table, say, verbosity, warn
from posbench.naming import plural
from posbench.pipeline.publish import Published


def print_run_summary(published: Published) -> None:
    """The tables and notes of a finished run, then the ``wrote ...`` line (nothing when
    quiet)."""
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
    if verbosity() <= QUIET:
        return
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
            title=f"held-out {plural(len(ho['drives']), 'drive')} (no predictor "
            f"trained or tuned on them) - errors in metres",
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
    if published.run.folder is not None:
        say(written_summary(published.run.folder, published.written, published.removed))
    if published.recording is not None:
        say(f"wrote {published.recording} (open it with: bench view {published.recording})")


def written_summary(out: Path, written: list[Path], removed: list[Path]) -> str:
    """One line naming what the run wrote into ``out`` (and removed of an earlier run)."""
    top = [p.name for p in written if p.parent == out]
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
