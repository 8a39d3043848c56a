"""A run's report: ``report.md`` (the tables a person reads first, with their notes, the data
check, the plots and the glossary), its tables as CSV and LaTeX files (``tables/``) and, when
not drawn already, its figures. results.json and the traces are
:func:`posbench.saved_run.run.save_run`'s."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from posbench.figures.per_drive import DEFAULT_DRIVE_PLOTS
from posbench.figures.style import PlotsWritten, shown_format
from posbench.figures.writer import joined, write_plots, write_result_plots
from posbench.naming import plural
from posbench.report.data_check import report_lines as consistency_lines
from posbench.report.glossary import glossary_lines
from posbench.report.limit import limit_report_lines
from posbench.report.notes import (
    MISSING_NOTE,
    block_note,
    dataset_reference,
    excluded_note,
    fixes_scored,
    has_held_out_paired,
    has_paired,
    held_out_note,
    paired_note,
    statistics_note,
    trained_note,
    tuning_lines,
)
from posbench.report.outage_lengths import figure_file, outage_length_lines
from posbench.report.sections import answers_lines, gate_lines, sanity_report_lines, seeds_lines
from posbench.report.table_files import TABLE_FORMATS, write_tables
from posbench.scoring.reference import reference_lines, references
from posbench.scoring.schema import KINDS
from posbench.tables.breakdown_tables import (
    NOT_CONCLUSIVE,
    drives_table,
    label_table,
    outage_table,
    speed_table,
)
from posbench.tables.run_tables import dataset_table, summary_table, warmup_table
from posbench.tables.stat_tables import paired_label_table, paired_table
from posbench.tables.track import TRACK_NOTE, track_table
from posbench.tables.uncertainty import UNCERTAINTY_NOTE, uncertainty_table

if TYPE_CHECKING:
    from posbench.saved_run.run import Run


#: where a run's latency figures come from: a replay's (False) or an answers file's (True)
LATENCY_WHERE = {
    False: "measured in the replay's worker processes, which share the machine's cores "
    "(`bench latency` gives single-process figures).",
    True: "as the answers file gives them.",
}


def write_report(
    run: Run,
    out: Path,
    formats: Iterable[str] = ("png",),
    drive_plots: int | None = DEFAULT_DRIVE_PLOTS,
    table_formats: Iterable[str] = TABLE_FORMATS,
    plots: PlotsWritten | None = None,
) -> list[Path]:
    """Write the run's plots (in each of ``formats``: png, svg, pdf; ValueError on others),
    ``report.md`` and its tables as files (``table_formats``: csv, latex; see
    :func:`posbench.report.table_files.write_tables`) into ``out``; return the paths written.
    The run itself (results.json, traces) is written by
    :func:`posbench.saved_run.run.save_run`. ``plots``: the plots already drawn into ``out``
    (``bench run`` draws them while it aggregates,
    :mod:`posbench.pipeline.jobs`); None draws them here."""
    shown = "." + shown_format(formats)  # checks the formats before anything is written
    out.mkdir(parents=True, exist_ok=True)
    if plots is None:
        plots = write_plots(run.trace_set, run.results, out, formats, drive_plots)
    plots = joined(plots, write_result_plots(run.results, out, formats))
    (out / "report.md").write_text(
        render_markdown(
            run.results,
            [p.relative_to(out).as_posix() for p in plots.files if p.suffix == shown],
            plot_notes=plots.notes,
        )
    )
    return [
        *plots.files,
        out / "report.md",
        *write_tables(run.results, out / "tables", table_formats),
    ]


def render_markdown(
    res: dict[str, Any], plots: list[str], plot_notes: dict[str, str] | None = None
) -> str:
    """The report as Markdown. ``plots``: figure files relative to the report (those under
    ``drives/`` are listed as links, the others shown); ``plot_notes``: figure name -> why it
    was not written."""
    cfg = res["config"]
    lines = [
        "# posbench report",
        "",
        f"Command: `{res['command']}`",
        "",
        f"posbench {res['versions'].get('posbench')} at commit `{res.get('git_commit')}`; "
        f"horizon {cfg['horizon_s']} s; now-queries every {cfg['now_step_s']} s; "
        f"GPS profile `{cfg['gps_profile']}`; dropouts `{cfg['dropouts']}`; "
        f"seed {cfg['seed']}.",
        "",
        *[f"- {line[0].upper()}{line[1:]}." for line in reference_lines(res, fixes_scored(res))],
        "",
        "Errors are Euclidean distances in metres, in a local ENU frame, to each data set's "
        "reference named above. "
        "`future` = position at fix time + horizon, asked at the fix; `now` = current position, "
        "asked every now-step between fixes. Latency: `step` = one `observe_gps` plus the "
        "future query, `query` = one between-fix `position_at`, "
        + LATENCY_WHERE[bool(res.get("answers"))],
        "",
    ]
    lines += consistency_lines(res)
    lines += answers_lines(res)
    if statistics_note(res):
        lines += [statistics_note(res), ""]
    lines += ["## All drives", "", summary_table(res).markdown(), ""]
    for note in (trained_note(res), excluded_note(res), MISSING_NOTE):
        if note:
            lines += [note, ""]
    lines += limit_report_lines(res)
    lines += sanity_report_lines(res)
    lines += tuning_lines(res)
    if has_paired(res):
        lines += [
            f"### Against the baseline `{res['paired']['baseline']}`",
            "",
            paired_note(res),
            "",
            paired_table(res).markdown(),
            "",
        ]
        if trained_note(res):
            lines += [
                "`*` after a name: a learned predictor trained on some of these drives; "
                "its comparison over the held-out drives only is below.",
                "",
            ]
    if res.get("track_errors", {}).get("predictors"):
        lines += ["### Where the error points", "", TRACK_NOTE, "", track_table(res).markdown(), ""]
    if "uncertainty" in res:
        lines += [
            "### Uncertainty",
            "",
            UNCERTAINTY_NOTE,
            "",
            uncertainty_table(res).markdown(),
            "",
        ]
        if res["uncertainty"].get("by_since_fix"):
            lines += [
                "By time since the last fix (no CI):",
                "",
                uncertainty_table(res, "by_since_fix").markdown(),
                "",
            ]
    lines += seeds_lines(res)
    if res.get("held_out_all"):
        ho = res["held_out_all"]
        lines += [
            f"## Held-out drives ({len(ho['drives'])}: no predictor of this run was trained "
            f"or tuned on them)",
            "",
            summary_table(res, held_out=True).markdown(),
            "",
        ]
        if has_held_out_paired(res):
            lines += [
                paired_note(res, " on the held-out drives"),
                "",
                paired_table(res, held_out=True).markdown(),
                "",
            ]
    warm = warmup_table(res)
    if (warm.frame[["future_n", "now_n", "missing"]].to_numpy() > 0).any():
        lines += [
            "## Warm-up queries (left out above)",
            "",
            "Queries issued before a drive's second received fix: a cold start, not a prediction.",
            "",
            warm.markdown(),
            "",
        ]
    fixes_by_dataset = fixes_scored(res)
    refs = references(res)
    for ds in res["by_dataset"]:
        drives = [d for d in res["drives"] if d["dataset"] == ds]
        lines += [
            f"## Data set `{ds}`",
            "",
            f"{plural(len(drives), 'drive')}; "
            f"{dataset_reference(refs.get(ds), fixes_by_dataset.get(ds))}.",
            "",
        ]
        lines += [dataset_table(res, ds).markdown(), ""]
        note = block_note([s[k] for s in res["by_dataset"][ds].values() for k in KINDS], f"`{ds}`")
        if note:
            lines += [note, ""]
        if has_paired(res):
            lines += [paired_note(res, f" in `{ds}`"), "", paired_table(res, ds).markdown(), ""]
        lines += [
            "### Route type (paper's Table I layout), future point, mean error in cm (queries)",
            "",
            label_table(res, ds, "future").markdown(),
            "",
        ]
        if res.get("statistics"):
            lines += [
                f"`{NOT_CONCLUSIVE}`: not conclusive, the cell's 95 % interval is wider "
                f"than its value.",
                "",
            ]
        lines += [
            "### Route type, current position (now), mean error in cm (queries)",
            "",
            label_table(res, ds, "now").markdown(),
            "",
        ]
        if has_paired(res):
            base = res["paired"]["baseline"]
            lines += [
                f"### Route type, future point, Δ mean vs `{base}` in cm (queries both answered)",
                "",
                paired_label_table(res, ds, "future").markdown(),
                "",
            ]
        ho = res.get("held_out", {}).get(ds)
        if ho:
            lines += [
                f"### Held-out drives only ({len(ho['drives'])} of {len(drives)})",
                "",
                f"{held_out_note(res, ho['excluded_training_drives'])}. On the held-out "
                f"drives ({', '.join(ho['drives']) or 'none'}):",
                "",
            ]
            if ho["drives"] and has_held_out_paired(res, ds):
                lines += [
                    paired_note(res, f" on the held-out drives of `{ds}`"),
                    "",
                    paired_table(res, ds, held_out=True).markdown(),
                    "",
                ]
            if ho["drives"]:
                lines += [
                    "Future point, mean error in cm (queries):",
                    "",
                    label_table(res, ds, "future", held_out=True).markdown(),
                    "",
                    "Current position (now), mean error in cm (queries):",
                    "",
                    label_table(res, ds, "now", held_out=True).markdown(),
                    "",
                ]
    if res.get("by_speed"):
        lines += [
            "## Future-point error by speed, mean [m] (queries)",
            "",
            speed_table(res).markdown(),
            "",
        ]
    if res.get("outages"):
        lines += [
            "## GPS outages",
            "",
            "Current-position (now) error by time since the last received fix, mean [m] "
            "(queries within 0.05 s of each checkpoint), and per outage: ADE (mean error "
            "over the outage), FDE (error just before the fix returns), miss rate (share of "
            "outages with FDE > 2 m).",
            "",
        ]
        lines += [outage_table(res).markdown(), ""]
    lines += outage_length_lines(res, plots)
    lines += gate_lines(res)
    lines += ["## Drives", ""]
    lines += [drives_table(res).markdown(), ""]
    note = block_note(
        [
            d["predictors"][p]["future"]
            for d in res["drives"]
            if not d["skipped"]
            for p in d.get("predictors", {})
        ],
        "Each row",
    )
    if note:
        lines += [note, ""]
    warn = [(d["name"], w) for d in res["drives"] for w in d["warnings"]]
    if warn:
        lines += ["## Loader warnings", ""] + [f"- `{n}`: {w}" for n, w in warn] + [""]
    if plots or plot_notes:
        curve = figure_file(plots) if res.get("outage_lengths") else None  # in its section
        shown = [p for p in plots if not p.startswith("drives/") and p != curve]
        per_drive = [p for p in plots if p.startswith("drives/")]
        lines += ["## Plots", ""]
        lines += [
            f"![{p}]({p})" if p.endswith((".png", ".svg")) else f"- [{p}]({p})" for p in shown
        ] + [""] * bool(shown)
        if plot_notes:
            lines += ["Not drawn:", ""] + [f"- {k}: {v}" for k, v in plot_notes.items()] + [""]
        if per_drive:
            lines += ["Future-point error over time, per drive:", ""]
            lines += [
                f"- [{Path(p).stem.removesuffix('-error_over_time')}]({p})" for p in per_drive
            ] + [""]
    if res.get("paper_figures"):
        lines += ["## The paper's figures, from this run", ""]
        for f in res["paper_figures"]:
            lines += [f"![{f['file']}]({f['file']})", "", f"*{f['caption']}*", ""]
    lines += (
        ["## Data", ""]
        + [
            f"- `{m['path']}`: {m['files']} files, {m['bytes']} bytes, "
            f"sha256 `{m['sha256'][:16]}...`"
            for m in res["data"]
        ]
        + [""]
    )
    lines += glossary_lines(res)
    return "\n".join(lines)
