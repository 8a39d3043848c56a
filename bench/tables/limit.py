"""The bound beside the predictors in the run's tables (results.json's ``limit``, schema 1.9).

The headline and each data set's table get the bound as rows of their own, named
``limit (PCRB, CA model)`` (and ``limit with IMU ...`` where the drives have an IMU), with
its mean error and interval, and never anything a predictor is ranked by (latency, median,
p95: the bound is on the mean error only); each predictor gets its ``x limit`` ratio (its
mean / the bound's) and, where there is an IMU, its ``x IMU limit``. The route-type and
per-drive tables get the bound's mean as a column.
A run saved before schema 1.9 has no ``limit``: every helper here then adds nothing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from posbench.scoring.schema import KINDS
from posbench.tables.table import as_float

#: the ratio columns' header and decimals
RATIO_LABEL = "x limit"
RATIO_IMU_LABEL = "x IMU limit"
RATIO_DIGITS = 2


def limit_scope(res: Mapping[str, Any], dataset: str | None = None) -> Mapping[str, Any] | None:
    """The bound over all drives (``dataset`` None) or one data set's, or None (no bound:
    a run saved before schema 1.9, scored answers, a data set without one)."""
    lim = res.get("limit")
    if not lim:
        return None
    scope = lim.get("overall") if dataset is None else (lim.get("by_dataset") or {}).get(dataset)
    return scope or None


def ratio_of(
    res: Mapping[str, Any], name: str, kind: str, dataset: str | None = None, imu: bool = False
) -> float:
    """Predictor ``name``'s x limit of ``kind`` (NaN where there is none)."""
    lim = res.get("limit") or {}
    ratios = lim.get("ratios") or {}
    scope = (
        ratios.get("overall") if dataset is None else (ratios.get("by_dataset") or {}).get(dataset)
    )
    return as_float(((scope or {}).get(name) or {}).get(f"{kind}_imu" if imu else kind))


def limit_rows(
    res: Mapping[str, Any], bound: Mapping[str, Any], counts: Mapping[str, str]
) -> list[dict[str, Any]]:
    """The bound's rows of a predictor table: its mean [m] per kind with the interval as
    ``{KIND}_mean``, ``_lo``, ``_hi``, the query counts in the columns ``counts`` names
    (kind -> column), ``missing`` (queries without a bound); fixes only, then with the IMU
    where there is one."""
    lim = res["limit"]
    rows = []
    for name, kinds in ((lim["name"], bound), (lim["name_imu"], bound.get("imu"))):
        if not kinds:
            continue
        row: dict[str, Any] = {"predictor": name}
        for k in KINDS:
            s = kinds.get(k) or {}
            row[f"{k}_mean"] = as_float(s.get("mean_m"))
            lo, hi = ((s.get("ci95") or {}).get("mean_m") or [None, None])[:2]
            row[f"{k}_mean_lo"], row[f"{k}_mean_hi"] = as_float(lo), as_float(hi)
            row[counts[k]] = int(s.get("count", 0))
        row["missing"] = sum(int((kinds.get(k) or {}).get("missing", 0)) for k in KINDS)
        rows.append(row)
    return rows


def with_ratio_columns(cols: list[str], imu: bool = False) -> list[str]:
    """``cols`` with ``future_xlim`` after ``future_mean``'s interval and ``now_xlim`` after
    ``now_mean``'s; with ``imu``, ``KIND_xlim_imu`` after each (the ratio to the limit with
    IMU)."""
    out = []
    for c in cols:
        out.append(c)
        for k in KINDS:
            if c == f"{k}_mean_hi":
                out += [f"{k}_xlim", f"{k}_xlim_imu"] if imu else [f"{k}_xlim"]
    return out


def ratio_cells(res: Mapping[str, Any], name: str, dataset: str | None = None) -> dict[str, float]:
    """Predictor ``name``'s ratio cells of a table row: ``KIND_xlim`` and ``KIND_xlim_imu``."""
    out = {}
    for k in KINDS:
        out[f"{k}_xlim"] = ratio_of(res, name, k, dataset)
        out[f"{k}_xlim_imu"] = ratio_of(res, name, k, dataset, imu=True)
    return out


def ratio_labels() -> dict[str, str]:
    """Header texts of the ratio columns."""
    out = {}
    for k in KINDS:
        out[f"{k}_xlim"], out[f"{k}_xlim_imu"] = RATIO_LABEL, RATIO_IMU_LABEL
    return out


def ratio_digits() -> dict[str, int]:
    """Decimals of the ratio columns."""
    return {c: RATIO_DIGITS for c in ratio_labels()}


def drive_limit_mean(drive: Mapping[str, Any], kind: str = "future") -> float:
    """A drive's bound on the mean error of ``kind`` [m] (NaN without one)."""
    return as_float(((drive.get("limit") or {}).get(kind) or {}).get("mean_m"))


def label_limit_mean(res: Mapping[str, Any], dataset: str, kind: str, label: str | None) -> float:
    """The bound's mean [m] of a route type (``label``; None: every query) of a data set."""
    lim = res.get("limit") or {}
    if label is None:
        return as_float(((limit_scope(res, dataset) or {}).get(kind) or {}).get("mean_m"))
    groups = ((lim.get("by_label") or {}).get(dataset) or {}).get(kind) or {}
    return as_float((groups.get(label) or {}).get("mean_m"))
