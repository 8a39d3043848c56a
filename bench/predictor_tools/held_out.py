"""A trained hybrid against its prior on held-out development drives, with paired CIs.

``bench train --network hybrid`` calls :func:`compare_on_held_out` once the model is
written: the validation drives (held out by route, never trained on) are replayed through
the real runner with ``kf`` (the prior the hybrid sits on), ``hybrid`` (the new model,
its gate on) and, where given, ``kf@gradient`` (the kf with noise fitted by gradient on
the training drives, ``bench tune kf --method gradient``: the prior tuned the same way as
the network). Drives with a truth are replayed under each simulated GPS profile of the
training; drives without one on their own fixes (condition ``native``), once.

Each figure is the mean error [m] of the scored queries of one kind (``future``: the
horizon after each fix; ``now``: the current position between fixes), pooled over the
drives; each difference (hybrid minus the other, negative = the hybrid is better) has a
95 % paired cluster-bootstrap interval over the drives
(:func:`posbench.metrics.bootstrap.paired_ratio_diff`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from posbench.config import RunConfig
from posbench.metrics.bootstrap import paired_ratio_diff, resample_counts
from posbench.replay.runner import run
from posbench.scenarios.drive import Drive
from posbench.scoring.schema import scored_mask

#: the kf tuned by gradient, in the comparison's runs
GRADIENT = "kf@gradient"
KINDS = ("future", "now")


def _sums(runs: Sequence[Any], predictors: Sequence[str]) -> dict[tuple[str, str], np.ndarray]:
    """(predictor, kind) -> (drives, 2) array of [error sum [m], count] per drive."""
    out = {(p, k): np.zeros((len(runs), 2)) for p in predictors for k in KINDS}
    for i, r in enumerate(runs):
        t = r.traces
        if t.empty:
            continue
        t = t[scored_mask(t)]
        for (p, k), a in out.items():
            e = t.loc[(t.predictor == p) & (t.kind == k), "error_m"].to_numpy(float)
            e = e[np.isfinite(e)]
            a[i] = e.sum(), e.size
    return out


def _condition(runs: Sequence[Any], predictors: Sequence[str], seed: int) -> dict[str, Any]:
    """Means and paired differences of one GPS condition's runs."""
    sums = _sums(runs, predictors)
    keep = np.flatnonzero(sums[("kf", "future")][:, 1] > 0)
    res: dict[str, Any] = {"drives": int(keep.size)}
    if keep.size == 0:
        return res
    w = resample_counts(keep.size, seed=seed)
    for k in KINDS:
        row: dict[str, Any] = {}
        for p in predictors:
            s = sums[(p, k)][keep]
            row[f"{p}_mean_m"] = float(s[:, 0].sum() / s[:, 1].sum()) if s[:, 1].sum() else None
        hy = sums[("hybrid", k)][keep]
        for p in predictors:
            if p == "hybrid":
                continue
            o = sums[(p, k)][keep]
            row[f"hybrid_minus_{p}"] = paired_ratio_diff(o[:, 0], o[:, 1], hy[:, 0], hy[:, 1], w)
        res[k] = row
    return res


def compare_on_held_out(
    model_dir: Path,
    drives: Sequence[Drive],
    profiles: Sequence[str],
    *,
    gradient_params: dict[str, dict[str, Any]] | None = None,
    workers: int = 2,
    seed: int = 0,
    max_drives: int = 40,
) -> dict[str, Any]:
    """The hybrid in ``model_dir`` against ``kf`` (and ``kf@gradient`` where
    ``gradient_params`` holds the condition) on held-out ``drives``; see the module doc.

    Returns:
        ``{"drives": [names], "conditions": {condition: {"drives": n, "future": {...},
        "now": {...}}}, "how": text}``; per kind ``<predictor>_mean_m`` and
        ``hybrid_minus_<predictor>`` = ``{"diff", "lo", "hi"}`` [m].
    """
    picked = sorted(drives, key=lambda d: d.name)
    if len(picked) > max_drives:  # evenly spread over the sorted names, deterministic
        idx = np.linspace(0, len(picked) - 1, max_drives).round().astype(int)
        picked = [picked[i] for i in idx]
    with_truth = [d for d in picked if d.truth is not None and len(d.truth) > 1]
    own = [d for d in picked if d.truth is None or len(d.truth) <= 1]
    plan = [(p, with_truth) for p in profiles] + [("native", own)]
    out: dict[str, Any] = {"drives": [d.name for d in picked], "conditions": {}}
    for cond, ds in plan:
        if not ds:
            continue
        grad = (gradient_params or {}).get(cond)
        preds = ("kf", "hybrid") + ((GRADIENT,) if grad is not None else ())
        options: dict[str, dict[str, Any]] = {"hybrid": {"model": str(model_dir)}}
        if grad is not None:
            options[GRADIENT] = dict(grad)
        cfg = RunConfig(
            predictors=preds,
            gps_profile=cond,
            seed=seed,
            predictor_options=options,
        )
        runs = run(ds, cfg, workers=workers)
        out["conditions"][cond] = _condition(runs, preds, seed)
    out["how"] = (
        "Replayed by the runner on held-out development drives (validation split, by "
        f"route; at most {max_drives}); mean error [m] of the scored queries pooled over "
        "drives; hybrid minus other with a 95 % paired cluster-bootstrap interval over "
        "drives (negative: the hybrid is better)"
    )
    return out
