"""`bench train`: train the LSTM predictor."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from bench.commands.common import (
    DataError,
    DataOpt,
    UsageError,
    command_line,
    console,
    fail,
)
from bench.options import check_at_least, check_data_paths, check_out_dir


def train(
    data: DataOpt = None,
    out: Annotated[Path, typer.Option("--out", "-o", metavar="DIR",
                                      help="Folder for model.onnx and model.json.")
                   ] = Path("model-out"),
    epochs: Annotated[int, typer.Option(help="Maximum epochs (early stopping may end sooner).")] = 40,
    seed: Annotated[int, typer.Option(help="Seed for split, sampling and initialisation.")] = 0,
    synthetic: Annotated[int, typer.Option(help="Number of synthetic drives to add.")] = 0,
) -> None:
    """Train the LSTM predictor (needs the `train` extra: pip install 'posbench[train]')."""
    try:  # every option is checked before PyTorch is imported or a drive loaded
        check_at_least(epochs, 1, "--epochs")
        check_at_least(seed, 0, "--seed")
        check_at_least(synthetic, 0, "--synthetic")
        if not data and synthetic == 0:
            raise UsageError("no training drives: give --data PATH... or --synthetic N")
        check_data_paths(data)
        check_out_dir(out)
    except UsageError as e:
        raise fail(str(e)) from None
    try:
        import torch  # noqa: F401
    except ImportError:
        raise fail("bench train needs PyTorch: pip install 'posbench[train]'") from None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from predictors.lstm.train import run_training

    command = command_line()
    try:
        with Progress(TextColumn("[bold]training"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), TextColumn("{task.fields[loss]}"), console=console) as prog:
            task = prog.add_task("train", total=epochs, loss="")

            def progress(epoch: int, n_epochs: int, train_loss: float, val_loss: float) -> None:
                prog.update(task, completed=epoch, total=n_epochs,
                            loss=f"train {train_loss:.4f} val {val_loss:.4f}")

            info = run_training([str(p) for p in data or []], out, epochs=epochs, seed=seed,
                                synthetic=synthetic, progress=progress, command=command)
    except (DataError, UsageError) as e:
        raise fail(str(e)) from None
    console.print(json.dumps(info.get("validation", info), indent=2, default=float))
    console.print(f"wrote {out / 'model.onnx'} and {out / 'model.json'}")
