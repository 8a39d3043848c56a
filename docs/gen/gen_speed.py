"""Build-time generator of the Speed page (``docs/results/speed.md``): the latency of each
predictor's fix step as a ratio to constant velocity's, read from ``reports/latency.json``
(``bench latency --json``, as ``reports/regenerate.sh`` runs it), and ``bench run``'s wall
time against drive hours, read from ``reports/scaling.json`` (``reports/scaling.py``). Never
copied by hand: the figures are whatever those files hold.
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
    """Per timed predictor: step p50 and p99 [us], both over cv's step p50, and p99 over p50."""
    cv = res["cv"]["step_us"]["p50"]
    lines = [
        f"Fix step (observe_gps + the future query) on `{res.get('drive', '?')}`, one process, "
        "one thread, warm; ratios to cv's step p50 in the same run.",
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
        lines.append(
            f"| {name} | {p50:.1f} | {p99:.1f} | {p50 / cv:.1f} | {p99 / cv:.1f} | "
            f"{p99 / p50:.1f} | {TARGET_X_CV.get(name, '')} |"
        )
    return lines


def scaling_table(sc: dict[str, Any]) -> list[str]:
    """bench run wall time [s] per size, the default predictors and cv alone."""
    default = sc["predictors"]
    lines = [
        f"`{sc['command']}` on {sc['machine']}: the corpus written as Parquet files, "
        "`bench run --data FOLDER` timed as a new process (default workers).",
        "",
        "| drive hours | wall [s], `-p cv` | wall [s], default predictors "
        "| per drive hour [s] | x cv |",
        "|---:|---:|---:|---:|---:|",
    ]
    for r in sc["runs"]:
        w = r["wall_s"]
        cv, full = w.get("cv", math.nan), w.get(default, math.nan)
        lines.append(
            f"| {r['drive_hours']:.2f} | {cv:.0f} | {full:.0f} | "
            f"{full / r['drive_hours']:.0f} | {full / cv:.1f} |"
        )
    lines += ["", f"Default predictors: `{default}`."]
    return lines


def speed_markdown() -> str:
    out: list[str] = []
    lat = _load("latency.json")
    out += latency_table(lat) if lat else ["`reports/latency.json` is missing."]
    out += ["", "### bench run against drive hours", ""]
    sc = _load("scaling.json")
    out += scaling_table(sc) if sc else ["`reports/scaling.json` is missing."]
    return "\n".join(out) + "\n"
