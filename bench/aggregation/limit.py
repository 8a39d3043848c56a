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
uncertain (:func:`~posbench.aggregation.bound_figures.floor_sd`), and a predictor is below
only by more than that too. The bound is never a predictor: it is kept out of
``predictors``, the paired comparison, the sanity check and every gate. The figures are
combined one drive at a time (:mod:`posbench.aggregation.bound_figures`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from posbench.aggregation.bound_figures import bound_figures, z_of
from posbench.aggregation.intervals import Statistics
from posbench.metrics.limit import LIMIT_IMU_NAME, LIMIT_NAME
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
    against ``bound`` (a scope of :class:`~posbench.aggregation.bound_figures.BoundFigures`),
    and against the IMU variant (``KIND_imu``)."""
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
    z = z_of(level)
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
    figures = bound_figures(runs, list(res["by_dataset"]), stats)
    if figures is None:
        return None
    for d, r in zip(res["drives"], runs, strict=True):
        entry = figures.drives.get((r.dataset, r.name))
        if entry is not None:
            info = {k: v for k, v in r.limit_info.items() if k != "cost_s"}  # run-wide only
            d["limit"] = {**info, **entry}
    section: dict[str, Any] = {
        "name": LIMIT_NAME,
        "name_imu": LIMIT_IMU_NAME,
        "assumptions": ASSUMPTIONS,
        "overall": figures.overall,
        "by_dataset": {},
        "by_label": figures.by_label,
    }
    for ds, entry in figures.by_dataset.items():
        mine = [r for r in runs if r.dataset == ds and r.has_limit and not r.skipped]
        conditions: dict[str, int] = {}
        for r in mine:
            conditions[r.gps_condition] = conditions.get(r.gps_condition, 0) + 1
        added = sum(bool(r.limit_info.get("slow_added")) for r in mine)
        entry["gps_conditions"] = dict(sorted(conditions.items()))
        entry["slow_floor"] = {"added": added, "not_added": len(mine) - added}
        section["by_dataset"][ds] = entry
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
