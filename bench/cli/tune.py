"""``bench tune``: grid-search a filter's noise on development drives (or fit the kf's by
gradient descent, ``--method gradient``), then calibrate its covariance
(:mod:`posbench.predictor_tools.tuning`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from posbench.checks import check_at_least, check_choice, check_data_paths
from posbench.cli.options import ConfigOpt, DataOpt, QuietOpt, VerboseOpt, WorkersOpt, command_line
from posbench.cli.terminal import reporter, say, warn
from posbench.errors import UsageError

if TYPE_CHECKING:
    from collections.abc import Sequence

    from posbench.scenarios.drive import Drive

#: how ``bench tune`` searches the noise
METHODS = ("grid", "gradient")


def tune(
    predictor: Annotated[
        str,
        typer.Argument(
            metavar="PREDICTOR",
            help="Predictor to tune: kf, ekf (noise grid, then calibration) or "
            "cv (calibration only).",
        ),
    ],
    gps_profile: Annotated[
        str,
        typer.Option(
            metavar="PROFILE",
            help="GPS condition to tune for: none, rtk, consumer (fixes drawn from the truth of "
            "--data, or of synthetic development drives, seeds 1000+) or native (the "
            "recordings' own fixes; give --data).",
        ),
    ] = "rtk",
    data: DataOpt = None,
    drives: Annotated[
        int,
        typer.Option(
            metavar="N", help="Synthetic development drives per route type (seeds 1000+)."
        ),
    ] = 1,
    calibrate_only: Annotated[
        bool,
        typer.Option(
            "--calibrate-only",
            help="Keep the noise parameters of the tuning in force for this profile (the --out "
            "file's where it holds them, else the built-in ones) and fit only cov_scale (no "
            "position changes).",
        ),
    ] = False,
    method: Annotated[
        str,
        typer.Option(
            metavar="METHOD",
            help="grid: search a grid of noise values, replaying the drives per trial (kf, "
            "ekf). gradient (kf only; needs the train extra): fit the kf's jerk density, fix "
            "noise and IMU noise by gradient descent on the 0.2 s prediction's beta-NLL "
            "(OKF), one differentiable filter over all drives at once.",
        ),
    ] = "grid",
    iterations: Annotated[
        int,
        typer.Option(
            metavar="N", help="--method gradient: Adam steps over all drives (full batch)."
        ),
    ] = 100,
    lr: Annotated[
        float,
        typer.Option(
            metavar="RATE",
            help="--method gradient: Adam's learning rate on the log-noise (0.1: ~10 % per step).",
        ),
    ] = 0.1,
    holdout: Annotated[
        float,
        typer.Option(
            metavar="FRACTION",
            help="--method gradient: hold out this fraction of the drives' 10 s segments, keep "
            "the step with the best held-out NLL and stop 20 steps after it (0: run all "
            "--iterations on all segments).",
        ),
    ] = 0.0,
    slow_error: Annotated[
        bool | None,
        typer.Option(
            "--slow-error/--no-slow-error",
            help="--method gradient: fit the receiver's slow error too (a covariance added to "
            "the predictions against the truth, never weighing a fix): for receivers whose "
            "error wanders over minutes. Default: on for consumer, off otherwise.",
        ),
    ] = None,
    workers: WorkersOpt = 2,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="FILE",
            help="The tuning file to write (merged into if it exists); use it with `bench run "
            "--tuning FILE`. The package's built-in tuning is never written.",
        ),
    ] = Path("tuning.json"),
    save: Annotated[
        bool, typer.Option(help="Write the result to --out (--no-save: print it only).")
    ] = True,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """Grid-search a filter's noise parameters on development drives (never evaluation drives),
    then calibrate its covariance.

    The grid minimises mean future + mean now error. With the winner, the same drives are
    replayed once and cov_scale is set so that 95 % of the 95 % ellipses cover the truth
    (it changes no position). Both go to the --out file under the GPS profile, with the
    names of the drives used: `bench run --tuning FILE` then marks those drives like a
    learned model's training drives, and scores the others as held out.

    --method gradient (kf only) fits the kf's noise instead, as OKF does (Greenberg et al.,
    NeurIPS 2023): a differentiable copy of its linear filter (fixes, IMU acceleration,
    wheel speed) runs over all drives at once and Adam fits the jerk density, the fix noise
    and the IMU noise to the beta-NLL of the position 0.2 s after each fix (the hybrid
    network's loss); the NLL makes their scale identifiable, not only their ratios. They
    become jerk_psd (a bank of one aided and one fixes-only filter), gps_sigma or
    gps_sigma_scale and accel_sigma; the full matrices and the loss go to the entry's
    "fit". About a second per step for 4 drives of 80 s.

    Examples: bench tune kf --data my-dev-drives/ --gps-profile native --out my-tuning.json;
    bench tune ekf --gps-profile rtk --calibrate-only --drives 3 --out my-tuning.json;
    bench tune kf --method gradient --gps-profile rtk --out my-tuning.json
    """
    from itertools import product

    from posbench.config import GPS_CONDITIONS
    from posbench.pipeline.drives import load_drives
    from posbench.predictor_tools.tuning import (
        GRIDS,
        calibrate,
        grid_for,
        grid_search,
        save_tuned,
        tuning_note,
    )
    from posbench.predictors.registry import PredictorError, tuned_params

    check_choice(method, METHODS, "--method")
    if predictor not in GRIDS:
        raise UsageError(f"no tuning grid for {predictor!r}; tunable: {', '.join(GRIDS)}")
    if method == "gradient":
        check_gradient(predictor, calibrate_only, iterations, lr, holdout)
    check_choice(gps_profile, GPS_CONDITIONS, "--gps-profile")
    check_at_least(drives, 1, "--drives")
    check_at_least(workers, 1, "--workers")
    check_data_paths(data)
    if save:
        check_tuning_out(out)
    grid = {} if calibrate_only else grid_for(predictor, gps_profile)
    mine = out if out.exists() else None
    try:
        kept = {
            k: v for k, v in tuned_params(predictor, gps_profile, mine).items() if k != "cov_scale"
        }
    except PredictorError as e:
        raise UsageError(f"--out: {e}") from None
    if gps_profile == "native" and not data:
        raise UsageError("--gps-profile native tunes on recorded fixes: give --data PATH...")
    if data:
        dev = load_drives(data, "enu", None, reporter=reporter())
        source = "development drives " + ", ".join(str(p) for p in data)
    else:
        from posbench.scenarios.synthetic import default_drives

        dev = [d for s in range(1000, 1000 + drives) for d in default_drives(seed=s)]
        source = f"synthetic development drives, seeds 1000-{999 + drives}"
    if method == "gradient":
        slow = gps_profile == "consumer" if slow_error is None else slow_error
        fit_options = {"iterations": iterations, "lr": lr, "holdout": holdout, "slow": slow}
        tune_gradient(dev, gps_profile, source, fit_options, workers, out, save)
        return
    n = (
        len(list(product(*list(grid.values())[:2])))
        + sum(len(v) for v in list(grid.values())[2:])
        + 1
    )  # + the calibration replay
    trials: list[tuple[dict[str, Any], float]]  # (parameters, objective [m]) per trial
    with reporter().steps(f"tuning {predictor} ({gps_profile})", n) as done:
        if calibrate_only:
            best, trials = kept, []
        else:
            best, trials = grid_search(
                predictor,
                dev,
                gps_profile,
                grid,
                workers=workers,
                on_step=lambda p, v: done(f"{p}: {v:.4f} m"),
            )
        cov_scale = calibrate(predictor, dev, gps_profile, best, workers=workers)
        done("calibration")
    if trials:
        best_val = min(v for _, v in trials)
        say(f"best {best} -> future+now mean error {best_val:.4f} m over {len(dev)} drives")
    else:
        say(
            f"kept {best or 'the defaults'} from the tuning in force "
            f"({out if mine else 'built-in'})"
        )
    best = with_cov_scale(predictor, best, cov_scale, len(dev))
    if save:
        command = command_line()
        how = (
            f"cov_scale for 95 % coverage by `{command}` on {source}"
            if calibrate_only
            else f"`{command}`: {source}; objective mean future + mean now error "
            f"{best_val:.4f} m; {len(trials)} trials; then cov_scale for 95 % coverage"
            if trials
            else f"`{command}`: cov_scale for 95 % coverage on {source}"
        )
        if calibrate_only:
            how = tuning_note(predictor, gps_profile, how, out)
        save_tuned(predictor, gps_profile, best, how, out, drives=[d.name for d in dev])
        say(f"saved to {out} (use it: bench run --tuning {out})")


def with_cov_scale(
    predictor: str, params: dict[str, Any], cov_scale: float, n_drives: int
) -> dict[str, Any]:
    """``params`` with the calibrated ``cov_scale`` (held in the range ``predictor``
    accepts, with a one-line warning where it was clamped; none where NaN: no covariance),
    said on stdout."""
    from posbench.predictor_tools.tuning import held_cov_scale

    if cov_scale != cov_scale:
        say("no covariance reported on these drives: nothing to calibrate")
        return params
    held, clamp = held_cov_scale(predictor, cov_scale)
    if clamp is not None:
        warn(clamp)
    else:
        say(
            f"calibrated: cov_scale {cov_scale:g} (95 % of the 95 % ellipses cover "
            f"on {n_drives} drives)"
        )
    return {**params, "cov_scale": held}


def check_tuning_out(out: Path) -> None:
    """``--out`` of ``bench tune``: a writable JSON file that is not the package's own
    tuning (which a command never changes)."""
    from posbench.checks import check_out_file
    from posbench.predictors.registry import TUNED_FILE

    if out.resolve() == TUNED_FILE.resolve():
        raise UsageError(
            f"--out {out}: that is the package's built-in tuning, which commands "
            "never change; write a file of your own and run with --tuning FILE"
        )
    check_out_file(out, "--out")


def check_gradient(
    predictor: str, calibrate_only: bool, iterations: int, lr: float, holdout: float
) -> None:
    """The options of ``--method gradient``, and torch being there, before any drive loads."""
    if predictor != "kf":
        raise UsageError(f"--method gradient tunes kf only; tune {predictor} with --method grid")
    if calibrate_only:
        raise UsageError("--calibrate-only fits no noise: leave out --method gradient")
    check_at_least(iterations, 1, "--iterations")
    if not 0.0 < lr <= 10.0:
        raise UsageError(f"--lr must be > 0 and <= 10; got {lr:g}")
    if not 0.0 <= holdout < 1.0:
        raise UsageError(f"--holdout must be >= 0 and < 1; got {holdout:g}")
    from posbench.predictors.kalman.tuning.gradient import TRAIN_EXTRA, require_torch

    try:
        require_torch()
    except ImportError:
        raise UsageError(f"--method gradient needs PyTorch: {TRAIN_EXTRA}") from None


def tune_gradient(
    dev: Sequence[Drive],
    gps_profile: str,
    source: str,
    fit_options: dict[str, Any],
    workers: int,
    out: Path,
    save: bool,
) -> None:
    """``bench tune kf --method gradient``: fit the kf's noise on the development drives
    ``dev`` (:func:`posbench.predictor_tools.tuning.gradient_search` with ``fit_options``),
    calibrate cov_scale with it, and write both to ``out`` (unless not ``save``)."""
    from posbench.predictor_tools.tuning import (
        calibrate,
        gradient_note,
        gradient_search,
        save_tuned,
    )

    steps = int(fit_options["iterations"]) + 1  # + the calibration replay
    with reporter().steps(f"tuning kf ({gps_profile}, gradient)", steps) as done:
        try:
            fit = gradient_search(
                dev,
                gps_profile,
                **fit_options,
                on_step=lambda i, f: done(
                    f"step {i}: 0.2 s error {f['error_m']:.4f} m, NLL {f['nll']:.3f}"
                ),
            )
        except ValueError as e:
            raise UsageError(f"--method gradient: {e}") from None
        best = dict(fit["params"])
        cov_scale = calibrate("kf", dev, gps_profile, best, workers=workers)
        done("calibration")
    note = gradient_note(fit)
    say(f"fitted {best} ({note}) over {len(dev)} drives in {fit['seconds']:.0f} s")
    for name, value in fit.get("clamped", {}).items():
        warn(f"fitted {name} {value:g} is outside the kf's range: clamped to {best[name]:g}")
    best = with_cov_scale("kf", best, cov_scale, len(dev))
    if save:
        how = f"`{command_line()}`: {source}; {note}; then cov_scale for 95 % coverage"
        kept = ("Q_c", "R", "sigma_a", "slow", "sigma_ref_m", "loss", "iterations")
        extra = {k: fit[k] for k in (*kept, "best_iteration", "segments", "fixes")}
        save_tuned(
            "kf",
            gps_profile,
            best,
            how,
            out,
            drives=[d.name for d in dev],
            extra={"fit": {"method": "gradient", **extra}},
        )
        say(f"saved to {out} (use it: bench run --tuning {out})")
