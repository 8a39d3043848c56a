"""Saved runs compared, as one object: what ``bench compare`` prints and what
:func:`posbench.compare` returns.

:func:`compare_runs` aligns one figure of every run (:mod:`posbench.comparison.align`), adds
each later run's paired difference from the first (:mod:`posbench.comparison.paired`),
optionally the uncertainty figures side by side (:mod:`posbench.comparison.uncertainty`),
and checks the accuracy gates (:mod:`posbench.comparison.gates`). The result,
:class:`Comparison`, keeps the numeric frames, the display tables and the notes; it renders
nothing by itself.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from posbench.comparison.align import Metric
from posbench.comparison.gates import GateCheck
from posbench.errors import UsageError
from posbench.saved_run.run import Run
from posbench.tables.table import Table

#: the row scopes a comparison may show (``--scope``)
SCOPES = ("all", "dataset", "route", "drive", "since-fix")
#: scope names -> row scopes of the tables
SCOPE_ROWS = {"route": "route type", "since-fix": "since fix"}


@dataclass
class Comparison:
    """Saved runs side by side.

    Attributes:
        runs: the runs, the first one the reference.
        labels: a short unique name per run (folder names).
        metric: the figure compared (``future.mean_m``, ...).
        table: the display table (``value [CI]`` per run, ``Δ`` columns).
        frame: the numbers behind it: per row (scope, dataset, group, predictor) each run's
            value [m], CI bounds and query count, and each later run's paired difference.
        differences: one line per configuration item on which the runs disagree.
        gates: the accuracy gates checked (NEW = the second run against OLD = the first).
        uncertainty: the uncertainty figures side by side (table, frame), if asked for.
        notes: what the uncertainty table cannot show (runs without those figures), and the
            runs that did not complete (compared with ``allow_failed``).
    """

    runs: list[Run]
    labels: list[str]
    metric: Metric
    table: Table
    frame: pd.DataFrame
    differences: list[str] = field(default_factory=list)
    gates: list[GateCheck] = field(default_factory=list)
    uncertainty: tuple[Table, pd.DataFrame] | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """Whether every gate passed (True without gates)."""
        return not any(g.failed for g in self.gates)

    def figure(self) -> Any:
        """The whole-run figure of every predictor, one bar per run, 95 % CI whiskers (a
        matplotlib figure)."""
        from posbench.comparison.views import comparison_figure

        return comparison_figure(self.runs, self.labels, self.metric)

    def __repr__(self) -> str:
        rows = (self.frame["scope"] == "all").sum() if "scope" in self.frame else 0
        lines = [
            f"Comparison of {len(self.runs)} runs ({', '.join(self.labels)}): {self.metric}, "
            f"{len(self.frame)} rows ({rows} whole-run)"
        ]
        if self.differences:
            lines.append(f"  configurations differ: {'; '.join(self.differences)}")
        if self.gates:
            failed = sum(g.failed for g in self.gates)
            lines.append(f"  gates: {len(self.gates) - failed} passed, {failed} failed")
        return "\n".join(lines)


def row_scopes(scopes: Sequence[str], uncertainty: bool) -> list[str]:
    """``--scope`` names (:data:`SCOPES`) as the tables' row scopes, checked."""
    from posbench.checks import check_choice

    for s in scopes:
        check_choice(s, SCOPES, "--scope")
    if "since-fix" in scopes and not uncertainty:
        raise UsageError("--scope since-fix: rows of the uncertainty table only; add --uncertainty")
    return [SCOPE_ROWS.get(s, s) for s in scopes]


def compare_runs(
    runs: Sequence[Run | str | Path],
    metric: str | Metric = "future.mean_m",
    scopes: Sequence[str] = ("all", "dataset"),
    seed: int = 0,
    gates: Sequence[str] = (),
    uncertainty: bool = False,
    allow_config_change: bool = False,
    allow_failed: bool = False,
) -> Comparison:
    """Compare saved runs (objects or folders): ``metric`` of each aligned per predictor,
    data set, route type and drive (``scopes``), each later run's paired difference from the
    first (cluster bootstrap seeded ``seed``), with ``uncertainty`` the uncertainty figures
    too, and the ``gates`` (``PREDICTOR:KIND.STAT:TOL``, exactly two runs) checked.
    ``allow_failed``: also runs that did not complete (results.json ``status`` failed or
    interrupted), each named in a note.

    Raises:
        UsageError: a bad metric, scope or gate; gates over runs whose configurations differ
            (unless ``allow_config_change``).
        DataError: a folder that holds no saved run; a run that failed or was interrupted
            (unless ``allow_failed``).
    """
    from posbench.comparison.align import config_differences, run_labels
    from posbench.comparison.gates import Gate, check_gates
    from posbench.comparison.views import comparison_table
    from posbench.saved_run.run import COMPLETE, check_complete, load_run

    m = metric if isinstance(metric, Metric) else Metric.parse(metric)
    rows = row_scopes(scopes, uncertainty)
    parsed = [Gate.parse(g) for g in gates]
    if parsed and len(runs) != 2:
        raise UsageError(f"--fail-if-worse compares exactly two runs (OLD NEW); got {len(runs)}")
    loaded = [r if isinstance(r, Run) else load_run(r, allow_failed) for r in runs]
    for r in loaded if not allow_failed else ():
        check_complete(r)
    labels = run_labels(loaded)
    diffs = config_differences(loaded, labels)
    if parsed and diffs and not allow_config_change:
        raise UsageError(
            "the runs' configurations differ ("
            + "; ".join(diffs)
            + "): their figures are not comparable; re-run one, or pass "
            "--allow-config-change"
        )
    table, frame = comparison_table(loaded, labels, m, rows, seed)
    out = Comparison(loaded, labels, m, table, frame, diffs)
    if uncertainty:
        from posbench.comparison.uncertainty import missing_notes, uncertainty_comparison

        u_table, u_frame = uncertainty_comparison(loaded, labels, rows)
        out.uncertainty = (u_table, u_frame)
        out.notes = missing_notes(loaded, labels)
        if u_frame.empty:
            out.notes.append("no run has uncertainty figures to compare")
    if parsed:
        out.gates = check_gates(loaded[0], loaded[1], parsed, seed)
    out.notes += [
        f"{label} is {'an' if r.status[0] in 'aeiou' else 'a'} {r.status} run: {r.reason}"
        for r, label in zip(loaded, labels, strict=True)
        if r.status != COMPLETE
    ]
    return out
