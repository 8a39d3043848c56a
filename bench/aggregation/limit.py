"""How far from the limit: results.json's ``limit`` (schema 1.9) from each drive's bound.

Each replayed drive carries the bound on the mean error of its scored queries
(``DriveRun.limit``, :func:`posbench.replay.limit.drive_limit`): one value per query, for the
very queries the predictors are scored on (past the warm-up, with a reference). Here they
are summarised as a predictor's errors are (mean over the same queries, with its cluster
bootstrap interval over drives), overall and per data set, fixes only and with the IMU;
each predictor's ``x limit`` ratio (its mean / the bound's); and the predictors whose mean
lies below **the bound that applies to them** by more than their interval, each with the
likely reason: a predictor that reads the IMU (its class overrides ``observe_imu`` and no
``use_imu`` option turns it off: :func:`imu_readers`) is held against the bound with IMU,
one that does not against the fixes-only bound. Where a drive's slow floor was measured on
few independent samples (a receiver's own fixes against a truth,
``drives[].limit.slow_var_sd_m2``), the bound's interval is widened by what that leaves
uncertain (:func:`floor_sd`), and a predictor is below only by more than that too. The bound
is never a predictor: it is kept out of ``predictors``, the paired comparison, the sanity
check and every gate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from statistics import NormalDist
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import Statistics
from posbench.aggregation.limit_rows import BoundRows, bound_rows
from posbench.metrics.accuracy import summarize, summarize_groups
from posbench.metrics.limit import LIMIT_IMU_NAME, LIMIT_NAME, mean_ci
from posbench.scenarios.labels import LABELS
from posbench.scoring.records import DriveRun
from posbench.scoring.reference import KIND_FIXES
from posbench.scoring.schema import KINDS

#: what the bound assumes, in one paragraph (results.json ``limit.assumptions``, report.md)
ASSUMPTIONS = (
    "a bound under stated assumptions, not a predictor: the posterior Cramér-Rao bound of "
    "a predictor that knows the motion model (constant acceleration driven by white jerk, per "
    "axis, of the PSD q the reference shows, as it varies along each drive in 2 s windows) "
    "and the noise of the fixes it is fed (white, of the simulated profile's variance, else "
    "as estimated from the fixes), at the drive's actual fix times; against an independent "
    "truth plus the receiver's slow error (no fix can reveal it: on simulated fixes the error "
    "posbench drew for the drive, at each query; on a receiver's own, its variance measured "
    "against the truth, the interval widened by how few independent samples of it a drive "
    "holds), against the receiver's own fixes without. The mean error of the 2-D Gaussian it "
    "implies, averaged over the queries "
    "the predictors are scored on. The IMU variant also observes the acceleration at every "
    "IMU sample, with the white noise the samples show (bias, tilt and mounting taken as "
    "known)."
)


#: ``use_imu`` option values that switch a predictor's IMU off
_OFF = {"false", "no", "off", "0"}


def imu_readers(
    names: Sequence[str], options: Mapping[str, Mapping[str, Any]] | None = None
) -> dict[str, bool | None]:
    """Per predictor name, whether it reads the IMU: its class overrides
    :meth:`~posbench.predictors.base.Predictor.observe_imu` (as the data check's
    ``uses_stream`` tells) and its ``use_imu`` option (``options[name]``) does not turn that
    off; None where the class cannot be found (e.g. answers scored from a file)."""
    from posbench.predictors.base import Predictor
    from posbench.predictors.registry import predictor_class

    out: dict[str, bool | None] = {}
    for name in names:
        try:
            cls = predictor_class(name)
        except Exception:  # noqa: BLE001 - any failure to resolve: not known
            out[name] = None
            continue
        reads = getattr(cls, "observe_imu", None) is not Predictor.observe_imu
        use = (options or {}).get(name, {}).get("use_imu", True)
        if use is False or str(use).strip().lower() in _OFF:
            reads = False
        out[name] = reads
    return out


def floor_sd(bound_m: np.ndarray, slow_sd_m2: np.ndarray, codes: np.ndarray) -> float:
    """The standard deviation [m] of the mean of ``bound_m`` (per-query bounds [m]) that its
    drives' measured slow floors leave (``slow_sd_m2`` [m^2] per query, its drive's;
    ``codes`` the drives): a query's bound ``c sqrt(V)``, ``c^2 = pi/2``, moves by
    ``pi / (4 b)`` per m^2 of slow variance; fully correlated within a drive (one floor),
    independent across drives. 0 where no drive's floor was measured."""
    b = np.asarray(bound_m, dtype=float)
    sd = np.asarray(slow_sd_m2, dtype=float)
    ok = np.isfinite(b) & (b > 0) & np.isfinite(sd)
    if not ok.any() or not (sd[ok] > 0).any():
        return 0.0
    per_query = math.pi * sd[ok] / (4.0 * b[ok])
    per_drive = np.bincount(np.asarray(codes)[ok], weights=per_query) / ok.sum()
    return float(np.sqrt(np.sum(per_drive * per_drive)))


