"""Build-time generator of the Results page (``docs/results/index.md``): every reference
report's figures read from its ``reports/NAME/results.json`` (what
``reports/regenerate.sh`` wrote), never copied by hand.

Per report: the command that made it, its configuration (GPS profile, dropouts, data
sets, drives), what each data set is scored against (its truth, or the receiver's own
fixes), each predictor's ``future`` and ``now`` mean error with its 95 % interval and
query count (and, from schema 1.9 on, its ``x limit`` and the bound's rows, never ranked),
the mean ``future`` error per data set when there are several, and a link to
the full ``report.md`` in the repository (it lives outside the docs folder, so it is linked
at the repository's URL). :data:`ROOT` and :data:`REPO_URL` are set by the
mkdocs hook (``docs/gen/hooks.py``) from mkdocs.yml.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

#: the repository root (the folder holding mkdocs.yml and reports/)
ROOT = Path(__file__).resolve().parents[2]
#: mkdocs.yml's repo_url ("" : report.md is named, not linked)
REPO_URL = ""
#: the branch the report links point at
BRANCH = "main"
#: reports in the order reports/regenerate.sh makes them (others follow, by name)
ORDER = (
    "synthetic",
    "kitti",
    "kitti-none",
    "kitti-consumer",
    "all-data",
    "outages",
    "kitti-outage-lengths",
    "aslan-no-gate",
    "aslan-gate",
)


def report_dirs(root: Path | None = None) -> list[Path]:
    """Every ``reports/*/`` folder with a results.json, in :data:`ORDER`."""
    found = {p.parent.name: p.parent for p in (root or ROOT).glob("reports/*/results.json")}
    known = [found.pop(n) for n in ORDER if n in found]
    return known + [found[n] for n in sorted(found)]


def _num(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) else math.nan


def figure(summary: Mapping[str, Any] | None, stat: str = "mean_m") -> str:
    """``0.038 [0.031, 0.048]``: a summary's figure [m] with its 95 % CI when there is
    one; ``-`` without queries."""
    if not summary:
        return "-"
    v = _num(summary.get(stat))
    if math.isnan(v):
        return "-"
    ci = (summary.get("ci95") or {}).get(stat)
    if ci and len(ci) == 2 and not any(math.isnan(_num(c)) for c in ci):
        return f"{v:.3f} [{_num(ci[0]):.3f}, {_num(ci[1]):.3f}]"
    return f"{v:.3f}"


def report_url(name: str, repo_url: str | None = None) -> str:
    """The report's report.md in the repository on the web ("" without a repo_url)."""
    base = (REPO_URL if repo_url is None else repo_url).rstrip("/")
    return f"{base}/blob/{BRANCH}/reports/{name}/report.md" if base else ""


def ratio(v: Any) -> str:
    """``0.38``: a predictor's x limit; ``-`` without one."""
    x = _num(v)
    return "-" if math.isnan(x) else f"{x:.2f}"


def predictor_table(res: Mapping[str, Any]) -> list[str]:
    """Per predictor: future and now mean error [m] with 95 % CI, and the query counts;
    the lowest future mean in bold. With the bound (schema 1.9), each predictor's x limit
    and the bound's rows below, in italics (a bound, never ranked)."""
    preds = res.get("predictors") or {}
    means = {p: _num((v.get("future") or {}).get("mean_m")) for p, v in preds.items()}
    finite = [m for m in means.values() if not math.isnan(m)]
    best = min(finite) if finite else None
    lim = res.get("limit") or {}
    ratios = (lim.get("ratios") or {}).get("overall") or {}
    imu = bool((lim.get("overall") or {}).get("imu"))
    head = "| predictor | future mean [m] (95 % CI) | n | now mean [m] (95 % CI) | n |"
    rule = "|---|---|---|---|---|"
    keys = ["future", "now"] + (["future_imu", "now_imu"] if imu else [])
    if lim:
        head += " future x limit | now x limit |" + (
            " future x IMU limit | now x IMU limit |" if imu else ""
        )
        rule += "---|" * len(keys)
    lines = [head, rule]
    for p, v in preds.items():
        fut, now = v.get("future") or {}, v.get("now") or {}
        f = figure(fut)
        if best is not None and means[p] == best:
            f = f"**{f}**"
        row = f"| `{p}` | {f} | {fut.get('count', 0)} | {figure(now)} | {now.get('count', 0)} |"
        if lim:
            r = ratios.get(p) or {}
            row += "".join(f" {ratio(r.get(k))} |" for k in keys)
        lines.append(row)
    overall = lim.get("overall") or {}
    for name, kinds in ((lim.get("name"), overall), (lim.get("name_imu"), overall.get("imu"))):
        if not name or not kinds:
            continue
        fut, now = kinds.get("future") or {}, kinds.get("now") or {}
        lines.append(
            f"| *{name}* | *{figure(fut)}* | {fut.get('count', 0)} | *{figure(now)}* | "
            f"{now.get('count', 0)} |" + " - |" * len(keys)
        )
    return lines


