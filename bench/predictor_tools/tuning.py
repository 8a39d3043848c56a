"""Tune a predictor's noise parameters on development drives by grid search.

Honest tuning: the development drives are never the evaluation drives. For the
simulated GPS profiles (``none``, ``rtk``, ``consumer``) they are synthetic drives
drawn with seeds 1000+ (the built-in default set uses seed 0); for ``native``
(the paper's routes, real fixes) they are the LSTM's training routes, never its
validation routes. The objective is the mean future-point error [m] plus the mean
current-position error [m] over all queries.

Calibration follows the search (:func:`calibrate`): with the winning parameters, the
same development drives are replayed once and ``cov_scale`` (the factor ``covariance_at``
multiplies its covariance by) is set so that 95 % of the scored queries (future and now
pooled) fall inside their 95 % ellipse (:func:`posbench.metrics.calibration.coverage_scale`). It
changes no position, so it cannot trade accuracy for honesty. ``cv`` has no noise to
search, only this scale. Winners are written to the user's tuning file (``bench tune
--out``, keyed by predictor and GPS condition, with the names of the development drives),
which ``bench run --tuning`` merges over the package's tuning and the predictors'
physical defaults. The package's own ``predictors/tuned.json`` is never written by a
command: maintainers copy a file made this way into the source tree.

``kf`` can also be tuned by gradient descent instead of the grid (:func:`gradient_search`,
``bench tune kf --method gradient``): its noise fitted as OKF does
(:mod:`posbench.predictors.kalman.tuning.gradient`, needs torch), then calibrated the same way.
"""

from __future__ import annotations

import itertools
import json
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from posbench.config import RunConfig
from posbench.errors import UsageError
from posbench.predictors.registry import TUNED_FILE
from posbench.replay.runner import run
from posbench.scenarios.drive import Drive
from posbench.scoring.records import DriveRun

TUNED_PATH = TUNED_FILE
#: Search grids per predictor (values tried for each parameter).
GRIDS: dict[str, dict[str, list[float]]] = {
    "kf": {"gps_sigma": [0.01, 0.02, 0.05, 0.1, 0.3, 1.0], "accel_sigma": [0.1, 0.3, 1.0, 3.0]},
    "cv": {},
    "ekf": {"gps_sigma": [0.01, 0.02, 0.05, 0.1, 0.3, 1.0], "yaw_rate_sigma": [0.005, 0.02, 0.05]},
}
#: values of ``gps_sigma_scale`` tried where the fixes state their accuracy (rtk, consumer):
#: there R = (scale * stated sigma)^2 and ``gps_sigma`` is never used, so the scale takes its
#: place in the grid (rtk's old optimum gps_sigma 0.3 m is 15 x its stated 0.02 m)
SCALE_GRID: list[float] = [0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 16.0, 32.0]


def grid_for(predictor: str, gps_profile: str) -> dict[str, list[float]]:
    """The search grid of ``predictor`` under ``gps_profile``: :data:`GRIDS`, with
    ``gps_sigma`` replaced by ``gps_sigma_scale`` (:data:`SCALE_GRID`) for a simulated
    profile whose fixes state their accuracy (:func:`posbench.scenarios.degrade.stated_sigma_m`)."""
    from posbench.scenarios.degrade import GPS_PROFILES, stated_sigma_m

    grid = GRIDS[predictor]
    if gps_profile not in GPS_PROFILES or stated_sigma_m(gps_profile) is None:
        return dict(grid)
    return {
        ("gps_sigma_scale" if k == "gps_sigma" else k): (SCALE_GRID if k == "gps_sigma" else v)
        for k, v in grid.items()
    }


def objective(runs: Sequence[DriveRun]) -> float:
    """Mean future error + mean now error [m] over all queries of the runs."""
    import pandas as pd

    t = pd.concat([r.traces for r in runs if not r.traces.empty], ignore_index=True)
    return float(
        t.loc[t.kind == "future", "error_m"].mean() + t.loc[t.kind == "now", "error_m"].mean()
    )