def _kind_summaries(
    rows: BoundRows,
    where: np.ndarray | slice,
    codes: np.ndarray,
    column: str,
    stats: Statistics | None,
) -> dict[str, Any] | None:
    """Per kind, :func:`summarize` of the bound in ``column`` over the rows ``where`` (their
    drives ``codes``, numbered within them) with the ``ci95`` of its mean (drives resampled,
    as a predictor's; its median and p95 are no bound: no interval), widened by
    ``floor_sd_m`` (:func:`floor_sd`, in quadrature with the resampling's half-widths); None
    when no query has one (e.g. no IMU)."""
    e = getattr(rows, column)[where]
    if not np.isfinite(e).any():
        return None
    kind = rows.kind[where]
    slow_sd = rows.slow_sd_m2()[where]
    masks = [kind == i for i in range(len(KINDS))]
    sds = [floor_sd(e[m], slow_sd[m], codes[m]) for m in masks]
    del slow_sd, kind
    out: dict[str, dict[str, Any]] = {}
    for k, m, sd in zip(KINDS, masks, sds, strict=True):
        ek, ck = e[m], codes[m]
        out[k] = dict(summarize(ek))
        out[k]["floor_sd_m"] = sd
        if stats is not None:
            r = mean_ci(ek, ck, rows.t_query[where][m], stats.resamples, stats.seed, stats.level)
            out[k]["ci95"] = {
                "mean_m": _widened(r["mean_m"], out[k]["mean_m"], sd, stats.level),
                "median_m": r["median_m"],
                "p95_m": r["p95_m"],
                "drives": r["clusters"],
                "block_len": r["block_len"],
            }
    return out


def _z(level: float) -> float:
    """The standard normal quantile of a two-sided ``level`` interval (1.96 at 0.95)."""
    return NormalDist().inv_cdf(0.5 + level / 2.0)


def _widened(ci: Any, mean: float, sd: float, level: float) -> Any:
    """``ci`` ([lo, hi] of a mean ``mean`` > 0) widened by the floor's uncertainty ``sd`` [m]
    (:func:`floor_sd`), in quadrature on the log scale: each end's log-ratio to the mean and
    ``z sd / mean`` combine as root sum of squares. A mean error stays positive however
    uncertain its floor (added in metres, a floor measured on few samples gave intervals
    below 0); to first order in the widths the same as adding ``z sd`` to each half-width.
    As it is where ``sd`` is 0 or not finite."""
    if not (sd > 0 and math.isfinite(sd)) or ci is None:
        return ci
    lo, hi = ci
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return ci
    if not (mean > 0 and lo > 0 and hi > 0):
        return ci
    extra = (_z(level) * sd / mean) ** 2
    down = math.sqrt(math.log(mean / lo) ** 2 + extra) if lo < mean else math.sqrt(extra)
    up = math.sqrt(math.log(hi / mean) ** 2 + extra) if hi > mean else math.sqrt(extra)
    return [mean * math.exp(-down), mean * math.exp(up)]


def _scope(rows: BoundRows, where: np.ndarray | slice, stats: Statistics | None) -> dict[str, Any]:
    """The bound's figures over the rows ``where``: per kind fixes only, and ``imu``. Their
    drives are numbered within them, in order of first appearance."""
    if isinstance(where, slice) and where == slice(0, len(rows)):
        codes = rows.drive  # all rows: numbered in order of first appearance already
    else:
        codes = pd.factorize(rows.drive[where])[0].astype(np.int32)
    out = _kind_summaries(rows, where, codes, "limit_m", stats) or {
        k: summarize(np.empty(0)) for k in KINDS
    }
    return {**out, "imu": _kind_summaries(rows, where, codes, "limit_imu_m", stats)}


def _ratio(pred: Mapping[str, Any] | None, bound: Mapping[str, Any] | None) -> float | None:
    """A predictor's mean error / the bound's [-] (None where either has none)."""
    m = (pred or {}).get("mean_m")
    b = (bound or {}).get("mean_m")
    if m is None or b is None or not (math.isfinite(m) and math.isfinite(b)) or b <= 0:
        return None
    return float(m) / float(b)


