"""Build-time generator of the Speed page (``docs/results/speed.md``): the latency of each
predictor's fix step as a ratio to constant velocity's, read from ``reports/latency.json``
(``bench latency --json``, as ``reports/regenerate.sh`` runs it), and ``bench run``'s wall
time and peak memory against drive hours, read from ``reports/scaling.json``
(``reports/scaling.py``). Never copied by hand: the figures are whatever those files hold.
"""

from __future__ import annotations

import json
import math
from typing import Any

import gen_results

#: the issue's targets for the step p50 as a multiple of cv's (one run of bench latency)
TARGET_X_CV = {"kf": "4", "ekf": "8", "lstm": "10", "hybrid": "lstm + kf"}


def _load(name: str) -> dict[str, Any] | None:
    path = gen_results.ROOT / "reports" / name
    return json.loads(path.read_text()) if path.is_file() else None


def latency_table(res: dict[str, Any]) -> list[str]:
    """Per timed predictor: step p50 and p99 [us], both over cv's step p50 (the p50's ratio as
    ``bench latency`` took it: over several rounds, the median of the rounds' ratios), and
    p99 over p50."""
    cv = res["cv"]["step_us"]["p50"]
    ratios = res.get("ratio_to_cv", {})
    rounds = len(res["cv"].get("step_p50_rounds") or [1])
    how = (
        f"the median of {rounds} interleaved rounds' ratios, each over cv timed in the same round"
        if rounds > 1
        else "in the same run"
    )
    lines = [
        f"Fix step (observe_gps + the future query) on `{res.get('drive', '?')}`, one process, "
        f"one thread, warm; p50 ratios to cv's step p50: {how}.",
        "",
        "| predictor | step p50 [us] | p99 [us] | p50 x cv | p99 x cv | p99 / p50 "
        "| target p50 x cv |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in res.items():
        step = r.get("step_us") if isinstance(r, dict) else None
        if not step or name.startswith("lstm_") or name == "ratio_to_cv":
            continue
        p50, p99 = step["p50"], step["p99"]
        p50_x_cv = ratios.get(name, {}).get("step_p50", p50 / cv)
        lines.append(
            f"| {name} | {p50:.1f} | {p99:.1f} | {p50_x_cv:.1f} | {p99 / cv:.1f} | "
            f"{p99 / p50:.1f} | {TARGET_X_CV.get(name, '')} |"
        )
    return lines


#: how each case of reports/scaling.py is named in the table
CASE_LABELS = {
    "corpus": "corpus",
    "long-1hz": "one drive, 1 Hz fixes",
    "long-10hz": "one drive, 10 Hz fixes, 100 Hz IMU",
    "ray": "corpus, `--executor ray --workers 2`",
}


def _mb(rss: dict[str, Any] | None, key: str) -> str:
    v = (rss or {}).get(key)
    return "-" if v is None else f"{v:.0f}"


def scaling_table(sc: dict[str, Any]) -> list[str]:
    """bench run wall time [s] and peak RSS [MB] per case, size and predictor set (the
    default predictors and cv alone); runs recorded before the memory was measured show
    ``-`` for it."""
    default = sc["predictors"]
    lines = [
        f"`{sc['command']}` on {sc['machine']}: each case's drives written as Parquet files, "
        "`bench run --data FOLDER` run as a new process (default workers). Peak resident "
        "memory (RSS) in MB: `main` is bench's own process (the Ray driver in the ray case), "
        "`largest child` the largest process below it (replay workers, loaders, figure "
        "writers; forked ones count the pages they share with `main`; the Ray processes in "
        "the ray case), `largest` the larger of the two.",
        "",
        "| case | drive hours | drives | predictors | wall [s] | per drive hour [s] | x cv "
        "| RSS main [MB] | RSS largest child [MB] | RSS largest [MB] |",
        "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    skipped = []
    for r in [*sc["runs"], *sc.get("cases", [])]:
        case = r.get("case", "corpus")
        if r.get("skipped"):
            skipped.append(f"{CASE_LABELS.get(case, case)}: not run ({r['skipped']}).")
            continue
        w, rss = r["wall_s"], r.get("peak_rss_mb", {})
        cv = w.get("cv", math.nan)
        for name, wall in sorted(w.items(), key=lambda kv: kv[0] != "cv"):
            label = "default" if name == default else f"`{name}`"
            x_cv = f"{wall / cv:.1f}" if name != "cv" and cv > 0 else ""
            lines.append(
                f"| {CASE_LABELS.get(case, case)} | {r['drive_hours']:.2f} | "
                f"{r.get('drives', '')} | {label} | {wall:.0f} | {wall / r['drive_hours']:.0f} | "
                f"{x_cv} | {_mb(rss.get(name), 'main')} | {_mb(rss.get(name), 'worker')} | "
                f"{_mb(rss.get(name), 'largest')} |"
            )
    lines += ["", f"Default predictors: `{default}`."]
    lines += [f"{s}" for s in skipped]
    checks = [
        (m["largest"], m["largest_rusage"])
        for r in [*sc["runs"], *sc.get("cases", [])]
        for m in r.get("peak_rss_mb", {}).values()
        if m.get("largest") and m.get("largest_rusage") and r.get("executor") != "ray"
    ]
    if checks:
        worst = max(abs(a - b) / b for a, b in checks)
        lines += [
            "",
            f"Cross-check: in every local run, `RSS largest` is within {100 * worst:.1f} % of "
            "`getrusage(RUSAGE_CHILDREN).ru_maxrss` of the wrapper process that started `bench` "
            "(the largest single process it and its descendants waited for).",
        ]
    return lines


def speed_markdown() -> str:
    out: list[str] = []
    lat = _load("latency.json")
    out += latency_table(lat) if lat else ["`reports/latency.json` is missing."]
    out += ["", "### bench run: wall time and memory against drive hours", ""]
    sc = _load("scaling.json")
    out += scaling_table(sc) if sc else ["`reports/scaling.json` is missing."]
    return "\n".join(out) + "\n"
