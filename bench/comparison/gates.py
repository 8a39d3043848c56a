"""posbench.comparison.gates (split from the flat bench/; docstring to write)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from posbench.comparison.align import Metric
from posbench.errors import UsageError
from posbench.metrics.bootstrap import DEFAULT_RESAMPLES
from posbench.saved_run.run import Run

#: statistics whose paired difference is computed from per-drive summaries alone
#: (pooled from per-drive sums); the others need the runs' traces
SUMMARY_STATS = ("mean_m", "rmse_m")


#: fewest shared drives for a paired CI: with one drive, resampling drives says nothing
#: about the spread (the CI is then NaN and no gate can fail on it)
MIN_DRIVES = 2


@dataclass(frozen=True)
class Gate:
    """``PREDICTOR:KIND.STAT:TOL``: the NEW run fails when its figure is worse (larger) than
    the OLD run's by more than the tolerance **and** the paired CI of NEW - OLD excludes 0.

    ``tolerance`` is a fraction of the OLD figure when ``relative`` (``5%``), else metres
    (``0.01m``)."""

    predictor: str
    metric: Metric
    tolerance: float
    relative: bool
    text: str

    @classmethod
    def parse(cls, text: str) -> Gate:
        option = f"--fail-if-worse {text!r}"
        parts = text.strip().split(":")
        if len(parts) != 3 or not all(p.strip() for p in parts):
            raise UsageError(f"{option}: expected PREDICTOR:KIND.STAT:TOLERANCE, e.g. "
                             f"'lstm:future.mean_m:5%' or 'kf:now.p95_m:0.01m'")
        pred, metric, tol = (p.strip() for p in parts)
        m = re.fullmatch(r"([0-9]*\.?[0-9]+)\s*(%|m)", tol)
        if not m:
            raise UsageError(f"{option}: tolerance {tol!r} must be a percentage (5%) or metres "
                             f"(0.01m)")
        value = float(m.group(1))
        relative = m.group(2) == "%"
        return cls(pred, Metric.parse(metric, option), value / 100 if relative else value,
                   relative, text.strip())

    def limit(self, old: float) -> float:
        """The largest NEW figure that passes, given the OLD one [m]."""
        return old * (1 + self.tolerance) if self.relative else old + self.tolerance


# ------------------------------------------------------------------ paired differences
def _drive_key(d: Mapping[str, Any]) -> tuple[str, str]:
    return str(d["dataset"]), str(d["name"])


def _drive_summaries(run: Run, predictor: str, kind: str, dataset: str | None = None
                     ) -> dict[tuple[str, str], Mapping[str, Any]]:
    out = {}
    for d in run.results.get("drives", []):
        if dataset is not None and str(d["dataset"]) != dataset:
            continue
        s = (d.get("predictors") or {}).get(predictor, {}).get(kind)
        if not d.get("skipped") and s and s.get("count"):
            out[_drive_key(d)] = s
    return out


def _pooled_by_resample(summaries: Sequence[Mapping[str, Any]], stat: str,
                        weights: np.ndarray) -> tuple[float, np.ndarray]:
    """The pooled ``stat`` (mean_m or rmse_m) of drives given their summaries, and its value
    under each resample (rows of ``weights``: multiplicities of the drives)."""
    from posbench.metrics.bootstrap import resampled_means

    n = np.array([float(s["count"]) for s in summaries])
    if stat == "mean_m":
        x = np.array([float(s["mean_m"]) for s in summaries]) * n
        return float(x.sum() / n.sum()), resampled_means(x, n, weights)
    x = np.array([float(s["rmse_m"]) ** 2 for s in summaries]) * n
    return float(np.sqrt(x.sum() / n.sum())), np.sqrt(resampled_means(x, n, weights))


def _pooled_quantiles_by_resample(errors: Sequence[np.ndarray], q: float, weights: np.ndarray
                                  ) -> tuple[float, np.ndarray]:
    """Quantile ``q`` (0..1, linear interpolation) of the pooled errors of drives, and its
    value under each resample; exact (weights are drive multiplicities)."""
    from posbench.metrics.bootstrap import resampled_quantiles

    values = np.concatenate(errors)
    units = np.concatenate([np.full(len(e), i, dtype=np.int64) for i, e in enumerate(errors)])
    order = np.argsort(values, kind="stable")
    return (float(np.quantile(values, q)),
            resampled_quantiles(values[order], units[order], weights, (q,))[:, 0])


@dataclass(frozen=True)
class PairedDifference:
    """NEW - OLD of one statistic over the drives both runs scored (positive: NEW worse)."""

    old: float
    new: float
    diff: float
    lo: float
    hi: float
    drives: int

    @property
    def conclusive(self) -> bool:
        """The 95 % CI excludes 0 (False when there is no CI)."""
        return bool(self.lo > 0 or self.hi < 0)


def paired_difference(old: Run, new: Run, predictor: str, metric: Metric,
                      seed: int = 0, resamples: int = DEFAULT_RESAMPLES, dataset: str | None = None
                      ) -> PairedDifference | None:
    """The paired cluster-bootstrap difference of ``metric`` (NEW - OLD) for ``predictor``
    over the drives both runs scored (of ``dataset`` only, if given); None when they share
    no drive.

    ``mean_m`` and ``rmse_m`` come from the per-drive summaries of results.json; the other
    statistics read the runs' ``traces.parquet`` (a :class:`DataError` if one has none)."""
    from posbench.metrics.bootstrap import percentile_interval, resample_counts

    a = _drive_summaries(old, predictor, metric.kind, dataset)
    b = _drive_summaries(new, predictor, metric.kind, dataset)
    common = sorted(set(a) & set(b))
    if not common:
        return None
    enough = len(common) >= MIN_DRIVES
    w = (resample_counts(len(common), resamples, seed) if enough
         else np.ones((1, len(common)), dtype=np.int64))
    if metric.stat in SUMMARY_STATS:
        va, ra = _pooled_by_resample([a[k] for k in common], metric.stat, w)
        vb, rb = _pooled_by_resample([b[k] for k in common], metric.stat, w)
    elif metric.stat == "max_m":
        ma = np.array([float(a[k]["max_m"]) for k in common])
        mb = np.array([float(b[k]["max_m"]) for k in common])
        picked = w > 0
        va, vb = float(ma.max()), float(mb.max())
        ra = np.where(picked, ma, -np.inf).max(axis=1)
        rb = np.where(picked, mb, -np.inf).max(axis=1)
    else:
        q = 0.5 if metric.stat == "median_m" else 0.95
        ea = _drive_errors(old, predictor, metric.kind, common)
        eb = _drive_errors(new, predictor, metric.kind, common)
        va, ra = _pooled_quantiles_by_resample(ea, q, w)
        vb, rb = _pooled_quantiles_by_resample(eb, q, w)
    lo, hi = percentile_interval(rb - ra) if enough else (math.nan, math.nan)
    return PairedDifference(va, vb, vb - va, lo, hi, len(common))