def ratios(
    summaries: Mapping[str, Mapping[str, Any]], bound: Mapping[str, Any]
) -> dict[str, dict[str, float | None]]:
    """Per predictor of ``summaries`` (name -> kind -> summary), its ``x limit`` per kind
    against ``bound`` (:func:`_scope`), and against the IMU variant (``KIND_imu``)."""
    imu = bound.get("imu") or {}
    return {
        name: {
            **{k: _ratio(s.get(k), bound.get(k)) for k in KINDS},
            **{f"{k}_imu": _ratio(s.get(k), imu.get(k)) for k in KINDS},
        }
        for name, s in summaries.items()
    }


def below_reason(
    has_imu: bool, below_imu: bool, reference_kind: str | None, reads_imu: bool | None = None
) -> str:
    """Why a predictor's mean can lie below the bound that applies to it by more than its
    interval. ``reads_imu``: whether it reads the IMU (:func:`imu_readers`; None: posbench
    does not know, and both readings are given)."""
    why = []
    if reference_kind == KIND_FIXES:
        why.append(
            "the reference is a cubic through the receiver's own fixes, which the bound takes "
            "for the true motion"
        )
    assumptions = (
        "the bound's assumptions (white jerk of the PSD the reference shows, white fix noise "
        "of the variance taken) do not hold on this data"
    )
    if reads_imu is True and has_imu:
        why.append(
            "it reads the IMU and lies below the limit with IMU: it uses information that "
            "bound does not have too (wheel speed, a learned prior of how these vehicles "
            f"move, IMU errors smaller than the samples show), or {assumptions}"
        )
    elif reads_imu is False:
        why.append(
            "it does not read the IMU: it uses information the bound does not have (wheel "
            f"speed, a learned prior of how these vehicles move), or {assumptions}"
        )
    elif has_imu and not below_imu:
        why.append(
            "if it uses the IMU, that is what this bound does not have (it is not below the "
            f"limit with IMU); if it does not, {assumptions}"
        )
    else:
        why.append(
            "it uses information the bound"
            + (" with IMU" if has_imu else "")
            + " does not have (wheel speed, a learned prior of how these vehicles move"
            + ("" if has_imu else ", an IMU")
            + f"), or {assumptions}"
        )
    return "; ".join(why)


def _mean(summary: Mapping[str, Any] | None) -> float | None:
    """A summary's finite ``mean_m`` (None without one)."""
    m = (summary or {}).get("mean_m")
    return float(m) if m is not None and math.isfinite(m) else None


def below_limit(
    by_dataset: Mapping[str, Mapping[str, Any]],
    limit_by_dataset: Mapping[str, Mapping[str, Any]],
    references: Mapping[str, Mapping[str, Any]],
    reads_imu: Mapping[str, bool | None] | None = None,
    level: float = 0.95,
) -> list[dict[str, Any]]:
    """Predictors whose mean error lies below the bound that applies to them by more than
    their interval (the upper end of their 95 % interval of the mean below the bound's mean,
    less ``z`` times the bound's ``floor_sd_m``: what a slow floor measured on few samples
    leaves uncertain), per data set and query kind. The bound that applies: with the IMU
    for a predictor that reads it (``reads_imu[name]`` True, where the data set has one),
    fixes only for one that does not or whose reading is not known (None; then both readings
    are given). Entries: dataset, predictor, kind, ``mean_m``, ``ci95_hi_m``, ``limit_m``,
    ``limit_imu_m``, ``against`` (``"limit"`` or ``"limit with IMU"``), ``against_m`` (that
    bound's mean), ``floor_sd_m``, ``ratio`` (x that bound) and ``reason``."""
    out = []
    z = _z(level)
    for ds, preds in by_dataset.items():
        bound = limit_by_dataset.get(ds)
        if not bound:
            continue
        imu = bound.get("imu") or {}
        for name, s in preds.items():
            reads = (reads_imu or {}).get(name)
            for k in KINDS:
                mean = (s.get(k) or {}).get("mean_m")
                hi = ((s.get(k) or {}).get("ci95") or {}).get("mean_m", [None, None])[1]
                lim, lim_imu = _mean(bound.get(k)), _mean(imu.get(k))
                if mean is None or hi is None or lim is None or not math.isfinite(hi):
                    continue
                has_imu = lim_imu is not None
                use_imu = bool(reads) and has_imu
                applies = (imu if use_imu else bound).get(k) or {}
                against = lim_imu if use_imu and lim_imu is not None else lim
                sd = float(applies.get("floor_sd_m") or 0.0)
                if hi >= against - z * sd:
                    continue
                out.append(
                    {
                        "dataset": ds,
                        "predictor": name,
                        "kind": k,
                        "mean_m": mean,
                        "ci95_hi_m": hi,
                        "limit_m": lim,
                        "limit_imu_m": lim_imu,
                        "against": "limit with IMU" if use_imu else "limit",
                        "against_m": against,
                        "floor_sd_m": sd,
                        "ratio": _ratio(s.get(k), applies),
                        "reason": below_reason(
                            has_imu,
                            lim_imu is not None and hi < lim_imu,
                            (references.get(ds) or {}).get("kind"),
                            reads,
                        ),
                    }
                )
    return out


