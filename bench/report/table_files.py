"""A run's report tables as files beside report.md: which tables the report has
(:func:`report_tables`), each written as full-precision CSV and/or booktabs LaTeX
(:func:`write_tables`), and the ``--format`` / ``--table-format`` lists that choose them."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from posbench.errors import UsageError
from posbench.report.notes import has_held_out_paired, has_paired
from posbench.scoring.schema import KINDS
from posbench.tables.breakdown_tables import (
    drives_table,
    gate_table,
    label_table,
    outage_table,
    speed_table,
)
from posbench.tables.outage_lengths import outage_length_tables
from posbench.tables.run_tables import dataset_table, summary_table, warmup_table
from posbench.tables.stat_tables import paired_label_table, paired_table, seeds_table
from posbench.tables.table import Table
from posbench.tables.track import track_table
from posbench.tables.uncertainty import uncertainty_table

#: what ``--format`` may list: report.md is always written; csv and latex add table files
REPORT_FORMATS = ("md", "csv", "latex")
#: table file formats beside report.md: full-precision CSV, booktabs LaTeX (the default: both)
TABLE_FORMATS = ("csv", "latex")


def parse_report_formats(text: str, option: str = "--format") -> tuple[str, ...]:
    """``--format md,csv,latex`` -> the table file formats to write beside report.md
    (``("csv", "latex")``; ``md`` alone: none)."""
    items = [f.strip().lower() for f in text.split(",") if f.strip()]
    if not items:
        raise UsageError(f"{option}: give one or more of {', '.join(REPORT_FORMATS)}")
    for f in items:
        if f not in REPORT_FORMATS:
            raise UsageError(
                f"{option}: unknown format {f!r}; use one or more of "
                f"{', '.join(REPORT_FORMATS)} (e.g. md,csv)"
            )
    return tuple(f for f in REPORT_FORMATS[1:] if f in items)


def report_tables(res: dict[str, Any]) -> list[Table]:
    """Every table of the report, as numeric tables (for the CSV and LaTeX forms)."""
    if not res.get("drives"):
        return []
    tables = [summary_table(res), warmup_table(res)]
    if has_paired(res):
        tables.append(paired_table(res))
    if res.get("seeds"):
        tables.append(seeds_table(res))
    if res.get("held_out_all"):
        tables.append(summary_table(res, held_out=True))
    if has_held_out_paired(res):
        tables.append(paired_table(res, held_out=True))
    for ds in res["by_dataset"]:
        tables += [
            dataset_table(res, ds),
            label_table(res, ds, "future"),
            label_table(res, ds, "now"),
        ]
        if has_paired(res):
            tables += [paired_table(res, ds), paired_label_table(res, ds, "future")]
        if res.get("held_out", {}).get(ds, {}).get("drives"):
            tables += [label_table(res, ds, k, held_out=True) for k in KINDS]
            if has_held_out_paired(res, ds):
                tables.append(paired_table(res, ds, held_out=True))
    if res.get("track_errors", {}).get("predictors"):
        tables.append(track_table(res))
    if "uncertainty" in res:
        tables.append(uncertainty_table(res))
        if res["uncertainty"].get("by_since_fix"):
            tables.append(uncertainty_table(res, "by_since_fix"))
    if res.get("by_speed"):
        tables.append(speed_table(res))
    if res.get("outages"):
        tables.append(outage_table(res))
    tables += outage_length_tables(res)
    if res.get("gate", {}).get("enabled"):
        tables.append(gate_table(res))
    tables.append(drives_table(res))
    return tables


def write_tables(
    res: dict[str, Any], folder: Path, table_formats: Iterable[str] = TABLE_FORMATS
) -> list[Path]:
    """Each report table as ``NAME.csv`` (full precision) and/or ``NAME.tex`` (booktabs) in
    ``folder``, as ``table_formats`` asks; return the paths written."""
    written = []
    wanted = set(table_formats)
    for t in report_tables(res) if wanted else []:
        folder.mkdir(parents=True, exist_ok=True)
        forms = (("csv", "csv", t.csv), ("latex", "tex", t.latex))
        for ext, text in ((ext, render()) for name, ext, render in forms if name in wanted):
            path = folder / f"{t.name}.{ext}"
            path.write_text(text)
            written.append(path)
    return written
