"""The sentences around report.md's tables (and the terminal's): which model a learned
predictor used and which drives it was trained on, what the headline leaves out, how the
intervals and the paired comparison were made."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

from posbench.config import BUILT_IN_TUNING
from posbench.scenarios.text import fixed
from posbench.scenarios.truth_gaps import TRUTH_MAX_GAP_S
from posbench.scoring.reference import KIND_FIXES
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


def tuned_baseline(res: Mapping[str, Any], name: str) -> bool:
    """Whether the drives marked for ``name`` are the development drives of its tuning (a
    baseline run with tuned parameters, no learned model: results.json's ``models`` names
    its model ``tuning FILE``), not a learned model's training drives."""
    model = (res.get("models") or {}).get(name) or {}
    return name in (res.get("tuning") or {}) and str(model.get("model", "")).startswith("tuning ")


def tuning_file_text(entry: Mapping[str, Any], file: str | None = None) -> str:
    """How a report names a tuning file: the package's own, or the user's path (``file``:
    one of ``entry``'s conditions' file, else the predictor's)."""
    file = file or str(entry["file"])
    built_in = entry.get("built_in") if file == entry["file"] else file == BUILT_IN_TUNING
    return "the built-in predictors/tuned.json" if built_in else f"`{file}`"


def _names(names: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _marked_groups(
    res: Mapping[str, Any], marked: Mapping[str, Sequence[str]]
) -> list[tuple[list[str], str, Sequence[str], bool]]:
    """The predictors of ``marked`` (name -> drives of the run marked for it) as groups
    ``(names, what, drives, tuned)``: a learned predictor alone, with its model's text; tuned
    baselines that share a tuning file and development drives together, with the file's."""
    groups: dict[tuple[str, ...], tuple[list[str], str, Sequence[str], bool]] = {}
    for p, drives in marked.items():
        if tuned_baseline(res, p):
            what = tuning_file_text(res["tuning"][p])
            key: tuple[str, ...] = ("tuned", what, *drives)
        else:
            what, key = model_text(res["models"][p]), ("trained", p)
        groups.setdefault(key, ([], what, drives, key[0] == "tuned"))[0].append(p)
    return list(groups.values())


def trained_note(res: dict[str, Any]) -> str:
    """The footnote of ``*`` rows: which model, trained on which of the run's drives, or which
    tuning, tuned on which (its development drives)."""
    trained = trained_in_run(res)
    if not trained:
        return ""
    n_drives = sum(1 for d in res["drives"] if not d["skipped"])
    parts = []
    for names, what, drives, tuned in _marked_groups(res, trained):
        these = f"{len(drives)} of these {n_drives} drives"
        if tuned:
            verb = "was" if len(names) == 1 else "were"
            parts.append(f"{_names(names)} {verb} tuned on {these} (development drives of {what})")
        else:
            parts.append(f"{names[0]} ({what}) was trained on {these}")
    end = (
        "its figures on them flatter it"
        if len(trained) == 1
        else "their figures on those drives flatter them"
    )
    return "* " + "; ".join(parts) + f": {end}; see the held-out table."


def held_out_note(res: Mapping[str, Any], excluded: Sequence[str]) -> str:
    """Who was trained or tuned on which of the ``excluded`` drives of a data set, and that
    those drives flatter them (the held-out section of report.md); drives that all of them
    share are listed once."""
    leave = set(excluded)
    marked = {
        p: sorted(set(names) & leave)
        for p, names in res.get("training_drives", {}).items()
        if set(names) & leave
    }
    groups = _marked_groups(res, marked)
    shared = len({tuple(drives) for _, _, drives, _ in groups}) == 1
    parts = []
    for names, what, drives, tuned in groups:
        who = _names([f"`{n}`" for n in names])
        verb = "was" if len(names) == 1 else "were"
        on = "" if shared else f" on {', '.join(drives)}"
        if tuned:
            parts.append(f"{who} {verb} tuned{on} (development drives of {what})")
        else:
            parts.append(f"{who} ({what}) was trained{on}")
    them = "it" if len(marked) == 1 else "them"
    text = _names(parts) if shared else "; ".join(parts)
    if shared:
        text += f" on {', '.join(groups[0][2])}"
    return f"{text}: figures on those drives flatter {them}"


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


def dataset_reference(ref: Mapping[str, Any] | None, fixes: str | None) -> str:
    """``reference: TEXT; fixes: FIXES`` of a data set's section (:mod:`posbench.scoring.reference`;
    the fixes scored where they are not the reference themselves)."""
    if ref is None:
        return "reference: -" + (f"; fixes: {fixes}" if fixes else "")
    cubic = (
        "; the reference position of a query is a cubic through the fixes around it"
        if ref["kind"] == KIND_FIXES
        else ""
    )
    fed = f"; fixes: {fixes}" if fixes and ref["kind"] != KIND_FIXES else ""
    return f"reference: {ref['text']}{cubic}{fed}"


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
        f"the fixes, or in a gap of the truth longer than {TRUTH_MAX_GAP_S:g} s)."
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


#: what in a tuning's ``how`` the report leaves to results.json: the ``bench tune`` commands
#: ("by `CMD`", "`CMD`: ") and the paths of the development drives ("development drives P, Q")
_COMMAND_BY = re.compile(r"\s*\bby `[^`]*`")
_COMMAND_LEAD = re.compile(r"`[^`]*`:\s*")
_DRIVE_PATHS = re.compile(r"\bdevelopment drives [^;]*")


def short_how(how: str) -> str:
    """How a tuned value was obtained, without the ``bench tune`` command and the paths of its
    development drives (results.json keeps both): ``cov_scale for 95 % coverage on the
    development drives``."""
    how = _COMMAND_LEAD.sub("", _COMMAND_BY.sub("", how))
    return _DRIVE_PATHS.sub("the development drives", how).strip(" ;")


def tuning_lines(res: dict[str, Any]) -> list[str]:
    """The "Tuning of the baselines" lines (results.json ``tuning``): the tuning file(s) with
    their sha256, once; per predictor that ran with tuned parameters, per GPS condition its
    values, how they were obtained (without the command) and a label of its development
    drives; then each set of development drives once, by drive name. The full ``bench tune``
    commands stay in results.json."""
    tuning = res.get("tuning") or {}
    if not tuning:
        return []
    files: dict[str, tuple[str, str, list[str]]] = {}  # file -> (text, sha256, predictors)
    sets: dict[tuple[str, ...], str] = {}  # development drives -> label (D1, D2, ...)
    lines = []
    for name, t in tuning.items():
        conds = []
        for cond, e in t["conditions"].items():
            file = str(e.get("file", t["file"]))
            sha = e.get("sha256") or (t["sha256"] if file == t["file"] else "")
            text, _, users = files.setdefault(file, (tuning_file_text(t, file), sha, []))
            if name not in users:
                users.append(name)
            drives = tuple(sorted(e["drives"] if "drives" in e else t.get("drives", [])))
            label = sets.setdefault(drives, f"D{len(sets) + 1}") if drives else ""
            values = (
                ", ".join(
                    f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                    for k, v in e["params"].items()
                )
                or "defaults"
            )
            how = short_how(str(e.get("how", "")))
            conds.append(
                f"{cond}{f' [{label}]' if label else ''}: {values}"
                + (f" from {text}" if file != t["file"] else "")
                + (f" ({how})" if how else "")
            )
        lines.append(f"- `{name}`: {'; '.join(conds)}")
    if len(files) == 1:
        text, sha, _ = next(iter(files.values()))
        head = [f"- tuning file: {text}, sha256 {sha[:12]}"]
    else:
        head = [
            "- tuning files: "
            + "; ".join(
                f"{text}, sha256 {sha[:12]} ({', '.join(f'`{u}`' for u in users)})"
                for text, sha, users in files.values()
            )
        ]
    tail = [
        f"- development drives {label} ({len(drives)}): {', '.join(drives)}"
        for drives, label in sets.items()
    ]
    return [
        "Tuning of the baselines (their development drives are marked like training drives; "
        "results.json's `tuning` keeps the `bench tune` command behind each value):",
        "",
        *head,
        *lines,
        *tail,
        "",
    ]