def _drive_errors(run: Run, predictor: str, kind: str, drives: Sequence[tuple[str, str]]
                  ) -> list[np.ndarray]:
    """The scored errors [m] of ``predictor`` per drive, in ``drives`` order (from traces)."""
    from posbench.scoring.schema import scored_mask

    tr = run.traces
    tr = tr[scored_mask(tr) & (tr["predictor"] == predictor).to_numpy()
            & (tr["kind"] == kind).to_numpy()]
    groups = {(str(ds), str(dr)): g["error_m"].to_numpy(dtype=float)
              for (ds, dr), g in tr.groupby(["dataset", "drive"], observed=True, sort=False)}
    out = []
    for k in drives:
        e = groups.get(k, np.empty(0))
        out.append(e[np.isfinite(e)])
    return out


@dataclass(frozen=True)
class GateCheck:
    """One gate's outcome: passed or not, with the figures behind it."""

    gate: Gate
    paired: PairedDifference
    limit: float

    @property
    def failed(self) -> bool:
        """NEW beyond the limit and the paired CI of NEW - OLD entirely above 0."""
        return bool(self.paired.new > self.limit and self.paired.lo > 0)

    def line(self) -> str:
        p = self.paired
        verdict = "FAILED" if self.failed else "passed"
        return (f"{verdict}: {self.gate.predictor} {self.gate.metric} {p.new:.4f} m (NEW) vs "
                f"{p.old:.4f} m (OLD), limit {self.limit:.4f} m; NEW - OLD {p.diff:+.4f} m, "
                f"95 % CI [{p.lo:+.4f}, {p.hi:+.4f}] over {p.drives} shared drives")


def check_gates(old: Run, new: Run, gates: Sequence[Gate], seed: int = 0) -> list[GateCheck]:
    """Each gate checked on NEW against OLD (a :class:`UsageError` when a gate names a
    predictor one of the runs lacks or the runs share no scored drive)."""
    out = []
    for g in gates:
        for run, which in ((old, "OLD"), (new, "NEW")):
            if g.predictor not in run.predictors:
                raise UsageError(f"--fail-if-worse {g.text!r}: the {which} run has no predictor "
                                 f"{g.predictor!r} (it has {', '.join(run.predictors)})")
        paired = paired_difference(old, new, g.predictor, g.metric, seed)
        if paired is None:
            raise UsageError(f"--fail-if-worse {g.text!r}: the runs share no scored drive")
        out.append(GateCheck(g, paired, g.limit(paired.old)))
    return out
