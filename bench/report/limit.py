"""The sentences around the bound's rows (results.json's ``limit``, schema 1.9): what the
rows are and assume, what each data set's bound took, and the predictors that lie below it
by more than their interval, each with the likely reason. report.md prints them in full;
the terminal prints :func:`limit_terminal_lines`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from posbench.naming import plural
from posbench.scenarios.text import fixed


def _m(v: Any) -> str:
    return "-" if v is None else fixed(float(v), 3)


def limit_note(res: Mapping[str, Any]) -> str:
    """What the limit rows are and how to read ``x limit``, in one paragraph ("" without a
    bound)."""
    lim = res.get("limit")
    if not lim:
        return ""
    imu = any((b or {}).get("imu") for b in lim.get("by_dataset", {}).values())
    rows = f"`{lim['name']}`" + (f" and `{lim['name_imu']}`" if imu else "")
    return (
        f"The rows {rows}: {lim['assumptions']} Only the mean error is a bound (median, "
        "p95 and latency are left blank). `x limit` = a predictor's mean error / the limit's "
        "over the same queries (1: as good as any predictor can be under these assumptions)"
        + ("; `x IMU limit` the same against the limit with IMU" if imu else "")
        + ". See the glossary, and the Concepts page on the limit in the documentation."
    )


def dataset_limit_line(res: Mapping[str, Any], dataset: str) -> str:
    """What one data set's bound took, in one line ("" without one): its drives' jerk PSD q,
    the fixes' white noise, the slow floor, the IMU's noise, the GPS conditions."""
    lim = res.get("limit") or {}
    entry = (lim.get("by_dataset") or {}).get(dataset)
    if not entry:
        return ""
    drives = [
        d["limit"] for d in res.get("drives", []) if d["dataset"] == dataset and d.get("limit")
    ]

    def span(key: str, digits: int = 3, root: bool = False) -> str:
        vals = sorted(
            math.sqrt(float(d[key])) if root else float(d[key])
            for d in drives
            if d.get(key) is not None and math.isfinite(float(d[key]))
        )
        if not vals:
            return "-"
        lo, hi = fixed(vals[0], digits), fixed(vals[-1], digits)
        return lo if lo == hi else f"{lo}-{hi}"

    conds = ", ".join(f"`{c}` ({n})" for c, n in (entry.get("gps_conditions") or {}).items())
    floor = entry.get("slow_floor") or {}
    how = sorted({str(d.get("noise")) for d in drives if d.get("noise")})
    text = (
        f"Limit in `{dataset}` ({plural(len(drives), 'drive')}; GPS {conds or '-'}): jerk PSD q "
        f"{span('q_m2_s5')} m^2/s^5 per drive from the reference's motion (taken as it varies "
        f"along each drive); fixes' white noise "
        f"{span('fix_white_var_m2', root=True)} m per axis (1 sigma; {'; '.join(how) or '-'}); "
        f"receiver's slow error {span('slow_var_m2', root=True)} m per axis (1 sigma), added "
        f"on {floor.get('added', 0)} of {len(drives)} drives (against an independent truth; "
        f"never against the receiver's own fixes)"
    )
    if entry.get("imu"):
        text += f"; IMU white noise {span('imu_var_m2_s4', root=True)} m/s^2 per axis (1 sigma)"
    return text + "."


def below_lines(res: Mapping[str, Any]) -> list[str]:
    """One line per predictor and data set whose mean error lies below the bound that
    applies to it (with IMU for a predictor that reads the IMU) by more than its interval in
    a query kind (results.json ``limit.below``), with the likely reason."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for b in (res.get("limit") or {}).get("below", []):
        groups.setdefault((b["dataset"], b["predictor"]), []).append(b)
    out = []
    for (ds, name), entries in groups.items():
        parts = []
        for b in entries:
            with_imu = b.get("against") == "limit with IMU"
            ratio = (
                f", x {'IMU ' if with_imu else ''}limit {fixed(float(b['ratio']), 2)}"
                if b.get("ratio") is not None
                else ""
            )
            if with_imu:
                bound = f"the limit with IMU's {_m(b['limit_imu_m'])} m"
                other = f"; limit {_m(b['limit_m'])} m"
            else:
                bound = f"the limit's {_m(b['limit_m'])} m"
                other = (
                    f"; limit with IMU {_m(b['limit_imu_m'])} m"
                    if b.get("limit_imu_m") is not None
                    else ""
                )
            sd = float(b.get("floor_sd_m") or 0.0)
            floor = f" (its slow floor +/- {_m(sd)} m)" if sd > 0 else ""
            parts.append(
                f"{b['kind']} {_m(b['mean_m'])} m (95 % CI up to {_m(b['ci95_hi_m'])} m) "
                f"against {bound}{floor}{ratio}{other}"
            )
        reasons = list(dict.fromkeys(str(b["reason"]) for b in entries))
        out.append(f"{name} on `{ds}`: {'; '.join(parts)}. Likely: {'; '.join(reasons)}.")
    return out


def limit_report_lines(res: Mapping[str, Any]) -> list[str]:
    """report.md's lines under the headline: the note, each data set's bound, and the
    predictors below it (a heading and a list), or that none is."""
    if not res.get("limit"):
        return []
    lines = [limit_note(res), ""]
    for ds in res.get("by_dataset", {}):
        line = dataset_limit_line(res, ds)
        if line:
            lines += [f"- {line}"]
    lines += [""]
    below = below_lines(res)
    if not below:
        return lines + [
            "No predictor's mean error lies below the limit that applies to it (the limit "
            "with IMU for a predictor that reads the IMU) by more than its 95 % interval.",
            "",
        ]
    return lines + [
        "### Below the limit",
        "",
        "A predictor whose mean error lies below the limit that applies to it (the limit "
        "with IMU for a predictor that reads the IMU) by more than its 95 % interval "
        "uses information the bound does not have, or the bound's assumptions do not hold "
        "on that data:",
        "",
        *[f"- {line}" for line in below],
        "",
    ]


def limit_terminal_lines(res: Mapping[str, Any]) -> list[str]:
    """The terminal's lines after the headline: what the limit rows are, in short, and the
    predictors below the limit."""
    lim = res.get("limit")
    if not lim:
        return []
    lines = [
        f"{lim['name']}: a bound under stated assumptions, not a predictor (known motion "
        "model and fix noise; see report.md); x limit = mean error / the limit's"
    ]
    return lines + [f"below the limit: {line.replace('`', '')}" for line in below_lines(res)]
