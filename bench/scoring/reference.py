"""What a data set's figures are measured against, named once for the terminal, report.md and
results.json (``references``, schema 1.8).

A drive with a truth stream is scored against it (:data:`TRUTH`): its errors are true metres,
up to the truth's own error. A drive without one (the paper's routes, a bag with no truth
topic) is scored against a cubic through its receiver's own fixes (:data:`FIX_CUBIC`): a
receiver's error is mostly slow, and no predictor fed those fixes can see it, so its figures
say how well a predictor follows this receiver, not how close it is to the true position.
:func:`dataset_references` says which, per data set; :func:`reference_lines` in one line each.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from posbench.naming import plural

#: what a drive is scored against (``drives[].reference``): its truth ...
TRUTH = "truth"
#: ... or, without one, the paper's cubic through the surrounding fixes
FIX_CUBIC = "cubic through surrounding fixes"

#: ``references.<data set>.kind``: every scored drive has a truth, none has, or some have
KIND_TRUTH, KIND_FIXES, KIND_MIXED = "truth", "fixes", "mixed"

#: what the truth of a drive is, by its loader (``Drive.meta.format``, the run's data set)
TRUTH_BY_FORMAT = {
    "kitti": "the OXTS RT3003 INS/GNSS solution",
    "comma2k19": "comma2k19's fused global_pose",
    "synthetic": "the simulated vehicle path",
    "table": "the file's truth rows",
    "ros1": "the bag's truth topic",
    "ros2": "the bag's truth topic",
}
#: a truth whose loader :data:`TRUTH_BY_FORMAT` does not know
UNNAMED_TRUTH = "the drive's truth stream"

FIXES_TEXT = (
    "the receiver's own fixes (no independent truth): figures say how well a predictor "
    "follows this receiver, not how close it is to the true position"
)


def truth_name(dataset: str, topic: str | None = None) -> str:
    """What the truth of a drive of ``dataset`` (its loader's format) is, in words: e.g.
    ``the OXTS RT3003 INS/GNSS solution``; a bag's truth by its ``topic`` where known."""
    if topic and dataset in ("ros1", "ros2"):
        return f"the bag's truth topic {topic}"
    return TRUTH_BY_FORMAT.get(dataset, UNNAMED_TRUTH)


def truth_text(names: Iterable[str]) -> str:
    """``the truth, NAME (errors in true metres)``: a truth reference in words."""
    return f"the truth, {' or '.join(sorted(set(names)))} (errors in true metres)"


def dataset_references(drives: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per data set of the scored (not skipped) ``drives`` (results.json's ``drives``), what
    its figures are measured against: ``kind`` (:data:`KIND_TRUTH`, :data:`KIND_FIXES`, or
    :data:`KIND_MIXED` with ``drives`` = {kind: count}), ``truth`` (what the truth is, where
    one is the reference) and ``text``, one line. A drive saved before schema 1.8 has no
    ``truth_source``: its truth is named by its data set (:func:`truth_name`)."""
    counts: dict[str, dict[str, int]] = {}
    truths: dict[str, list[str]] = {}
    for d in drives:
        if d.get("skipped"):
            continue
        ds = str(d["dataset"])
        kind = KIND_TRUTH if d.get("reference") == TRUTH else KIND_FIXES
        by_kind = counts.setdefault(ds, {})
        by_kind[kind] = by_kind.get(kind, 0) + 1
        if kind == KIND_TRUTH:
            truths.setdefault(ds, []).append(str(d.get("truth_source") or truth_name(ds)))
    out: dict[str, dict[str, Any]] = {}
    for ds, by_kind in counts.items():
        names = sorted(set(truths.get(ds, [])))
        if len(by_kind) == 1 and KIND_FIXES in by_kind:
            out[ds] = {"kind": KIND_FIXES, "text": FIXES_TEXT}
        elif len(by_kind) == 1:
            out[ds] = {"kind": KIND_TRUTH, "truth": " or ".join(names), "text": truth_text(names)}
        else:
            n_truth, n_fixes = by_kind[KIND_TRUTH], by_kind[KIND_FIXES]
            out[ds] = {
                "kind": KIND_MIXED,
                "truth": " or ".join(names),
                "drives": dict(sorted(by_kind.items())),
                "text": f"{truth_text(names)} on {plural(n_truth, 'drive')}; the receiver's "
                f"own fixes on {plural(n_fixes, 'drive')} (no independent truth: figures on "
                f"{'it' if n_fixes == 1 else 'them'} say how well a predictor follows the "
                f"receiver, not how close it is to the true position)",
            }
    return out


def references(res: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """The ``references`` of a saved run (schema 1.8), or for an older run what its drives
    say (:func:`dataset_references`)."""
    saved = res.get("references")
    if saved:
        return dict(saved)
    return dataset_references(res.get("drives", []))


def reference_lines(res: Mapping[str, Any], fixes: Mapping[str, str] | None = None) -> list[str]:
    """``reference in `DATA SET`: TEXT`` per data set of a run, one line each; ``fixes`` (data
    set -> the fixes scored, in words) is added where a truth is the reference (where the
    fixes are the reference, that they are the receiver's goes without saying)."""
    lines = []
    for ds, ref in references(res).items():
        fed = (fixes or {}).get(ds)
        extra = f"; fixes scored: {fed}" if fed and ref["kind"] != KIND_FIXES else ""
        lines.append(f"reference in `{ds}`: {ref['text']}{extra}")
    return lines
