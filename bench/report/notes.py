"""The sentences around report.md's tables (and the terminal's): which model a learned
predictor used and which drives it was trained on, what the headline leaves out, how the
intervals and the paired comparison were made."""

from __future__ import annotations

from typing import Any

from posbench.scenarios.text import fixed
from posbench.scoring.schema import KINDS
from posbench.tables.run_tables import trained_in_run
from posbench.tables.stat_tables import block_lengths

MISSING_NOTE = (
    "`missing`: queries a predictor answered with no position (NaN) although a "
    "reference exists, e.g. before its first fix; they are counted, not averaged, so "
    "a predictor cannot look better by abstaining."
)


def model_text(model: dict[str, Any]) -> str:
    """How a report names a learned predictor's model: the bundled one, or its file."""
    if model.get("bundled"):
        text = str(model.get("model", ""))  # "bundled (predictors/<pkg>/bundled/model.onnx)"
        path = (
            text[text.find("(") + 1 : text.rfind(")")]
            if "(" in text
            else "predictors/lstm/bundled/model.onnx"
        )
        return f"the bundled model, {path}"
    return f"model {model['model']}"


def trained_note(res: dict[str, Any]) -> str:
    """The footnote of ``*`` rows: which model, trained on which of the run's drives."""
    trained = trained_in_run(res)
    if not trained:
        return ""
    n_drives = sum(1 for d in res["drives"] if not d["skipped"])
    parts = [
        f"{p} ({model_text(res['models'][p])}) was trained on {len(d)} of these {n_drives} drives"
        for p, d in trained.items()
    ]
    return "* " + "; ".join(parts) + ": its figures on them flatter it; see the held-out table."


def drive_condition(res: dict[str, Any], drive: dict[str, Any]) -> str:
    """The GPS condition a drive of a saved run was fed under; runs before schema 1.6 did
    not record it: their profile for a drive scored against its truth, else ``native``."""
    if drive.get("gps_condition"):
        return str(drive["gps_condition"])
    profile = res["config"].get("gps_profile", "native")
    return profile if drive.get("reference") == "truth" and profile != "auto" else "native"


def fixes_scored(res: dict[str, Any]) -> dict[str, str]:
    """Per data set (of the drives scored), which fixes the run fed and scored, in words: the
    recording's own receiver or fixes simulated from the truth (with drive counts when a
    data set mixes them)."""
    from posbench.config import GPS_CONDITIONS, fixes_description
    from posbench.naming import plural

    by_ds: dict[str, dict[str, int]] = {}
    for d in res["drives"]:
        if d["skipped"]:
            continue
        conds = by_ds.setdefault(d["dataset"], {})
        cond = drive_condition(res, d)
        conds[cond] = conds.get(cond, 0) + 1
    out = {}
    for ds, conds in by_ds.items():
        if len(conds) == 1:
            out[ds] = fixes_description(next(iter(conds)))
        else:
            out[ds] = "; ".join(
                f"{fixes_description(c)} ({plural(n, 'drive')})"
                for c, n in sorted(conds.items(), key=lambda cn: GPS_CONDITIONS.index(cn[0]))
            )
    return out


def fixes_lines(res: dict[str, Any], dataset: str | None = None) -> list[str]:
    """``fixes scored in `DATA SET`: ...`` per data set (or for ``dataset`` only):
    :func:`fixes_scored` as lines for the terminal and report.md."""
    return [
        f"fixes scored in `{ds}`: {text}"
        for ds, text in fixes_scored(res).items()
        if dataset is None or ds == dataset
    ]


def excluded_counts(res: dict[str, Any]) -> tuple[int, int]:
    """Per predictor (the first: every predictor is asked the same queries), the queries the
    headline figures leave out: ``(warm-up, without a reference position)``."""
    ex = res.get("excluded", {})
    first = next(iter(res["predictors"]), None)
    if first is None:
        return 0, 0
    warm = ex.get("warmup", {}).get(first, {})
    n_warm = sum(warm.get(k, {}).get("count", 0) + warm.get(k, {}).get("missing", 0) for k in KINDS)
    return n_warm, sum(ex.get("no_reference", {}).get(first, {}).values())


def excluded_note(res: dict[str, Any]) -> str:
    """One sentence: how many queries the headline figures leave out, and why."""
    if next(iter(res["predictors"]), None) is None:
        return ""
    n_warm, n_noref = excluded_counts(res)
    return (
        f"Excluded from these figures, per predictor: {n_warm} warm-up queries (issued before "
        f"a drive's second received fix, when no predictor can know a velocity) and "
        f"{n_noref} queries without a reference position (past the end of the truth or of "
        f"the fixes)."
    )


