"""What every ``bench`` command shares: consoles, the one-line error, option types, drive loading.

Bad user input (missing file, unknown format, unknown predictor, ...) prints one
line naming what is wrong and exits with status 2, never a traceback.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from posbench.checks import check_topics, parse_pairs
from posbench.errors import UsageError
from posbench.scenarios.errors import DataError

__all__ = ["DataError", "UsageError"]  # re-exported for the commands


console = Console()


err_console = Console(stderr=True)


DEFAULT_PREDICTORS = "cv,poly,kf,kf-paper,ekf,lstm"


#: the one line for a worker process that was killed (by the OOM killer, a signal, a crash)
WORKER_DIED = "a worker process died (out of memory?); try fewer --workers"


def fail(msg: str) -> typer.Exit:
    """Print ``error: msg`` as one line on stderr; return the exit (status 2) to raise."""
    from rich.markup import escape  # "posbench-harness[ray]" is text, not markup

    err_console.print(f"[bold red]error:[/] {escape(msg)}", highlight=False, soft_wrap=True,
                      emoji=False)
    return typer.Exit(2)


def import_from_cwd() -> None:
    """Let ``module:Class`` predictors be imported from the current folder, as under
    ``python -m`` (the installed ``bench`` script has its own folder first on sys.path)."""
    import os

    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.append(os.getcwd())


def command_line() -> str:
    """This invocation as a shell command, recorded in reports and model descriptions."""
    return "bench " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def parse_topics(values: list[str] | None) -> dict[str, str] | None:
    """``--topic ROLE=NAME`` pairs (roles gps, imu, speed, truth) or None when none given."""
    topics = parse_pairs(values, "--topic")
    check_topics(topics)
    return topics or None


def load_drives(paths: list[Path] | None, projection: str, topics: dict[str, str] | None,
                 seed: int = 0, synthetic_duration: float | None = None, workers: int = 1):
    """The drives at ``paths`` in order (``workers`` processes load recordings in parallel),
    or the built-in synthetic drives when there are none."""
    from posbench.scenarios.loaders import iter_load_many

    if not paths:
        from posbench.scenarios.synthetic import default_drives, generate_drive

        if synthetic_duration is not None:
            if not synthetic_duration > 1.0:
                raise UsageError("--synthetic-duration must be more than 1 s")
            return [generate_drive(seed=seed, route="mixed", duration_s=synthetic_duration)]
        return default_drives(seed=seed)
    from posbench.pipeline.preload import REPLAY_MODULES, Preload

    drives = []
    preload = Preload(REPLAY_MODULES)  # for the replay workers, forked after loading
    with console.status("loading drives...") as status:
        for d in iter_load_many(paths, projection=projection, topics=topics, workers=workers):
            drives.append(d)
            if workers > 1:  # the loader processes exist by now: safe to import in a thread
                preload.start()
            status.update(f"loading drives... {len(drives)} ({d.name})")
    preload.join()
    return drives


DataOpt = Annotated[list[Path] | None, typer.Option(
    "--data", "-d", metavar="PATH...",
    help="Recordings or folders of them (any mix of ROS 1/2 bags, KITTI raw, comma2k19 segments, "
         "the paper's route pickles, CSV/Parquet). Several paths may follow one --data. "
         "Default: the built-in synthetic drives.")]


TopicOpt = Annotated[list[str] | None, typer.Option(
    "--topic", metavar="ROLE=TOPIC...",
    help="Pick bag topics by role when ambiguous: gps=/name imu=/name speed=/name truth=/name. "
         "A bag has a truth only when named (e.g. truth=/ground_truth, nav_msgs/Odometry); it "
         "is aligned to the GPS by a 2-D rigid fit, refused if the residual RMS exceeds "
         "max(3 x stated GPS accuracy, 5 m).")]


SetOpt = Annotated[list[str] | None, typer.Option(
    "--set", metavar="NAME.OPTION=VALUE...",
    help="A constructor option of one predictor of the run, over its tuned value, e.g. "
         "--set kf.jerk_psd=4.0 or kf@slow.jerk_psd=1 or mymod:MyPredictor.tau_s=0.5 (split at "
         "the last '.' before '='). VALUE is a JSON literal (4, 0.5, true, \"text\", [1, 2]), "
         "else taken as text. Repeatable; see `bench predictors NAME` for the options.")]


StrictOpt = Annotated[bool, typer.Option(
    "--strict", help="Exit 2 if the data consistency check fails for any drive and stream "
                     "(the line names the drive, stream and figure), before any predictor runs.")]


ProjectionOpt = Annotated[str, typer.Option(
    metavar="enu|mercator",
    help="Local frame for lat/lon sources: 'enu' (true metres, default) or 'mercator' (the paper's "
         "spherical Mercator, for parity only: +1/cos(lat) scale error, ~+52 % at 49 deg N).")]


# ---- options shared by the commands that place drives, fixes and queries the same way
# (`bench run`, `bench queries`): one definition each, so the two stay the same config
HorizonOpt = Annotated[float, typer.Option(
    metavar="SECONDS", help="Future-point horizon after each fix [s] (0 < h <= 10).")]


GpsProfileOpt = Annotated[str, typer.Option(
    metavar="PROFILE",
    help="GPS input for drives with truth: native (their own fixes), none (exact), "
         "rtk (~2 cm), consumer (~1 m, correlated).")]


GpsLatencyOpt = Annotated[float, typer.Option(
    metavar="SECONDS", help="Receiver latency of drawn fixes [s].")]


DropoutsOpt = Annotated[str, typer.Option(
    metavar="PROFILE", help="GPS dropouts: none, random:P, outages (0.5/1/2/5 s), outage:L.")]


SeedOpt = Annotated[int, typer.Option(
    metavar="INT", help="Master seed (GPS draws, dropouts, synthetic data).")]


IncludePoorTruthOpt = Annotated[bool, typer.Option(
    help="Also score drives whose truth is poor (median accuracy > 1 m).")]


SyntheticDurationOpt = Annotated[float | None, typer.Option(
    metavar="SECONDS",
    help="Without --data: one synthetic mixed drive of this length [s] instead of the "
         "built-in set (e.g. 36000 for a 10-hour soak test).")]


ReportFormatOpt = Annotated[str, typer.Option(
    "--format", metavar="md,csv,latex",
    help="Report forms, comma-separated: md (report.md, always written), csv (every report "
         "table as tables/NAME.csv, full precision, CI bounds in their own columns), latex "
         "(tables/NAME.tex, booktabs). Example: --format md,csv.")]


PlotFormatOpt = Annotated[str, typer.Option(
    "--plot-format", metavar="FORMATS",
    help="Figure formats, comma-separated: png, svg, pdf (e.g. png,pdf).")]


DrivePlotsOpt = Annotated[str, typer.Option(
    "--drive-plots", metavar="N|all",
    help="Error-over-time plots per drive (drives/): every drive of a run with at most N, "
         "else the N drives with the largest mean future error; 'all' for every drive, 0 "
         "for none.")]


def check_drive_options(gps_profile: str, projection: str, horizon: float, gps_latency: float,
                        dropouts: str, seed: int, synthetic_duration: float | None,
                        data: list[Path] | None) -> None:
    """The checks of the options above (and ``--projection``, ``--data``), before any work."""
    from posbench.checks import (
        check_at_least,
        check_choice,
        check_data_paths,
        check_dropouts,
        check_horizon,
        check_synthetic_duration,
    )
    from posbench.config import GPS_PROFILES
    from posbench.scenarios.projection import PROJECTIONS

    check_choice(gps_profile, GPS_PROFILES, "--gps-profile")
    check_choice(projection, PROJECTIONS, "--projection")
    check_horizon(horizon)
    check_at_least(gps_latency, 0.0, "--gps-latency", " s")
    check_dropouts(dropouts)
    check_at_least(seed, 0, "--seed")
    check_synthetic_duration(synthetic_duration, data)
    check_data_paths(data)