def grid_search(
    predictor: str,
    drives: Sequence[Drive],
    gps_profile: str,
    grid: dict[str, list[float]],
    workers: int = 2,
    seed: int = 0,
    on_step: Callable[[dict[str, Any], float], None] | None = None,
) -> tuple[dict[str, Any], list[tuple[dict[str, Any], float]]]:
    """Coordinate-wise grid search: the first two parameters jointly, then each further
    one alone with the best so far. Returns (best parameters, every trial)."""
    names = list(grid)
    trials: list[tuple[dict[str, Any], float]] = []

    def score(params: dict[str, Any]) -> float:
        cfg = RunConfig(
            predictors=(predictor,),
            gps_profile=gps_profile,
            seed=seed,
            predictor_options={predictor: params},
            use_tuned=False,
        )
        val = objective(run(drives, cfg, workers=workers))
        trials.append((dict(params), val))
        if on_step:
            on_step(params, val)
        return val

    best: dict[str, Any] = {}
    best_val = np.inf
    head = names[:2]  # an empty grid: one trial of the defaults
    for combo in itertools.product(*(grid[n] for n in head)):
        p = dict(zip(head, combo, strict=True))
        v = score(p)
        if v < best_val:
            best, best_val = p, v
    for n in names[2:]:
        base = dict(best)
        for val in grid[n]:
            p = {**base, n: val}
            v = score(p)
            if v < best_val:
                best, best_val = p, v
    return best, trials


def calibrate(
    predictor: str,
    drives: Sequence[Drive],
    gps_profile: str,
    params: dict[str, Any],
    workers: int = 2,
    seed: int = 0,
) -> float:
    """``cov_scale`` for ``params``: replay ``drives`` once and return the factor that makes
    95 % of the scored queries' 95 % ellipses cover the truth, rounded to 3 significant
    digits (NaN when the predictor reports no covariance on these drives)."""
    import pandas as pd

    from posbench.metrics.calibration import coverage_scale, mahalanobis_sq
    from posbench.scoring.schema import COV_COLUMNS, scored_mask

    cfg = RunConfig(
        predictors=(predictor,),
        gps_profile=gps_profile,
        seed=seed,
        predictor_options={predictor: {k: v for k, v in params.items() if k != "cov_scale"}},
        use_tuned=False,
    )
    traces = [r.traces for r in run(drives, cfg, workers=workers) if not r.traces.empty]
    if not traces:
        return float("nan")
    t = pd.concat(traces, ignore_index=True)
    if any(c not in t for c in COV_COLUMNS):
        return float("nan")
    t = t[scored_mask(t)]
    err = t[["x", "y"]].to_numpy(float) - t[["x_ref", "y_ref"]].to_numpy(float)
    k = coverage_scale(mahalanobis_sq(err, t[list(COV_COLUMNS)].to_numpy(float)))
    return float(f"{k:.3g}") if np.isfinite(k) else k


#: what separates a tuned entry's note on its noise from the note on its calibration
CALIBRATION_NOTE = "; cov_scale for 95 % coverage by"


def tuning_note(predictor: str, condition: str, calibration: str, path: Path | None = None) -> str:
    """The note of an entry whose noise is kept and whose scale is refitted: the note the
    tuning in force holds (``path``'s entry if it has one, else the package's) on how its
    noise was tuned (without an older calibration note), then ``calibration``;
    ``calibration`` alone where there is none."""
    from posbench.predictors.registry import tuning_entry

    found = tuning_entry(predictor, condition, path if path is not None and path.exists() else None)
    old = found[1].get("how", "") if found else ""
    noise = "" if old.startswith(CALIBRATION_NOTE[2:]) else old.split(CALIBRATION_NOTE)[0]
    return f"{noise}; {calibration}" if noise else calibration


def held_cov_scale(predictor: str, cov_scale: float) -> tuple[float, str | None]:
    """A calibrated ``cov_scale`` held in the range the baselines accept
    (:data:`~posbench.predictors._geometry.COV_SCALE_RANGE`), and one line on the clamp
    (None where there was none). A scale of 0 (every error on the drives 0: a parked car
    with exact fixes) becomes the least one, whose ellipses still cover; a larger one than
    the most is held at the most, whose ellipses then cover less than 95 %."""
    from posbench.predictors._geometry import COV_SCALE_RANGE

    lo, hi = COV_SCALE_RANGE
    if not cov_scale == cov_scale or lo <= cov_scale <= hi:
        return cov_scale, None
    held = min(max(cov_scale, lo), hi)
    covers = "still cover" if cov_scale < lo else "cover less than"
    why = f"its 95 % ellipses {covers} 95 % of the errors on these drives"
    return held, (
        f"calibrated cov_scale {cov_scale:g} is outside the range {predictor} accepts "
        f"[{lo:g}, {hi:g}]: clamped to {held:g} ({why})"
    )