def _drive_entry(r: DriveRun, rows: BoundRows, spans: list[slice]) -> dict[str, Any]:
    """``drives[].limit``: what the drive's bound took, and its mean per kind, from its rows
    (``spans`` of ``rows``)."""
    info = {k: v for k, v in r.limit_info.items() if k != "cost_s"}  # timing: run-wide only
    mine = np.r_[tuple(spans)] if len(spans) > 1 else spans[0]
    kind = rows.kind[mine]
    bound = rows.limit_m[mine]
    imu = rows.limit_imu_m[mine]
    codes = {k: KINDS.index(k) for k in KINDS}
    return {
        **info,
        **{k: summarize(bound[kind == c]) for k, c in codes.items()},
        "imu": {k: summarize(imu[kind == c]) for k, c in codes.items()}
        if np.isfinite(imu).any()
        else None,
    }


def limit_section(
    runs: Sequence[DriveRun],
    res: dict[str, Any],
    stats: Statistics | None,
    reads_imu: Mapping[str, bool | None] | None = None,
) -> dict[str, Any] | None:
    """results.json's ``limit`` from the drives' bounds (None when no drive has one: scored
    answers, whose drives posbench did not replay), and each scored drive's
    ``drives[].limit`` in ``res``. ``res`` needs ``predictors``, ``by_dataset``,
    ``references`` and ``drives`` already.

    Returns:
        ``name``, ``name_imu``, ``assumptions``; ``overall`` and ``by_dataset[ds]``: per kind
        the bound's summary [m] with ``ci95``, ``imu`` the same with the IMU (None without
        one), and per data set ``gps_conditions`` (condition -> drives) and ``slow_floor``
        (drives whose slow error was added, and not); ``by_label[ds][kind][route type]``
        (no interval); ``ratios`` (``overall`` and ``by_dataset[ds]``: per predictor and
        kind its x limit, and ``KIND_imu`` against the IMU variant); ``reads_imu`` (per
        predictor: judged against the bound with IMU; None: not known); ``below``
        (:func:`below_limit`). No timing: results.json's figures are the same on every
        run of the same inputs (``DriveRun.limit_info["cost_s"]`` keeps each drive's).
    """
    rows = bound_rows(runs)
    if rows is None:
        return None
    index = {key: code for code, key in enumerate(rows.drives)}
    for d, r in zip(res["drives"], runs, strict=True):
        code = index.get((r.dataset, r.name))
        if code is not None:
            d["limit"] = _drive_entry(r, rows, rows.spans[code])
    everything = slice(0, len(rows))
    section: dict[str, Any] = {
        "name": LIMIT_NAME,
        "name_imu": LIMIT_IMU_NAME,
        "assumptions": ASSUMPTIONS,
        "overall": _scope(rows, everything, stats),
        "by_dataset": {},
        "by_label": {},
    }
    row_dataset = rows.drive_dataset[rows.drive]
    single = len(rows.datasets) == 1
    for ds in res["by_dataset"]:
        if ds not in rows.datasets:
            continue
        where = row_dataset == rows.datasets.index(ds)
        # one data set: its queries are all of them, the same figures
        entry = dict(section["overall"]) if single else _scope(rows, where, stats)
        mine = [r for r in runs if r.dataset == ds and r.has_limit and not r.skipped]
        conditions: dict[str, int] = {}
        for r in mine:
            conditions[r.gps_condition] = conditions.get(r.gps_condition, 0) + 1
        added = sum(bool(r.limit_info.get("slow_added")) for r in mine)
        entry["gps_conditions"] = dict(sorted(conditions.items()))
        entry["slow_floor"] = {"added": added, "not_added": len(mine) - added}
        section["by_dataset"][ds] = entry
        kind = rows.kind[where]
        bound = rows.limit_m[where]
        label = rows.label_text(where)
        section["by_label"][ds] = {
            k: summarize_groups(
                bound[kind == KINDS.index(k)], label[kind == KINDS.index(k)], order=list(LABELS)
            )
            for k in KINDS
        }
        del where, kind, bound, label
    section["ratios"] = {
        "overall": ratios(res["predictors"], section["overall"]),
        "by_dataset": {
            ds: ratios(res["by_dataset"][ds], b) for ds, b in section["by_dataset"].items()
        },
    }
    section["reads_imu"] = dict(reads_imu or {})
    section["below"] = below_limit(
        res["by_dataset"],
        section["by_dataset"],
        res.get("references") or {},
        reads_imu,
        stats.level if stats is not None else 0.95,
    )
    return section