def has_paired(res: dict[str, Any]) -> bool:
    """Whether the run compared its predictors with a baseline (schema 1.1, a baseline, and
    another predictor)."""
    paired = res.get("paired") or {}
    return bool(paired.get("baseline")) and bool(paired.get("overall"))


def has_held_out_paired(res: dict[str, Any], dataset: str | None = None) -> bool:
    """Whether the run holds the paired comparison over held-out drives (overall, or in
    ``dataset``)."""
    held = (res.get("paired") or {}).get("held_out") or {}
    src = held.get("overall") if dataset is None else held.get("by_dataset", {}).get(dataset)
    return has_paired(res) and bool(src)


def statistics_note(res: dict[str, Any]) -> str:
    """One sentence: how the intervals were computed (empty for runs without them)."""
    st = res.get("statistics")
    if not st:
        return ""
    return (
        f"`value [lo, hi]`: {100 * st['level']:g} % confidence interval, cluster bootstrap "
        f"over drives ({st['resamples']} resamples, seed {st['seed']}); a figure from a "
        f"single drive resamples blocks of contiguous queries instead (block bootstrap). "
        f"See the glossary at the end."
    )


def paired_note(res: dict[str, Any], where: str = "") -> str:
    """What the paired table shows."""
    base = res["paired"]["baseline"]
    return (
        f"Each predictor against `{base}`{where}, on the queries both answered: Δ mean = "
        f"its mean error minus `{base}`'s (negative: better than `{base}`), with its 95 % "
        f"interval (drives resampled jointly), `*` where the interval excludes 0; drives "
        f"won = drives on which its mean error is below `{base}`'s."
    )


def block_note(summaries: list[dict[str, Any]], what: str) -> str:
    """A sentence naming the block lengths of the single-drive intervals among ``summaries``."""
    lengths = block_lengths(summaries)
    if not lengths:
        return ""
    span = f"{lengths[0]}" if len(lengths) == 1 else f"{lengths[0]} to {lengths[-1]}"
    return (
        f"{what}: one drive, so the intervals come from a block bootstrap of its "
        f"contiguous queries (blocks of {span} queries), not from resampling drives."
    )


def _interval(ci: list[float] | None) -> str:
    """`` [lo, hi]`` of a 95 % interval, or nothing for a run saved without one."""
    return f" [{fixed(ci[0], 3)}, {fixed(ci[1], 3)}]" if ci else ""


def sanity_lines(res: dict[str, Any]) -> list[str]:
    """One line per predictor and data set that loses to cv (its kinds joined), e.g.
    ``kf loses to constant velocity on comma2k19: future +0.120 m [0.083, 0.157] (297
    queries); ...``, then a hint: a tuned baseline's tuning may not fit (see bench tune);
    for any other, its wins prove nothing there. Empty when none does (or cv was not run)."""
    section = res.get("sanity") or {}
    grouped: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for loss in section.get("losses", []):
        grouped.setdefault((loss["predictor"], loss["dataset"]), []).append(loss)
    lines = []
    for (name, ds), losses in grouped.items():
        parts = "; ".join(
            f"{x['kind']} {fixed(x['diff_m'], 3, '+')} m{_interval(x.get('ci95'))} "
            f"({x['queries']} queries)"
            for x in losses
        )
        hint = (
            "its tuning or inputs may not fit these sensors (see bench tune)"
            if name in (res.get("tuning") or {})
            else "a win of it over another method proves nothing on this data"
        )
        lines.append(f"{name} loses to constant velocity on {ds}: {parts}; {hint}")
    return lines


def _condition_text(condition: str, entry: dict[str, Any], file: str) -> str:
    """``rtk: cov_scale=0.708 (how)``: one GPS condition's tuned values, how they were
    obtained, and their file where it is not the predictor's."""
    values = (
        ", ".join(
            f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in entry["params"].items()
        )
        or "defaults"
    )
    other = entry.get("file", file)
    source = f" from `{other}`" if other != file else ""
    how = f" ({entry['how']})" if entry.get("how") else ""
    return f"{condition}: {values}{source}{how}"


def tuning_lines(res: dict[str, Any]) -> list[str]:
    """One line per predictor that ran with tuned parameters (results.json ``tuning``): the
    file (built-in or the user's, with its sha256) and, per GPS condition, how the values
    were obtained."""
    tuning = res.get("tuning") or {}
    lines = []
    for name, t in tuning.items():
        where = (
            "built-in (predictors/tuned.json)" if t.get("built_in") else f"`{t['file']}`"
        ) + f", sha256 {t['sha256'][:12]}"
        conds = "; ".join(_condition_text(c, e, t["file"]) for c, e in t["conditions"].items())
        lines.append(f"- `{name}`: tuning {where}; {conds}")
    return (
        [
            "Tuning of the baselines (their development drives are marked like training drives):",
            "",
            *lines,
            "",
        ]
        if lines
        else []
    )