def save_tuned(
    predictor: str,
    condition: str,
    params: dict[str, Any],
    note: str,
    path: Path,
    drives: Sequence[str] = (),
    extra: Mapping[str, Any] | None = None,
) -> None:
    """Merge one result into the tuning file ``path`` (created if missing): its
    ``params``, ``how`` they were obtained and the ``drives`` they were tuned on, plus the
    keys of ``extra`` (e.g. ``fit``: what a gradient tuning fitted; readers use ``params``
    only).

    The merged file is written to a temporary file beside ``path`` and checked there as
    ``bench run --tuning`` checks it (:func:`~posbench.replay.predictor_setup.tuning_entry_refusal`,
    the run's own function): an entry the run would refuse raises :class:`UsageError`
    (one line) and ``path`` is left as it was. Otherwise the temporary file is synced to
    disk and renamed over ``path``: a kill at any moment leaves the old file or the new
    one, never part of one."""
    from posbench.replay.predictor_setup import tuning_entry_refusal

    if path.resolve() == TUNED_PATH.resolve():
        raise ValueError("the package's tuning is not written by a command")
    data = json.loads(path.read_text()) if path.exists() else {}
    data.setdefault(predictor, {})[condition] = {
        "params": params,
        "how": note,
        "drives": sorted(drives),
        **(extra or {}),
    }
    text = json.dumps(data, indent=2, sort_keys=True) + "\n"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        why = tuning_entry_refusal(tmp, predictor, condition, {})
        if why is not None:
            raise UsageError(
                f"nothing saved to {path}: `bench run --tuning` would refuse it: {why}"
            )
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    _sync_folder(path.parent)


def _sync_folder(folder: Path) -> None:
    """fsync a folder (so a rename in it is on disk too); a no-op where the system
    cannot open one (Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def gradient_search(
    drives: Sequence[Drive],
    gps_profile: str,
    seed: int = 0,
    on_step: Callable[[int, dict[str, float]], None] | None = None,
    **fit: Any,
) -> dict[str, Any]:
    """The ``kf``'s noise fitted by gradient descent on ``drives``
    (:func:`posbench.predictors.kalman.tuning.gradient.gradient_tune`, whose result this returns)
    on the fixes a run with ``seed`` feeds under ``gps_profile``
    (:func:`~posbench.replay.prepare.prepare_drive`: the calibration's replay sees the same
    fixes). ``fit``: the keywords of ``gradient_tune``
    (``iterations``, ``lr``, ``holdout``, ...). Raises ImportError without torch."""
    from posbench.predictors.kalman.tuning.gradient import gradient_tune, require_torch
    from posbench.replay.prepare import prepare_drive

    require_torch()
    cfg = RunConfig(predictors=("kf",), gps_profile=gps_profile, seed=seed, use_tuned=False)
    gps = [prepare_drive(d, cfg).gps for d in drives]
    return gradient_tune(drives, gps_profile, gps=gps, seed=seed, on_step=on_step, **fit)


def gradient_note(fit: Mapping[str, Any]) -> str:
    """One line on what :func:`gradient_search` fitted (for the tuning file's ``how``)."""
    loss = fit["loss"]["train"]
    q = np.asarray(fit["Q_c"])
    r = np.asarray(fit["R"])
    parts = [
        f"gradient descent (OKF: {fit['best_iteration']} Adam steps, beta-NLL of the 0.2 s "
        f"reference) on {fit['fixes']['train']} fixes",
        f"Q_c eigenvalues {_eig(q)} m^2/s^5, R eigenvalues {_eig(r)} m^2",
    ]
    if fit.get("sigma_a") is not None:
        parts.append(f"sigma_a {fit['sigma_a']:.3g} m/s^2")
    if fit.get("slow") is not None:
        parts.append(f"slow error eigenvalues {_eig(np.asarray(fit['slow']))} m^2")
    parts.append(f"mean 0.2 s error {loss['error_m']:.4f} m, NLL {loss['nll']:.3f}")
    held = fit["loss"].get("holdout")
    if held:
        parts.append(f"held out {held['error_m']:.4f} m, NLL {held['nll']:.3f}")
    return "; ".join(parts)


def _eig(m: np.ndarray) -> str:
    """The eigenvalues of a symmetric 2x2 matrix, as ``a / b`` (3 significant digits)."""
    lo, hi = np.linalg.eigvalsh(m)
    return f"{hi:.3g} / {lo:.3g}"
