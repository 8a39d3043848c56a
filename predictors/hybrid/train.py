"""Train the ``hybrid``'s residual network and write ``model.onnx`` + ``model.json``.

:func:`run_training` is what ``bench train --model hybrid`` calls; its arguments mirror
:func:`posbench.predictors.lstm.train.run_training`. Pipeline: drives (``--data``, the benchmark's
synthetic generator, hours of :mod:`posbench.scenarios.corpus`) -> split by route
(:func:`posbench.predictors.lstm.training_data.split_by_route`) -> rows
(:func:`posbench.predictors.hybrid.data.hybrid_windows`):
drives with truth get their fixes drawn from it under each of ``profiles`` and the kf prior
with that profile's tuned parameters (``predictors/tuned.json``); drives without truth
keep their own fixes and the ``native`` parameters -> statistics -> Adam, early stopping
on the validation future-point error [m], turn rows oversampled, batches mirrored at
random (left <-> right: dy, ay, yaw of the features, y of prior and target negated) ->
ONNX export with a parity check -> the gate (:mod:`posbench.predictors.hybrid.gate`: the
shrinkage per horizon fitted on the validation rows, the box of the training inputs) ->
optionally the held-out comparison with the prior (``held_out``, run by ``bench train``) ->
model card.

Loss: beta-NLL (Seitzer et al., ICLR 2022, beta = 0.5) of the residual under the predicted
Gaussian, per horizon and axis, in residual units: the variance head learns how far the
prior can be trusted, and rows whose residual is noise (a consumer receiver's metre-level
error that nothing in the window can predict) weigh less in the mean's gradient instead of
swamping the centimetres elsewhere. Imports torch: training only.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from posbench.predictors.hybrid.data import HybridWindows, hybrid_windows
from posbench.predictors.hybrid.gate import fit_shrink, input_envelope
from posbench.predictors.lstm.train import (
    EarlyStop,
    Progress,
    error_stats,
    package_versions,
    sample_weights,
    subsample,
)
from posbench.predictors.lstm.training_data import (
    corpus_card,
    gather_drives,
    group_of,
    manifest,
    synthetic_seeds,
)
from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError

BETA = 0.5
#: the loss weighs the 0.2 s horizon (the benchmark's future point) this much more
FUTURE_WEIGHT = 4.0

#: ``held_out(model_dir, train_drives, validation_drives, profiles)``: a comparison of the
#: written model with its prior on the validation drives, recorded as model.json
#: ``held_out`` (``bench train`` passes
#: :func:`posbench.predictor_tools.held_out.compare_on_held_out` through it)
HeldOut = Callable[[Path, Sequence[Drive], Sequence[Drive], Sequence[str]], dict[str, Any]]


def drive_rows(
    drive: Drive, profiles: Sequence[str], kf_params: dict[str, dict], seed: int
) -> HybridWindows:
    """Training rows of one drive: per profile for a drive with truth, else its own fixes."""
    if drive.truth is None or len(drive.truth) < 2:
        return hybrid_windows(drive, drive.gps, kf_params.get("native") or {}, condition="native")
    from posbench.scenarios.degrade import degrade_gps

    return HybridWindows.concat(
        [
            hybrid_windows(
                drive,
                degrade_gps(drive.truth, p, seed=seed * 1000 + 100 * j),
                kf_params.get(p) or {},
                condition=p,
            )
            for j, p in enumerate(profiles)
        ]
    )


def build_rows(
    drives: Sequence[Drive], profiles: Sequence[str], kf_params: dict[str, dict], seed: int
) -> HybridWindows:
    return HybridWindows.concat([drive_rows(d, profiles, kf_params, seed) for d in drives])


def future_answers(hw: HybridWindows, corr: np.ndarray) -> np.ndarray:
    """World positions at t_fix + 0.2 s [m]: the kf's answer plus the 0.2 s correction
    (B, 2) [m, heading frame] rotated by psi."""
    c, s = np.cos(hw.psi), np.sin(hw.psi)
    return hw.kf_future + np.stack(
        [c * corr[:, 0] - s * corr[:, 1], s * corr[:, 0] + c * corr[:, 1]], axis=1
    )


def balanced_future_error(hw: HybridWindows, future: np.ndarray, groups: dict[str, str]) -> float:
    """The validation error the training selects by [m]: per cell (source group of the
    drive, GPS condition) the ratio of the hybrid's mean future-point error to its prior's,
    averaged over the cells with equal weight, times the prior's mean over all rows. Equal
    to the prior's mean for a correction of 0; a consumer receiver's metre-level rows, where
    nothing is to be learned, do not outweigh the centimetre cells (or the real drives)."""
    e_h = np.linalg.norm(future - hw.truth_future, axis=1)
    e_k = np.linalg.norm(hw.kf_future - hw.truth_future, axis=1)
    cells = np.array([f"{groups.get(d)}|{c}" for d, c in zip(hw.drive, hw.condition, strict=True)])
    ratios = [e_h[cells == c].mean() / e_k[cells == c].mean() for c in np.unique(cells)]
    return float(np.mean(ratios) * e_k.mean())


def evaluate(hw: HybridWindows, future: np.ndarray, groups: dict[str, str]) -> dict:
    """Future-point error [m] of the hybrid and of its kf prior alone, overall, per label and
    per source group."""

    def both(m: np.ndarray) -> dict:
        return {
            "hybrid": error_stats(future[m], hw.truth_future[m]),
            "kf": error_stats(hw.kf_future[m], hw.truth_future[m]),
        }

    out = {"all": both(np.ones(len(hw), dtype=bool))}
    for lab in sorted(set(hw.label.tolist())):
        out[f"label:{lab}"] = both(hw.label == lab)
    for g in sorted(set(groups.values())):
        out[f"group:{g}"] = both(np.array([groups.get(d) == g for d in hw.drive], dtype=bool))
    return out


def run_training(
    data_paths: Sequence[str | Path],
    out_dir: Path,
    epochs: int = 40,
    seed: int = 0,
    synthetic: int = 0,
    progress: Progress | None = None,
    command: str | None = None,
    drives: Sequence[Drive] | None = None,
    hidden: int = 48,
    lstm_layers: int = 1,
    batch_size: int = 512,
    lr: float = 2e-3,
    patience: int = 6,
    threads: int = 2,
    on_early_stop: EarlyStop | None = None,
    corpus_hours: float = 0.0,
    profiles: Sequence[str] = ("none", "rtk", "consumer"),
    mirror: bool = True,
    max_minutes: float = 30.0,
    max_val_windows: int = 60_000,
    kf_params: dict[str, dict] | None = None,
    held_out: HeldOut | None = None,
) -> dict:
    """Train, export and describe a hybrid model; returns the dict written to model.json.

    Args as :func:`posbench.predictors.lstm.train.run_training`; ``hidden`` is the network width
    (default 48), ``kf_params`` the prior's parameters per GPS condition (default: the kf's
    tuned ones, :func:`posbench.predictors.hybrid.export.prior_kf_params`); ``held_out``
    compares the written model with its prior on the validation drives (:data:`HeldOut`)."""
    import torch

    from posbench.predictors.hybrid.export import fit_stats, prior_kf_params, save_model
    from posbench.predictors.hybrid.model import HybridNet
    from posbench.predictors.training_loop import fit_epochs

    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(threads)
    prior = dict(kf_params or prior_kf_params())

    train_d, val_d, corpus_d = gather_drives(data_paths, synthetic, corpus_hours, seed, drives)
    tr = build_rows(train_d, profiles, prior, seed)
    va = subsample(build_rows(val_d, profiles, prior, seed + 7919), max_val_windows, seed)
    if len(tr) == 0 or len(va) == 0:
        raise DataError(
            None,
            f"too few windows (train {len(tr)}, validation {len(va)}): "
            "drives need >= 2 s of moving GPS",
        )
    t_data = time.perf_counter() - t_start
    val_groups = {d.name: group_of(d) for d in val_d}

    net = HybridNet(hidden=hidden, lstm_layers=lstm_layers)
    st = fit_stats(tr)
    net.set_stats(st["feature_mean"], st["feature_std"], st["prior_std"], st["res_std"])

    def tens(a: np.ndarray) -> torch.Tensor:
        return torch.tensor(a, dtype=torch.float32)

    Xtr, Ptr, Ttr = tens(tr.X), tens(tr.prior), tens(tr.target)
    Xva, Pva, Tva = tens(va.X), tens(va.prior), tens(va.target)
    hw_ = torch.ones(Ttr.shape[1], 1)
    hw_[0] = FUTURE_WEIGHT
    hw_ = hw_ / hw_.mean()
    feat_sign = torch.tensor([1.0, -1.0, 1.0, -1.0, -1.0, 1.0])
    vec_sign = torch.tensor([1.0, -1.0])

    def loss_fn(x: torch.Tensor, p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        y = net.forward_std(x, p)
        mu, lv = y[..., :2], y[..., 2:].clamp(-12.0, 12.0)
        z = t / net.res_std
        nll = 0.5 * (lv + (z - mu) ** 2 * torch.exp(-lv))
        return torch.mean(torch.exp(lv).detach() ** BETA * nll * hw_)

    def validate() -> tuple[float, float]:
        net.eval()
        tot, outs = 0.0, []
        with torch.no_grad():
            for i in range(0, len(va), 8192):
                sl = slice(i, i + 8192)
                tot += float(loss_fn(Xva[sl], Pva[sl], Tva[sl])) * Xva[sl].shape[0]
                outs.append(net(Xva[sl], Pva[sl])[:, 0, :2].numpy())
        fut = future_answers(va, np.concatenate(outs).astype(float))
        return tot / len(va), balanced_future_error(va, fut, val_groups)

    gen = torch.Generator().manual_seed(seed)

    def batch_loss(idx: torch.Tensor) -> torch.Tensor:
        xb, pb, tb = Xtr[idx], Ptr[idx], Ttr[idx]
        if mirror:
            flip = (torch.rand(idx.shape[0], generator=gen) < 0.5).float()[:, None, None]
            xb = xb * (1 - flip + flip * feat_sign)
            pb = pb * (1 - flip + flip * vec_sign)
            tb = tb * (1 - flip + flip * vec_sign)
        return loss_fn(xb, pb, tb)

    fit = fit_epochs(
        net,
        batch_loss,
        validate,
        torch.tensor(sample_weights(tr.label)),
        epochs=epochs,
        batch_size=batch_size,
        lr=lr,
        patience=patience,
        gen=gen,
        t_start=t_start,
        max_minutes=max_minutes,
        select="val_future_mean_m",
        include_initial=True,
        progress=progress,
        on_early_stop=on_early_stop,
    )
    history, stopped_by = fit.history, fit.stopped_by
    train_s = time.perf_counter() - t_start

    from posbench.predictors.hybrid.predictor import HybridPredictor  # noqa: F401 - loadability below
    from posbench.predictors.lstm.runtime import OnnxModel

    extra = {
        "trained": True,
        "training": {
            "epochs_max": epochs,
            "epochs_run": len(history) - 1,
            "best_epoch": fit.best_epoch,
            "stopped_by": stopped_by,
            "max_minutes": max_minutes,
            "seed": seed,
            "batch_size": batch_size,
            "lr": lr,
            "optimizer": "Adam",
            "scheduler": "ReduceLROnPlateau(factor 0.5, patience 2) on the validation future error",
            "early_stopping_patience": patience,
            "selection": "validation future-point error [m] balanced over cells (source "
            "group x GPS condition): the mean of the cells' hybrid/kf ratios times the kf's "
            "mean (development drives; epoch 0 = the untrained net = the kf alone); "
            "history key val_future_mean_m",
            "loss": f"beta-NLL (beta {BETA}) of the residual per horizon and axis, "
            f"in residual units; the 0.2 s horizon weighted {FUTURE_WEIGHT}x",
            "oversampling": "turn/roundabout weight n_other/n_turn clipped to [1, 5]",
            "augmentation": {
                "mirror": mirror,
                "gps_profiles": list(profiles),
                "time_jitter": "fix times drawn afresh per GPS draw",
            },
            "threads": threads,
            "data_seconds": round(t_data, 1),
            "seconds": round(train_s, 1),
            "history": history,
        },
        "data": {
            "paths": manifest(data_paths),
            "synthetic": {
                "drives": synthetic,
                "generator": "posbench.scenarios.synthetic.generate_drive",
                "generator_seeds": synthetic_seeds(synthetic, seed),
            },
            "corpus": corpus_card(corpus_d, corpus_hours, seed),
            "in_memory_drives": [d.name for d in (drives or [])],
            "train_drives": [d.name for d in train_d],
            "val_drives": [d.name for d in val_d],
            "split": "by route (predictors.lstm.training_data.split_by_route)",
            "train_windows": len(tr),
            "val_windows": len(va),
            "train_labels": {
                k: int(v) for k, v in zip(*np.unique(tr.label, return_counts=True), strict=True)
            },
        },
        "packages": package_versions(),
        "command": command,
    }
    info = save_model(net, out_dir, prior, **extra)
    onnx = OnnxModel(out_dir / "model.onnx")
    outs = onnx.session.run(
        None, {"features": va.X.astype(np.float32), "prior": va.prior.astype(np.float32)}
    )[0]
    corr = outs[:, :, :2].astype(float)
    shrink = fit_shrink(corr, va.target)
    info["gate"] = {
        "shrink": [round(float(a), 4) for a in shrink],
        **input_envelope(tr.X, tr.prior),
        "how": "shrink: least-squares factor per horizon on the validation rows (held-out "
        "drives), clipped to [0, 1]; feature_/prior_ min and max: the box of the training "
        "inputs (widened 10 % at run time); at run time also the drive's own evidence "
        "(predictors/hybrid/gate.py)",
    }
    groups = {d.name: group_of(d) for d in val_d}
    info["validation"] = evaluate(va, future_answers(va, corr[:, 0]), groups)
    info["validation_shrunk"] = evaluate(va, future_answers(va, corr[:, 0] * shrink[0]), groups)
    (out_dir / "model.json").write_text(json.dumps(info, indent=1) + "\n")
    if held_out is not None:
        t0 = time.perf_counter()
        info["held_out"] = held_out(out_dir, train_d, val_d, profiles)
        info["held_out"]["seconds"] = round(time.perf_counter() - t0, 1)
        (out_dir / "model.json").write_text(json.dumps(info, indent=1) + "\n")
    from posbench.predictors.model_card import write_model_card

    write_model_card(info, out_dir, "hybrid")
    return info
