"""``bench export``: a saved run's reference and answers as TUM or CSV tracks, for evo and
other trajectory tools (:mod:`posbench.offline.export` does the work)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.options import ConfigOpt, QuietOpt, VerboseOpt


def export(
    run_dir: Annotated[
        Path,
        typer.Argument(
            metavar="RUN_DIR",
            show_default=False,
            help="A folder written by `bench run` or `bench score` (or its results.json); its "
            "traces.parquet is read.",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="DIR",
            show_default=False,
            help="Folder to write the tracks into (made if missing; files of the same names "
            "are replaced).",
        ),
    ],
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            metavar="tum|csv",
            help="tum: `t x y z qx qy qz qw` lines (evo, TUM RGB-D tools); csv: header "
            "t,x,y,drive[,predictor],kind[,t_issue,error_m].",
        ),
    ] = "tum",
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """Write a saved run's tracks, per drive: the reference and each predictor's answers to
    the now queries and to the future queries, one file each, exactly the queries the run
    scored (past the warm-up, with a reference: the rows of report.md's and results.json's
    figures; an unanswered query has no row).

    Files (DRIVE, PREDICTOR made file-safe): DRIVE.reference.tum (reference at the now
    queries), DRIVE.reference.future.tum (at the future queries: their times can coincide with
    now query times, so each kind has its own reference), DRIVE.PREDICTOR.now.tum,
    DRIVE.PREDICTOR.future.tum. Time: t_query [s] from the drive's t = 0 (traces.parquet's
    clock, not Unix time); x east, y north [m] in the drive's local ENU frame; z = 0; the
    orientation is the identity quaternion 0 0 0 1 (predictors answer positions only). Numbers
    are exact (Python's repr of the float), so evo associates each answer with its own query.

    A drive's now figures of results.json (mean, median, RMSE, max) are evo's translation
    APE without alignment (its defaults), e.g. for kf: evo_ape tum DIR/DRIVE.reference.tum
    DIR/DRIVE.kf.now.tum (future: DIR/DRIVE.reference.future.tum with DIR/DRIVE.kf.future.tum;
    the command prints one such line with a real drive). A now track is also an answers file
    for `bench score` (its `# drive:` line names the drive).

    Example: bench export bench-out --format tum --out bench-out/tum
    """
    from posbench.checks import check_out_dir
    from posbench.cli.terminal import say
    from posbench.errors import UsageError
    from posbench.naming import plural
    from posbench.offline.export import FORMATS, export_run
    from posbench.saved_run.run import load_run
    from posbench.scenarios.errors import DataError

    fmt = fmt.strip().lower()
    if fmt not in FORMATS:
        raise UsageError(f"--format {fmt}: not an export format; give one of {', '.join(FORMATS)}")
    check_out_dir(out)
    run = load_run(run_dir)
    try:
        done = export_run(run, out, fmt)
    except OSError as e:
        raise DataError(out, f"cannot write the tracks: {e.strerror or e}") from None
    say(
        f"{out}: {plural(len(done.files), f'{fmt.upper()} file')} (reference and "
        f"{plural(len(run.predictors), 'predictor')}, now and future queries scored, "
        f"{plural(len(done.drives), 'drive')})"
    )
    if done.skipped:
        say(f"drives the run skipped (no tracks): {', '.join(done.skipped)}")
    if done.empty:
        shown = ", ".join(done.empty[:5]) + (", ..." if len(done.empty) > 5 else "")
        say(f"{plural(len(done.empty), 'track')} without a scored answer, not written: {shown}")
    now = [(ref, est) for ref, est in done.pairs if est.name.endswith(".now.tum")]
    if now:
        say(f"compare with evo (a drive's now figures): evo_ape tum {now[0][0]} {now[0][1]}")
