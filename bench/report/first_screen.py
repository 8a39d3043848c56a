"""The notes of the first screen, what ``bench run`` and ``bench score`` print around their
table by default: at most one line per warning or finding, each naming where report.md has it
in full. ``--wide`` prints the long forms instead (:func:`~posbench.report.notes.sanity_lines`,
:func:`~posbench.report.limit.limit_terminal_lines`, the paired tables)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from posbench.scenarios.text import fixed
from posbench.tables.run_tables import FLAG_MARK

#: what report.md flags a predictor for, as :func:`flagged` names it
BELOW_LIMIT = "below the limit"
LOSES_TO_CV = "loses to constant velocity"


def _names(names: Sequence[str]) -> str:
    return ", ".join(names) if names else "none"


def flagged(res: Mapping[str, Any]) -> dict[str, list[str]]:
    """Per predictor that report.md flags, what for (:data:`BELOW_LIMIT`: its mean error lies
    below the bound by more than its interval, results.json ``limit.below``;
    :data:`LOSES_TO_CV`: it loses to constant velocity, ``sanity.losses``)."""
    out: dict[str, list[str]] = {}
    for what, entries in (
        (BELOW_LIMIT, (res.get("limit") or {}).get("below", [])),
        (LOSES_TO_CV, (res.get("sanity") or {}).get("losses", [])),
    ):
        for e in entries:
            reasons = out.setdefault(str(e["predictor"]), [])
            if what not in reasons:
                reasons.append(what)
    return out


def mark_legend(res: Mapping[str, Any]) -> str:
    """The one line under the table that says what ``!`` means ("" when nothing is flagged)."""
    if not flagged(res):
        return ""
    return f"{FLAG_MARK.strip()} = report.md flags it (see the warning and note lines)"


def limit_legend(res: Mapping[str, Any]) -> str:
    """What the bound's rows are and what ``x limit`` is, in one line ("" without a bound)."""
    lim = res.get("limit")
    if not lim:
        return ""
    imu = [n for n, reads in (lim.get("reads_imu") or {}).items() if reads]
    which = (
        f" (the limit with IMU for {', '.join(imu)}, which read{'s' * (len(imu) == 1)} the IMU)"
        if imu and lim.get("name_imu")
        else ""
    )
    return (
        f"{lim['name']}: a bound under stated assumptions, not a predictor; "
        f"x limit = future mean / limit{which}"
    )


def below_line(res: Mapping[str, Any]) -> str:
    """The predictors below the limit, per data set, in one line ("" when none is)."""
    by_ds: dict[str, list[str]] = {}
    for b in (res.get("limit") or {}).get("below", []):
        names = by_ds.setdefault(str(b["dataset"]), [])
        if b["predictor"] not in names:
            names.append(str(b["predictor"]))
    if not by_ds:
        return ""
    where = "; ".join(f"{_names(names)} on {ds}" for ds, names in by_ds.items())
    return f'below the limit: {where}; why that can be: report.md "Below the limit"'


def sanity_short_lines(res: Mapping[str, Any]) -> list[str]:
    """One line per predictor and data set that loses to constant velocity (results.json
    ``sanity.losses``): by how much per kind; the intervals, query counts and what it means
    are in report.md ("Implausible results")."""
    grouped: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for loss in (res.get("sanity") or {}).get("losses", []):
        grouped.setdefault((str(loss["predictor"]), str(loss["dataset"])), []).append(loss)
    return [
        f"{name} {LOSES_TO_CV} on {ds}: "
        + ", ".join(f"{x['kind']} {fixed(float(x['diff_m']), 3, '+')} m" for x in losses)
        + " (report.md)"
        for (name, ds), losses in grouped.items()
    ]


def paired_line(res: Mapping[str, Any], held_out: bool = False) -> str:
    """The comparison with the baseline in one line: which predictors' future mean error is
    above or below the baseline's on the same queries, the 95 % interval of the difference
    excluding 0, and which are not decided ("" without a comparison). ``held_out``: over the
    drives no predictor trained or tuned on."""
    paired = res.get("paired") or {}
    base = paired.get("baseline")
    src = ((paired.get("held_out") or {}) if held_out else paired).get("overall") or {}
    if not base or not src:
        return ""
    groups: dict[str, list[str]] = {"better": [], "worse": [], "not decided": []}
    for name, kinds in src.items():
        e = kinds.get("future") or {}
        if e.get("diff_m") is None:
            continue
        if not e.get("conclusive"):
            groups["not decided"].append(name)
        else:
            groups["better" if float(e["diff_m"]) < 0 else "worse"].append(name)
    parts = "; ".join(f"{k} {', '.join(v)}" for k, v in groups.items() if v)
    where = " over the held-out drives" if held_out else ""
    return f"vs {base}{where}, future mean on the same queries (95 % CI): {parts} (--wide)"


def excluded_line(n_warm: int, n_noref: int) -> str:
    """The queries the headline leaves out, per predictor (warm-up, without a reference
    position), in one line."""
    return (
        f"left out, per predictor: {n_warm} warm-up queries, {n_noref} without a reference "
        "(report.md)"
    )
