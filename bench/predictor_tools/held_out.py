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
(:func:`posbench.metrics.cluster_bootstrap.paired_ratio_diff`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from posbench.config import RunConfig
from posbench.metrics.cluster_bootstrap import paired_ratio_diff, resample_counts
from posbench.replay.runner import run
from posbench.scenarios.drive import Drive
from posbench.scoring.schema import scored_mask

#: the kf tuned by gradient, in the comparison's runs
GRADIENT = "kf@gradient"
#: seed of the synthetic development drives the comparison adds (those ``bench tune``
#: develops on: never the benchmark's seed 0, never a training seed)
DEV_SEED = 1000
#: minutes of training drives the gradient-tuned kf is fitted on, at most (about)
GRADIENT_MINUTES = 10.0
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


def gradient_priors(
    train_d: Sequence[Drive],
    profiles: Sequence[str],
    seed: int = 0,
    tell: Callable[[str], None] | None = None,
) -> dict[str, dict[str, Any]]:
    """The kf with its noise fitted by gradient (``bench tune kf --method gradient``,
    :func:`posbench.predictors.kalman.tuning.gradient.gradient_tune`) on the hybrid's own training
    drives, per GPS condition they give: their own fixes (``native``) for drives without a
    truth, each of ``profiles`` for those with one. A condition none gives is not fitted.
    At most about :data:`GRADIENT_MINUTES` of drives per condition (every k-th drive by
    name): the fit's cost grows with the drive time (about 1 s per Adam step for 10 min).
    ``tell`` hears one line per fit."""
    from posbench.predictors.kalman.tuning.gradient import gradient_tune

    def spread(ds: list[Drive]) -> list[Drive]:
        ds = sorted(ds, key=lambda d: d.name)
        total = sum(d.duration_s for d in ds) / 60.0
        return ds[:: max(1, math.ceil(total / GRADIENT_MINUTES))]

    own = [d for d in train_d if d.truth is None or len(d.truth) <= 1]
    with_truth = [d for d in train_d if d.truth is not None and len(d.truth) > 1]
    out = {}
    for cond, ds in [("native", spread(own))] + [(p, spread(with_truth)) for p in profiles]:
        if ds:
            if tell is not None:
                tell(f"fitting the kf's noise by gradient ({cond}, {len(ds)} drives)")
            out[cond] = gradient_tune(ds, cond, seed=seed)
    return out


def hybrid_held_out(
    model_dir: Path,
    train_d: Sequence[Drive],
    val_d: Sequence[Drive],
    profiles: Sequence[str],
    *,
    workers: int = 2,
    seed: int = 0,
    tell: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """What ``bench train --network hybrid`` records as model.json ``held_out``: the model
    against ``kf`` and the kf tuned by gradient on ``train_d`` (:func:`gradient_priors`),
    on the validation drives ``val_d`` plus the synthetic development drives of seed
    :data:`DEV_SEED` (:func:`compare_on_held_out`); the gradient fits under
    ``gradient_prior``."""
    from posbench.scenarios.synthetic import default_drives

    if tell is not None:
        tell("held-out comparison with the prior: replaying validation drives")
    dev = default_drives(seed=DEV_SEED)  # never trained on (training uses other seeds)
    gradient = gradient_priors(train_d, profiles, seed, tell)
    res = compare_on_held_out(
        model_dir,
        [*val_d, *dev],
        profiles,
        gradient_params={c: g["params"] for c, g in gradient.items()},
        workers=workers,
        seed=seed,
    )
    res["gradient_prior"] = {
        c: {k: g[k] for k in ("params", "Q_c", "R", "sigma_a", "loss", "best_iteration")}
        | {
            "how": "predictors.kalman.tuning.gradient.gradient_tune on the training drives "
            "(bench tune kf --method gradient), defaults"
        }
        for c, g in gradient.items()
    }
    return res
