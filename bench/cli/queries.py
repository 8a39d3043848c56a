"""``bench queries``: write posbench's queries and inputs for a system that answers elsewhere
(:mod:`posbench.offline.queries_folder` writes the folder)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.options import (
    ConfigOpt,
    DataOpt,
    DropoutsOpt,
    GpsLatencyOpt,
    GpsProfileOpt,
    HorizonOpt,
    IncludePoorTruthOpt,
    OldFormatOpt,
    ProjectionOpt,
    QuietOpt,
    SeedOpt,
    SyntheticDurationOpt,
    TopicOpt,
    VerboseOpt,
    command_line,
    parse_topics,
    renamed,
)


def queries(
    data: DataOpt = None,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="DIR",
            help="Queries folder to write: queries.csv and inputs/ (give these to the system under "
            "test), key/ (the answer key: keep it), manifest.json.",
        ),
    ] = Path("bench-queries"),
    horizon: HorizonOpt = 0.2,
    gps_profile: GpsProfileOpt = "auto",
    gps_latency: GpsLatencyOpt = 0.0,
    dropouts: DropoutsOpt = "none",
    seed: SeedOpt = 0,
    topic: TopicOpt = None,
    projection: ProjectionOpt = "enu",
    include_poor_truth: IncludePoorTruthOpt = False,
    synthetic_duration: SyntheticDurationOpt = None,
    file_format: Annotated[
        str,
        typer.Option(
            "--file-format",
            metavar="csv|parquet",
            help="File format of the queries list and the inputs.",
        ),
    ] = "csv",
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    old_format: OldFormatOpt = None,
) -> None:
    """Write the queries of a run and the inputs to answer them, for a system that runs outside
    posbench (another process, language or machine); score its answers with `bench score`.

    Same drives, fed fixes (after --gps-profile, --dropouts), query times and references as
    `bench run` with the same options and --seed. Per drive, inputs/DRIVE.csv holds what a
    predictor may see, in the long table format (stream gps/imu/speed, t [s], x, y [m, local
    ENU], ax, ay [m/s^2], yaw [rad], yaw_rate [rad/s], v [m/s]); queries.csv lists drive, kind
    (future: position at t_query = fix time + horizon, asked at the fix; now: current
    position), t_issue (answer using only inputs with t <= t_issue) and t_query [s]. Times are
    seconds from each drive's first input sample, written exactly (repr of the float).

    Example: bench queries --dropouts outages --out q; then give q/queries.csv and q/inputs/
    to the system under test, keep q/key/, and run bench score ANSWERS.csv --queries q
    """
    from posbench.checks import check_choice, check_drive_options, check_out_dir
    from posbench.cli.terminal import reporter, say
    from posbench.config import RunConfig
    from posbench.naming import plural
    from posbench.offline.queries_folder import FORMATS, write_queries
    from posbench.pipeline.drives import load_drives
    from posbench.saved_run.provenance import data_provenance
    from posbench.scenarios.remote import local_paths

    if old_format is not None:
        renamed("--format", "--file-format", "bench queries")
        file_format = old_format
    check_drive_options(
        gps_profile, projection, horizon, gps_latency, dropouts, seed, synthetic_duration, data
    )
    topics = parse_topics(topic)
    check_choice(file_format, FORMATS, "--file-format")
    check_out_dir(out)
    # no predictor runs here, and no gate: the system under test gets every fed fix
    cfg = RunConfig(
        predictors=(),
        horizon_s=horizon,
        gps_profile=gps_profile,
        gps_latency_s=gps_latency,
        dropouts=dropouts,
        seed=seed,
        exclude_poor_truth=not include_poor_truth,
        gate=False,
    )
    progress = reporter()
    with local_paths(data) as local:
        drives = load_drives(
            local,
            projection,
            topics or None,
            seed=seed,
            synthetic_duration_s=synthetic_duration,
            reporter=progress,
        )
        with progress.steps(
            f"{plural(len(drives), 'drive')}: queries and inputs", len(drives)
        ) as done:
            written = write_queries(
                drives,
                cfg,
                out,
                command=command_line(),
                data=data_provenance(local, cfg.seed),
                fmt=file_format,
                on_done=done,
            )
    skipped = f" ({written.skipped} skipped, named in manifest.json)" if written.skipped else ""
    say(
        f"wrote {out}/: {written.files[0]} ({written.queries} queries), "
        f"{plural(written.drives, 'input file')} in inputs/{skipped}, key/ (the answer "
        f"key: keep it from the system under test), manifest.json"
    )
    say(f"score the answers with: bench score ANSWERS.csv --queries {out}")
