"""``bench train``: train the ``lstm`` or the ``hybrid`` predictor's network."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from posbench.checks import check_at_least, check_data_paths, check_out_dir
from posbench.cli.options import (
    ConfigOpt,
    DataOpt,
    QuietOpt,
    VerboseOpt,
    WorkersOpt,
    command_line,
    renamed,
)
from posbench.cli.terminal import QUIET, console, print_table, say, verbosity
from posbench.errors import UsageError

#: the networks `bench train` trains (``--network``)
NETWORKS = ("lstm", "hybrid")
#: GPS profiles drawn from the truth of drives that have one, per network (``--profiles``)
DEFAULT_PROFILES = {"lstm": "none,rtk", "hybrid": "none,rtk,consumer"}


def train(
    data: DataOpt = None,
    network: Annotated[
        str,
        typer.Option(
            "--network",
            "-n",
            metavar="NAME",
            help="Which network: lstm (the paper's MLP-LSTM-MLP) or hybrid (kf prior + learned "
            "residual).",
        ),
    ] = "lstm",
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="DIR",
            help="Folder for model.onnx, model.json, MODEL_CARD.md and (lstm) model.core.npz.",
        ),
    ] = Path("model-out"),
    epochs: Annotated[
        int, typer.Option(help="Maximum epochs (early stopping may end sooner).")
    ] = 40,
    seed: Annotated[int, typer.Option(help="Seed for split, sampling and initialisation.")] = 0,
    synthetic: Annotated[int, typer.Option(help="Number of synthetic drives to add.")] = 0,
    corpus_hours: Annotated[
        float,
        typer.Option(
            "--corpus-hours",
            metavar="H",
            help="Hours of the vehicle-dynamics corpus (0-40 m/s, urban/rural/highway; "
            "scenarios.corpus) to add, e.g. 20.",
        ),
    ] = 0.0,
    profiles: Annotated[
        str | None,
        typer.Option(
            metavar="P,P",
            help="GPS profiles drawn from the truth of drives that have one "
            "(none, rtk, consumer). Default: none,rtk for lstm, "
            "none,rtk,consumer for hybrid.",
        ),
    ] = None,
    hidden: Annotated[int, typer.Option(help="Width of encoder, LSTM and decoder.")] = 64,
    max_minutes: Annotated[
        float,
        typer.Option(
            "--max-minutes",
            metavar="MIN",
            help="Wall-clock budget for the epochs; the best epoch so far is kept.",
        ),
    ] = 30.0,
    held_out: Annotated[
        bool,
        typer.Option(
            "--held-out/--no-held-out",
            help="hybrid: once written, replay the model against its prior kf (and the kf "
            "tuned by gradient on the training drives) on the held-out drives, with paired "
            "95 % intervals, for its model card.",
        ),
    ] = True,
    workers: WorkersOpt = 2,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    old_model: Annotated[str | None, typer.Option("--model", "-m", hidden=True)] = None,
) -> None:
    """Train a predictor's network on drives and write model.onnx + model.json (its model card).

    Needs the `train` extra: pip install 'posbench-harness[train]'. KITTI is refused (one
    error line): it is evaluation-only data. Example (the bundled models):
    bench train --data ../shared/data/aslan --data ../shared/data/comma2k19 --corpus-hours 20
    --out DIR
    """
    from posbench.scenarios.degrade import GPS_PROFILES

    if old_model is not None:
        renamed("--model", "--network", "bench train")
        network = old_model
    # every option is checked before PyTorch is imported or a drive loaded
    if network not in NETWORKS:
        raise UsageError(f"--network {network!r}: choose one of {', '.join(NETWORKS)}")
    check_at_least(epochs, 1, "--epochs")
    check_at_least(seed, 0, "--seed")
    check_at_least(synthetic, 0, "--synthetic")
    check_at_least(hidden, 4, "--hidden")
    check_at_least(workers, 1, "--workers")
    if not corpus_hours >= 0:
        raise UsageError(f"--corpus-hours must be >= 0, got {corpus_hours}")
    if not max_minutes > 0:
        raise UsageError(f"--max-minutes must be > 0, got {max_minutes}")
    prof = [p.strip() for p in (profiles or DEFAULT_PROFILES[network]).split(",") if p.strip()]
    bad = [p for p in prof if p not in GPS_PROFILES]
    if bad or not prof:
        raise UsageError(f"--profiles {profiles!r}: choose from {', '.join(GPS_PROFILES)}")
    if not data and synthetic == 0 and corpus_hours == 0:
        raise UsageError(
            "no training drives: give --data PATH..., --synthetic N or --corpus-hours H"
        )
    check_data_paths(data)
    check_out_dir(out)
    try:
        import torch  # noqa: F401
    except ImportError:
        raise UsageError(
            "bench train needs PyTorch: pip install 'posbench-harness[train]'"
        ) from None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    # the two networks' trainers take the same keywords used below, and differ in others
    run_training: Callable[..., dict[str, Any]]
    if network == "hybrid":
        from posbench.predictors.hybrid.train import run_training
    else:
        from posbench.predictors.lstm.train import run_training

    command = command_line()
    stopped: list[tuple[int, int, int]] = []
    with Progress(
        TextColumn(f"[bold]training {network}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[loss]}"),
        console=console,
        disable=verbosity() <= QUIET,
    ) as prog:
        task = prog.add_task("train", total=epochs, loss="preparing windows")

        def progress(
            epoch: int,
            n_epochs: int,
            train_loss: float,
            val_loss: float,
            val_m: float = float("nan"),
        ) -> None:
            prog.update(
                task,
                completed=epoch,
                total=n_epochs,
                loss=f"train {train_loss:.4f} val {val_loss:.4f} val future {val_m:.4f} m",
            )

        def early_stop(epoch: int, best_epoch: int, patience: int) -> None:
            stopped.append((epoch, best_epoch, patience))
            say(early_stop_message(epoch, best_epoch))

        info = run_training(
            [str(p) for p in data or []],
            out,
            epochs=epochs,
            seed=seed,
            synthetic=synthetic,
            progress=progress,
            command=command,
            on_early_stop=early_stop,
            corpus_hours=corpus_hours,
            profiles=tuple(prof),
            hidden=hidden,
            max_minutes=max_minutes,
            **(
                {"held_out": held_out_comparison(workers, seed, console)}
                if network == "hybrid" and held_out
                else {}
            ),
        )
    if verbosity() > QUIET:
        print_summary(console, info, out, stopped[0] if stopped else None)


def held_out_comparison(workers: int, seed: int, console: Console) -> Any:
    """The hybrid's held-out comparison
    (:func:`posbench.predictor_tools.held_out.hybrid_held_out`) as
    :data:`posbench.predictors.hybrid.train.HeldOut`, its steps said on ``console``."""

    def tell(text: str) -> None:
        if verbosity() > QUIET:
            console.print(text)

    def compare(model_dir: Path, train_d: Any, val_d: Any, profiles: Any) -> dict[str, Any]:
        from posbench.predictor_tools.held_out import hybrid_held_out

        return hybrid_held_out(
            model_dir, train_d, val_d, profiles, workers=workers, seed=seed, tell=tell
        )

    return compare


def early_stop_message(epoch: int, best_epoch: int) -> str:
    """The line announcing that early stopping ended training after ``epoch``."""
    return (
        f"early stop at epoch {epoch}: validation loss did not improve for "
        f"{_plural(epoch - best_epoch, 'epoch')} (best epoch {best_epoch})"
    )


def _sources(names: list[str], info: dict[str, Any]) -> str:
    """Where a split's drives come from: --data, the synthetic generator, in-memory drives."""
    data = info["data"]
    seeds = {f"-s{s}" for s in data["synthetic"]["generator_seeds"]}
    in_memory = set(data["in_memory_drives"])
    n_mem = sum(n in in_memory for n in names)
    n_syn = sum(
        n not in in_memory
        and n.startswith("synthetic-")
        and "-s" in n
        and n[n.rindex("-s") :] in seeds
        for n in names
    )
    n_corpus = sum(n not in in_memory and n.startswith("corpus-") for n in names)
    parts = [
        (len(names) - n_mem - n_syn - n_corpus, "--data"),
        (n_syn, "synthetic"),
        (n_corpus, "corpus"),
        (n_mem, "in memory"),
    ]
    return ", ".join(f"{k} {what}" for k, what in parts if k)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def print_summary(
    console: Console, info: dict[str, Any], out: Path, early_stop: tuple[int, int, int] | None
) -> None:
    """The end of ``bench train``: data, epochs and early stopping, validation error [m] of the
    model beside the cubic-extrapolation and constant-velocity baselines, export timing [us]
    and where model.onnx and its model card model.json are. ``info`` is ``run_training``'s
    result; ``early_stop`` is ``(epoch, best_epoch, patience)`` when early stopping fired."""
    data, tr = info["data"], info["training"]
    print_table(
        console,
        ("split", "sources", "drives", "windows"),
        [
            [
                split,
                _sources(data[f"{key}_drives"], info),
                str(len(data[f"{key}_drives"])),
                str(data[f"{key}_windows"]),
            ]
            for split, key in (("train", "train"), ("validation", "val"))
        ],
        title="training data",
        left_columns=2,
    )
    paths = [p["path"] for p in data["paths"]]
    if paths:
        console.print("--data: " + ", ".join(paths), markup=False, highlight=False, soft_wrap=True)

    patience = tr["early_stopping_patience"]
    stop = f"after epoch {early_stop[0]}" if early_stop else "no"
    if not early_stop and str(tr.get("stopped_by", "")).startswith("time budget"):
        stop = f"no; stopped by the {tr['stopped_by']}"
    export = info.get("export") or {}
    chosen = export.get("chosen")
    p50 = (export.get("candidates") or {}).get(chosen, {}).get("p50_us")
    rows = [
        ["epochs run", f"{tr['epochs_run']} of {tr['epochs_max']}"],
        ["early stopping", f"{stop} (patience {patience})"],
        ["best epoch", f"{tr['best_epoch']} (its weights exported)"],
        ["training time", f"{tr['seconds']:.1f} s"],
    ]
    if chosen:
        rows.append(["ONNX exporter", chosen])
    if p50 is not None:
        rows.append(["inference p50", f"{p50:.1f} us per window"])
    print_table(console, ("training", ""), rows, left_columns=2)

    val = info["validation"]
    groups = [k for k in val if k.startswith("group:")]
    subsets = ["all", *groups] if len(groups) > 1 else ["all"]
    labels = {
        "lstm": "lstm (this model)",
        "hybrid": "hybrid (this model)",
        "kf": "kf (its prior)",
        "cubic": "cubic extrapolation",
        "cv": "constant velocity",
    }
    methods = [(k, labels.get(k, k)) for k in val["all"]]
    by_source = len(subsets) > 1  # a source column only when the windows come from several
    rows = []
    for sub in subsets:
        for key, label in methods:
            e = val[sub][key]
            rows.append(
                [
                    *([sub.removeprefix("group:")] if by_source else []),
                    label,
                    str(e["n"]),
                    *(f"{e[k]:.3f}" if e["n"] else "-" for k in ("mean_m", "p50_m", "p95_m")),
                ]
            )
    header = ("predictor", "windows", "mean [m]", "p50 [m]", "p95 [m]")
    print_table(
        console,
        ("source", *header) if by_source else header,
        rows,
        title="validation: future-point error",
        key_columns=1 + by_source,
        left_columns=1 + by_source,
    )
    conds = (info.get("held_out") or {}).get("conditions") or {}
    if conds:
        rows = []
        for cond, c in conds.items():
            for kind in ("future", "now"):
                r = c.get(kind) or {}
                for key, d in r.items():
                    if not key.startswith("hybrid_minus_"):
                        continue
                    other = key.removeprefix("hybrid_minus_")
                    rows.append(
                        [
                            cond,
                            kind,
                            other,
                            str(c["drives"]),
                            f"{r[f'{other}_mean_m']:.4f}",
                            f"{r['hybrid_mean_m']:.4f}",
                            f"{d['diff']:+.4f} ({d['lo']:+.4f}, {d['hi']:+.4f})",
                        ]
                    )
        print_table(
            console,
            ("GPS", "query", "vs", "drives", "its mean [m]", "hybrid [m]", "diff [m] (95 % CI)"),
            rows,
            title="held out, as run: hybrid minus its prior",
            key_columns=3,
            left_columns=3,
        )
    core = (info.get("core") or {}).get("file")
    for what, name in (
        ("model", "model.onnx"),
        ("model card", "model.json"),
        ("model card (text)", "MODEL_CARD.md"),
        *((("core weights", core),) if core else ()),
    ):
        console.print(f"{what}: {out / name}", markup=False, highlight=False, soft_wrap=True)