def dataset_table(res: Mapping[str, Any]) -> list[str]:
    """Mean future error [m] with 95 % CI per predictor and data set (several data sets
    only)."""
    by = res.get("by_dataset") or {}
    if len(by) < 2:
        return []
    sets = list(by)
    lines = [
        "| predictor | " + " | ".join(f"{d} future mean [m]" for d in sets) + " |",
        "|---|" + "---|" * len(sets),
    ]
    for p in res.get("predictors") or {}:
        cells = [figure((by[d].get(p) or {}).get("future")) for d in sets]
        lines.append(f"| `{p}` | " + " | ".join(cells) + " |")
    lim = res.get("limit") or {}
    if lim:
        bounds = lim.get("by_dataset") or {}
        cells = [figure((bounds.get(d) or {}).get("future")) for d in sets]
        lines.append(f"| *{lim['name']}* | " + " | ".join(f"*{c}*" for c in cells) + " |")
    return lines


def reference_lines(res: Mapping[str, Any]) -> list[str]:
    """What each data set's figures are measured against, one item each (its truth, or the
    receiver's own fixes: :mod:`posbench.scoring.reference`), then a blank line."""
    from posbench.scoring.reference import reference_lines as lines_of

    lines = lines_of(res)
    return [f"- {line[0].upper()}{line[1:]}." for line in lines] + [""] * bool(lines)


def report_section(folder: Path, repo_url: str | None = None) -> str:
    """One report's section of the page."""
    res = json.loads((folder / "results.json").read_text())
    cfg = res.get("config") or {}
    name = folder.name
    drives = res.get("drives") or []
    scored = [d for d in drives if not d.get("skipped")]
    sets = ", ".join(f"`{d}`" for d in res.get("by_dataset") or {}) or "-"
    url = report_url(name, repo_url)
    out = [
        f"## {name}",
        "",
        f"```console\n$ {res.get('command', '')}\n```",
        "",
        f"GPS profile `{cfg.get('gps_profile', '?')}`, dropouts `{cfg.get('dropouts', '?')}`, "
        f"horizon {cfg.get('horizon_s', '?')} s, outlier gate "
        f"{'on' if cfg.get('gate', True) else 'off'}; data sets {sets}; "
        f"{len(scored)} drives scored"
        + (f" ({len(drives) - len(scored)} skipped)" if len(scored) < len(drives) else "")
        + f"; results.json schema {res.get('schema_version', '?')}.",
        "",
        *reference_lines(res),
        *predictor_table(res),
        "",
    ]
    per_set = dataset_table(res)
    if per_set:
        out += ["Per data set:", "", *per_set, ""]
    if url:
        out += [
            f"The full report (every table, figure and the glossary): "
            f"[reports/{name}/report.md]({url}).",
            "",
        ]
    else:
        out += [f"The full report: `reports/{name}/report.md` in the repository.", ""]
    return "\n".join(out)


def results_markdown(root: Path | None = None, repo_url: str | None = None) -> str:
    """The page body: a summary table of every report (best future mean), then a section
    per report."""
    dirs = report_dirs(root)
    if not dirs:
        return "No reference reports found (`reports/*/results.json`)."
    lines = [
        "| report | data sets | GPS profile | dropouts | predictors | best future mean [m] "
        "| limit future mean [m] |",
        "|---|---|---|---|---|---|---|",
    ]
    sections = []
    for d in dirs:
        res = json.loads((d / "results.json").read_text())
        preds = res.get("predictors") or {}
        means = {p: _num((v.get("future") or {}).get("mean_m")) for p, v in preds.items()}
        finite = {p: m for p, m in means.items() if not math.isnan(m)}
        best = min(finite, key=finite.__getitem__) if finite else None
        best_txt = f"`{best}` {figure(preds[best]['future'])}" if best else "-"
        cfg = res.get("config") or {}
        sets = ", ".join(res.get("by_dataset") or {}) or "-"
        bound = ((res.get("limit") or {}).get("overall") or {}).get("future")
        lines.append(
            f"| [{d.name}](#{d.name}) | {sets} | `{cfg.get('gps_profile', '?')}` | "
            f"`{cfg.get('dropouts', '?')}` | {len(preds)} | {best_txt} | {figure(bound)} |"
        )
        sections.append(report_section(d, repo_url))
    return "\n".join([*lines, "", *sections])
