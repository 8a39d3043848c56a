"""The epoch loop both learned predictors train with (torch; training only, imported lazily).

One job: draw weighted batches, step Adam, validate after each epoch, keep the best weights,
stop early (``patience`` epochs without improvement) or on a wall-clock budget, and report
progress. What a batch's loss is and how validation is scored stay with the caller
(:mod:`posbench.predictors.lstm.train`, :mod:`posbench.predictors.hybrid.train`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch


@dataclass
class FitResult:
    """What :func:`fit_epochs` did: per-epoch records, the epoch whose weights the net now
    holds (0 = the initial weights) and why it stopped."""

    history: list[dict] = field(default_factory=list)
    best_epoch: int = 0
    stopped_by: str = "epochs"


def fit_epochs(
    net: torch.nn.Module,
    batch_loss: Callable[[torch.Tensor], torch.Tensor],
    validate: Callable[[], tuple[float, float]],
    weights: torch.Tensor,
    *,
    epochs: int,
    batch_size: int,
    lr: float,
    patience: int,
    gen: torch.Generator,
    t_start: float,
    max_minutes: float,
    select: str = "val_loss",
    include_initial: bool = False,
    progress: Callable[[int, int, float, float, float], None] | None = None,
    on_early_stop: Callable[[int, int, int], None] | None = None,
) -> FitResult:
    """Train ``net`` in place and leave it holding its best weights (eval mode).

    Args:
        net: the torch module.
        batch_loss: ``batch_loss(idx)`` -> the loss tensor of the training rows ``idx``.
        validate: ``() -> (val_loss, val_future_mean_m)`` on the validation rows.
        weights: per-row sampling weights (torch tensor); each epoch draws ``len(weights)``
            rows with replacement.
        select: ``"val_loss"`` or ``"val_future_mean_m"``: what the scheduler, the choice of
            the best epoch and early stopping follow.
        include_initial: validate the initial weights as epoch 0 and let them win.
        progress: ``(epoch, epochs, train_loss, val_loss, val_m)`` after each epoch.
        on_early_stop: ``(epoch, best_epoch, patience)`` when early stopping ends training.
    """
    import torch

    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=2)
    res = FitResult()
    best: tuple[float, dict | None] = (float("inf"), None)
    if include_initial:
        vl, vm = validate()
        res.history.append({"epoch": 0, "val_loss": vl, "val_future_mean_m": vm})
        best = (res.history[0][select], {k: v.clone() for k, v in net.state_dict().items()})
    n = int(weights.shape[0])
    for epoch in range(1, epochs + 1):
        net.train()
        tot, cnt = 0.0, 0
        order = torch.multinomial(weights, n, replacement=True, generator=gen)
        for i in range(0, n, batch_size):
            idx = order[i : i + batch_size]
            opt.zero_grad()
            loss = batch_loss(idx)
            loss.backward()
            opt.step()
            tot += loss.item() * idx.shape[0]
            cnt += idx.shape[0]
        vl, vm = validate()
        rec = {
            "epoch": epoch,
            "train_loss": tot / max(cnt, 1),
            "val_loss": vl,
            "val_future_mean_m": vm,
            "lr": opt.param_groups[0]["lr"],
            "elapsed_s": round(time.perf_counter() - t_start, 1),
        }
        res.history.append(rec)
        sched.step(rec[select])
        if progress is not None:
            progress(epoch, epochs, rec["train_loss"], vl, vm)
        if rec[select] < best[0] - 1e-6:
            best = (rec[select], {k: v.clone() for k, v in net.state_dict().items()})
            res.best_epoch = epoch
        elif epoch - res.best_epoch >= patience:
            res.stopped_by = "early stopping"
            if on_early_stop is not None:
                on_early_stop(epoch, res.best_epoch, patience)
            break
        if time.perf_counter() - t_start > max_minutes * 60.0:
            res.stopped_by = f"time budget ({max_minutes:g} min)"
            break
    if best[1] is not None:
        net.load_state_dict(best[1])
    net.eval()
    return res
