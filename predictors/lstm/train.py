"""Train the paper's MLP-LSTM-MLP on drives and write ``model.onnx`` + ``model.json``.

:func:`run_training` is what ``bench train --data PATH... --out DIR [--epochs N] [--seed N]``
calls. Pipeline: load drives (``posbench.scenarios.load``), optional synthetic drives and hours of
the vehicle-dynamics corpus (:mod:`posbench.scenarios.corpus`) -> split by route (never by window)
-> windows (:mod:`posbench.predictors.lstm.windows`; drives with a truth stream are fed GPS degraded
from it under each of ``profiles``, ``gps_seeds`` draws each: fresh fix times from the
paper's interval distribution every draw, i.e. time jitter) -> feature statistics on the
training windows -> Adam + ReduceLROnPlateau + early stopping on the validation loss,
turn windows oversampled, every batch mirrored at random (left <-> right: dy, ay, yaw
negated in inputs and targets; exact in both frames) -> ONNX export (faster exporter kept)
-> validation future-point error [m] of the exported model and, on the same windows, of a
plain cubic extrapolation and constant velocity.

Loss (the paper's): MSE over all 8 x 6 outputs in the network's units (standardised;
for the ``"speed"`` form the displacement is a residual in units of its own scale, see
:mod:`posbench.predictors.lstm.model`) + 10 x MSE of the last output's x, y. Seeded and
deterministic (torch, numpy, the sampler's generator). A wall-clock budget
(``max_minutes``) ends training early if it is reached; the best epoch is kept.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, Self, TypeVar

import numpy as np

from posbench.predictors.lstm.features import FEATURES, FRAMES
from posbench.predictors.lstm.resample import DT, MIN_SPAN_S, N_STEPS
from posbench.predictors.lstm.training_data import (
    VAL_EVERY,
    VAL_OFFSET,
    build_windows,
    corpus_card,
    gather_drives,
    group_of,
    manifest,
    synthetic_seeds,
)
from posbench.predictors.lstm.windows import WindowSet, future_from_output
from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError

if TYPE_CHECKING:
    import torch

#: ``callback(epoch, n_epochs, train_loss, val_loss, val_future_mean_m)`` after each epoch
Progress = Callable[[int, int, float, float, float], None]
EarlyStop = Callable[[int, int, int], None]
FORMAT = "posbench-lstm"
TURN_LABELS = ("turn", "roundabout")


def mirror_signs(n: int, gen: torch.Generator, like: torch.Tensor) -> torch.Tensor:
    """Per-window sign vectors (n, 1, 6) for left-right mirroring: +1 everywhere, or -1 on
    dy, ay and yaw (features 1, 3, 4) for about half the windows (torch tensors)."""
    import torch

    flip = torch.rand(n, generator=gen) < 0.5
    sg = torch.ones(n, 1, 6, dtype=like.dtype)
    sg[flip, :, 1] = -1.0
    sg[flip, :, 3] = -1.0
    sg[flip, :, 4] = -1.0
    return sg


class Rows(Protocol):
    """A set of training rows: its length and the rows at given indices."""

    def __len__(self) -> int: ...

    def take(self, idx: np.ndarray) -> Self: ...


RowsT = TypeVar("RowsT", bound=Rows)


def subsample(ws: RowsT, n_max: int, seed: int) -> RowsT:
    """At most ``n_max`` windows, drawn without replacement (seeded), order kept (any set
    of rows with ``len`` and ``take``: also the hybrid's HybridWindows)."""
    if len(ws) <= n_max:
        return ws
    idx = np.sort(np.random.default_rng(seed).choice(len(ws), n_max, replace=False))
    return ws.take(idx)


def sample_weights(labels: np.ndarray, turn_boost_max: float = 5.0) -> np.ndarray:
    """Per-window weights: turn/roundabout windows up-weighted to balance them with the rest
    (factor n_other / n_turn, between 1 and ``turn_boost_max``)."""
    turn = np.isin(labels, TURN_LABELS)
    w = np.ones(labels.size)
    if turn.any() and (~turn).any():
        w[turn] = float(np.clip((~turn).sum() / turn.sum(), 1.0, turn_boost_max))
    return w


# --------------------------------------------------------------------------- metrics
def error_stats(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    e = np.linalg.norm(pred - truth, axis=1)
    if e.size == 0:
        return {"n": 0}
    return {
        "n": int(e.size),
        "mean_m": float(e.mean()),
        "p50_m": float(np.median(e)),
        "p95_m": float(np.percentile(e, 95)),
    }


def evaluate(ws: WindowSet, lstm_future: np.ndarray, groups: dict[str, str]) -> dict:
    """Future-point error [m] of the network, plain cubic and constant velocity, overall,
    per label, per source group (``groups``: drive name -> group) and per drive."""
    out = {
        "all": {
            k: error_stats(p, ws.truth_future)
            for k, p in (("lstm", lstm_future), ("cubic", ws.cubic_pred), ("cv", ws.cv_pred))
        }
    }
    for lab in sorted(set(ws.label.tolist())):
        m = ws.label == lab
        out[f"label:{lab}"] = {
            k: error_stats(p[m], ws.truth_future[m])
            for k, p in (("lstm", lstm_future), ("cubic", ws.cubic_pred), ("cv", ws.cv_pred))
        }
    for g in sorted(set(groups.values())):
        m = np.array([groups.get(d) == g for d in ws.drive], dtype=bool)
        out[f"group:{g}"] = {
            k: error_stats(p[m], ws.truth_future[m])
            for k, p in (("lstm", lstm_future), ("cubic", ws.cubic_pred), ("cv", ws.cv_pred))
        }
    for name in sorted(set(ws.drive.tolist())):
        m = ws.drive == name
        out[f"drive:{name}"] = {
            k: error_stats(p[m], ws.truth_future[m])
            for k, p in (("lstm", lstm_future), ("cubic", ws.cubic_pred), ("cv", ws.cv_pred))
        }
    return out


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("numpy", "torch", "onnx", "onnxruntime", "scipy", "posbench"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


# --------------------------------------------------------------------------- training
def run_training(
    data_paths: Sequence[str | Path],
    out_dir: Path,
    epochs: int = 40,
    seed: int = 0,
    synthetic: int = 0,
    progress: Progress | None = None,
    command: str | None = None,
    drives: Sequence[Drive] | None = None,
    hidden: int = 64,
    lstm_layers: int = 1,
    enc_layers: int = 1,
    batch_size: int = 512,
    lr: float = 2e-3,
    patience: int = 6,
    gps_seeds: int = 1,
    frame: str = "heading",
    threads: int = 2,
    timing_calls: int = 2000,
    on_early_stop: EarlyStop | None = None,
    form: str = "speed",
    corpus_hours: float = 0.0,
    profiles: Sequence[str] = ("none", "rtk"),
    mirror: bool = True,
    max_minutes: float = 30.0,
    max_val_windows: int = 60_000,
    fix_offset: bool = True,
) -> dict:
    """Train, export and describe a model. Returns the dict written to ``model.json``.

    Args:
        data_paths: files/folders for ``posbench.scenarios.load`` (aslan pickles, comma2k19, ...).
        out_dir: where ``model.onnx`` and ``model.json`` go (created).
        epochs: maximum epochs (early stopping or ``max_minutes`` may end sooner).
        seed: seeds torch, numpy, the sampler and the synthetic generators.
        synthetic: number of drives of the benchmark's synthetic generator to add.
        progress: called after each epoch (:data:`Progress`).
        command: the exact command line, recorded in model.json.
        drives: extra in-memory drives (tests).
        hidden, lstm_layers, enc_layers: network sizes.
        gps_seeds: GPS draws per profile for drives with truth (validation uses one).
        frame: feature frame, ``"heading"`` or ``"world"``.
        on_early_stop: ``callback(epoch, best_epoch, patience)`` when early stopping ends
            training after ``epoch``: the validation loss has not improved for
            ``epoch - best_epoch`` (= ``patience``) epochs; the best epoch's weights are kept.
        form: ``"speed"`` (speed-invariant input, residual output) or ``"paper"``
            (:mod:`posbench.predictors.lstm.model`).
        corpus_hours: hours of the vehicle-dynamics corpus to add
            (:mod:`posbench.scenarios.corpus`).
        profiles: GPS profiles drawn from the truth of drives that have one.
        mirror: mirror every batch left-right at random (augmentation).
        max_minutes: wall-clock budget of the epochs [min]; the best epoch so far is kept.
        max_val_windows: validation windows kept (a seeded subsample beyond).
        fix_offset: row 0 of the input holds the newest fix minus the newest grid point
            (:mod:`posbench.predictors.lstm.features`).
    """
    import torch

    from posbench.predictors.lstm.export import export_best
    from posbench.predictors.lstm.model import LstmNet
    from posbench.predictors.lstm.runtime import OnnxModel
    from posbench.predictors.training_loop import fit_epochs

    if frame not in FRAMES:
        raise ValueError(f"unknown frame {frame!r}")
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    torch.manual_seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - seeds any legacy-RNG user as well
    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(threads)

    train_d, val_d, corpus_d = gather_drives(data_paths, synthetic, corpus_hours, seed, drives)
    tr = build_windows(train_d, gps_seeds, seed, frame, profiles, fix_offset)
    va = subsample(
        build_windows(val_d, 1, seed + 7919, frame, profiles, fix_offset), max_val_windows, seed
    )
    if len(tr) == 0 or len(va) == 0:
        raise DataError(
            None,
            f"too few windows (train {len(tr)}, validation {len(va)}): "
            "drives need >= 2 s of moving GPS",
        )
    t_data = time.perf_counter() - t_start
    flat = tr.X.reshape(-1, tr.X.shape[-1])
    mean = flat.mean(axis=0)
    std = np.maximum(flat.std(axis=0), 1e-3)

    net = LstmNet(hidden, lstm_layers, enc_layers, form=form, fix_offset=fix_offset)
    net.set_stats(torch.tensor(mean), torch.tensor(std))
    Xtr, Ytr = torch.tensor(tr.X, dtype=torch.float32), torch.tensor(tr.Y, dtype=torch.float32)
    Xva, Yva = torch.tensor(va.X, dtype=torch.float32), torch.tensor(va.Y, dtype=torch.float32)
    if form == "speed":
        with torch.no_grad():
            log_s = torch.log(LstmNet.speed_scale(Xtr)).flatten()
            res = (Ytr[:, :, :2] - LstmNet.base_step(Xtr)).reshape(-1, 2)
            net.set_speed_stats(
                float(log_s.mean()), float(log_s.std().clamp_min(1e-3)), res.std(0).clamp_min(1e-3)
            )

    def loss_fn(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        pred, tgt = net.core(x), net.target_std(x, y)
        return torch.mean((pred - tgt) ** 2) + 10.0 * torch.mean(
            (pred[:, -1, :2] - tgt[:, -1, :2]) ** 2
        )

    def validate() -> tuple[float, float]:
        """Validation loss and future-point mean error [m] (no mirroring)."""
        net.eval()
        tot, outs = 0.0, []
        with torch.no_grad():
            for i in range(0, len(va), 8192):
                xb, yb = Xva[i : i + 8192], Yva[i : i + 8192]
                tot += float(loss_fn(xb, yb)) * xb.shape[0]
                outs.append(net(xb)[:, -1, :2].numpy())
        fut = future_from_output(va, np.concatenate(outs).astype(float), frame)
        return tot / len(va), float(np.linalg.norm(fut - va.truth_future, axis=1).mean())

    gen = torch.Generator().manual_seed(seed)

    def batch_loss(idx: torch.Tensor) -> torch.Tensor:
        xb, yb = Xtr[idx], Ytr[idx]
        if mirror:
            sg = mirror_signs(idx.shape[0], gen, xb)
            xb, yb = xb * sg, yb * sg
        return loss_fn(xb, yb)

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
        select="val_loss",
        progress=progress,
        on_early_stop=on_early_stop,
    )
    history, stopped_by = fit.history, fit.stopped_by
    train_s = time.perf_counter() - t_start

    onnx_path = out_dir / "model.onnx"
    export_report = export_best(net, onnx_path, n_calls=timing_calls)
    core = write_core_if_any(onnx_path) if form == "speed" else None
    out = OnnxModel(onnx_path).run_batch(va.X.astype(np.float32))
    lstm_future = future_from_output(va, out[:, :2].astype(float), frame)
    metrics = evaluate(va, lstm_future, {d.name: group_of(d) for d in val_d})

    forms = {
        "paper": "every feature standardised (training mean/std), displacement output "
        "standardised likewise",
        "speed": "speed-invariant in-graph: (dx, dy) / s with s = mean grid step + 0.02 m, "
        "log s as a 7th encoder channel; displacement output = previous grid step "
        "+ res_std x net (a residual); aux features standardised",
    }
    info = {
        "format": FORMAT,
        "version": 2 if form == "speed" else 1,
        "frame": frame,
        "form": form,
        "fix_offset": fix_offset,
        "features": list(FEATURES),
        "n_steps": N_STEPS,
        "dt_s": DT,
        "min_span_s": MIN_SPAN_S,
        "input": "features",
        "output": "future",
        "input_shape": ["batch", N_STEPS, len(FEATURES)],
        "output_shape": ["batch", len(FEATURES)],
        "normalisation": f"in-graph (raw features in, raw next-sample features out); {forms[form]}",
        "feature_mean": mean.tolist(),
        "feature_std": std.tolist(),
        "speed_stats": (
            {
                "log_s_mean": float(net.log_s_mean),
                "log_s_std": float(net.log_s_std),
                "res_std_m": net.res_std.tolist(),
            }
            if form == "speed"
            else None
        ),
        "architecture": {
            "encoder": f"{enc_layers} x (Linear -> LeakyReLU(0.1)), width {hidden}",
            "lstm": {"hidden": hidden, "layers": lstm_layers},
            "decoder": f"Linear({hidden},{hidden}) -> LeakyReLU(0.1) -> Linear({hidden},6)",
            "parameters": int(sum(p.numel() for p in net.parameters())),
        },
        "training": {
            "epochs_max": epochs,
            "epochs_run": len(history),
            "best_epoch": fit.best_epoch,
            "stopped_by": stopped_by,
            "max_minutes": max_minutes,
            "seed": seed,
            "batch_size": batch_size,
            "lr": lr,
            "optimizer": "Adam",
            "scheduler": "ReduceLROnPlateau(factor 0.5, patience 2)",
            "early_stopping_patience": patience,
            "loss": "MSE(all 8x6 outputs in network units) + 10 x MSE(last output x, y)",
            "oversampling": "turn/roundabout weight n_other/n_turn clipped to [1, 5], "
            "windows drawn with replacement",
            "augmentation": {
                "mirror": mirror,
                "gps_profiles": list(profiles),
                "gps_draws_per_profile": gps_seeds,
                "time_jitter": "fix times drawn afresh per GPS draw "
                "(the paper's interval distribution)",
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
            "split": f"by route: per source group in name order, every {VAL_EVERY}th drive "
            f"from index {VAL_OFFSET} held out",
            "train_windows": len(tr),
            "val_windows": len(va),
            "train_labels": {
                k: int(v) for k, v in zip(*np.unique(tr.label, return_counts=True), strict=True)
            },
        },
        "validation": metrics,
        "export": export_report,
        "core": core,
        "packages": package_versions(),
        "command": command,
    }
    (out_dir / "model.json").write_text(json.dumps(info, indent=1))
    from posbench.predictors.model_card import write_model_card

    write_model_card(info, out_dir, "lstm")
    return info


def write_core_if_any(onnx_path: Path) -> dict | None:
    """The fused step's core graph beside a speed-form model (``model.json["core"]``), or
    None where the export's layout has none (:mod:`posbench.predictors.lstm.core_graph`)."""
    from posbench.predictors.lstm.core_graph import NoCoreGraph, write_core

    try:
        return write_core(onnx_path)
    except NoCoreGraph:
        return None
