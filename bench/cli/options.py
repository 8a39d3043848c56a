"""The options several ``bench`` commands share: one definition each, so a name means the
same in every command (``--data``, ``--topic``, ``--model``, ``--set``, ``--out``, ...).

Every option takes one value and may be repeated (``--data a --data b``,
``--topic gps=/fix --topic truth=/rtk``, ``-p kf -p lstm`` as well as ``-p kf,lstm``): a
positional path is never taken for an option's value. ``-q``/``-v`` and ``--config`` are on
every command (:mod:`posbench.cli.terminal`, :mod:`posbench.cli.config_file`).
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from posbench.cli.config_file import load_config
from posbench.cli.terminal import QUIET, VERBOSE, set_verbosity, verbosity

#: the one line for a worker process that was killed (by the OOM killer, a signal, a crash)
WORKER_DIED = "a worker process died (out of memory?); try fewer --workers"


def import_from_cwd() -> None:
    """Let ``module:Class`` predictors be imported from the current folder, as under
    ``python -m`` (the installed ``bench`` script has its own folder first on sys.path)."""
    import os

    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.append(os.getcwd())


def command_line() -> str:
    """This invocation as a shell command, recorded in reports and model descriptions."""
    return "bench " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def parse_topics(values: list[str] | None) -> dict[str, str]:
    """``--topic ROLE=NAME`` values (roles gps, imu, speed, truth) as a dict."""
    from posbench.checks import check_topics, parse_pairs

    topics = parse_pairs(values, "--topic")
    check_topics(topics)
    return topics


def _loudness(level: int) -> Callable[[typer.Context, bool], bool]:
    """The eager callback of ``-q`` (``level`` QUIET) or ``-v`` (VERBOSE): sets the level,
    refusing the other one given too."""

    def callback(ctx: typer.Context, value: bool) -> bool:
        if value:
            if verbosity() == -level:
                raise typer.BadParameter("-q and -v together: give one")
            set_verbosity(level)
        return value

    return callback


# ------------------------------------------------------------------ on every command
QuietOpt = Annotated[
    bool,
    typer.Option(
        "--quiet",
        "-q",
        is_eager=True,
        callback=_loudness(QUIET),
        help="Only the command's own output (a table it was asked for), warnings and errors: no "
        "progress, no notes.",
    ),
]
VerboseOpt = Annotated[
    bool,
    typer.Option(
        "--verbose",
        "-v",
        is_eager=True,
        callback=_loudness(VERBOSE),
        help="Also a line per finished step (drive replayed, drive scored) and the details.",
    ),
]
ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config",
        "-c",
        metavar="FILE.toml",
        is_eager=True,
        callback=load_config,
        help="Take this command's options from a TOML file: its table named after the command "
        "([run], [compare], [data.inspect], ...), keys as the long option names (gps-profile "
        '= "consumer", data = ["a", "b"]). Options on the command line win. '
        "`bench run --print-config` writes one.",
    ),
]

# ------------------------------------------------------------------ data and drives
DataOpt = Annotated[
    list[Path] | None,
    typer.Option(
        "--data",
        "-d",
        metavar="PATH",
        help="A recording or a folder of them (any mix of ROS 1/2 bags, KITTI raw, comma2k19 "
        "segments, the paper's route pickles, CSV/Parquet; fsspec URLs too). Repeat for more: "
        "--data a --data b. Default: the built-in synthetic drives.",
    ),
]
TopicOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--topic",
        metavar="ROLE=TOPIC",
        help="Pick a bag topic by role when ambiguous (gps, imu, speed, truth); repeat for more "
        "roles: --topic gps=/fix --topic truth=/ground_truth. A bag has a truth only when "
        "named (nav_msgs/Odometry); it is aligned to the GPS by a 2-D rigid fit, refused if "
        "the residual RMS exceeds max(3 x stated GPS accuracy, 5 m).",
    ),
]
ProjectionOpt = Annotated[
    str,
    typer.Option(
        metavar="enu|mercator",
        help="Local frame for lat/lon sources: 'enu' (true metres, default) or 'mercator' (the "
        "paper's spherical Mercator, for parity only: +1/cos(lat) scale error, ~+52 % at 49 "
        "deg N).",
    ),
]
StrictOpt = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Exit 2 if the data consistency check fails for any drive and stream "
        "(the line names the drive, stream and figure), before any predictor "
        "runs.",
    ),
]

# ---- the options that place drives, fixes and queries (`bench run`, `bench queries`): one
# definition each, so the two stay the same config
HorizonOpt = Annotated[
    float,
    typer.Option(metavar="SECONDS", help="Future-point horizon after each fix [s] (0 < h <= 10)."),
]
GpsProfileOpt = Annotated[
    str,
    typer.Option(
        metavar="PROFILE",
        help="Which fixes drives with truth are fed and scored on. auto: the recording's own "
        "receiver where its fixes and truth are different sources (a bag or CSV with both, "
        "comma2k19), simulated rtk fixes drawn from the truth where the fixes are the truth "
        "(KITTI's OXTS, the synthetic drives). Or for every drive: native (the recorded "
        "fixes), none (exact), rtk (~2 cm), consumer (~1 m, correlated).",
    ),
]
GpsLatencyOpt = Annotated[
    float, typer.Option(metavar="SECONDS", help="Receiver latency of drawn fixes [s].")
]
DropoutsOpt = Annotated[
    str,
    typer.Option(
        metavar="PROFILE",
        help="GPS dropouts: none, random:P, outages (0.5/1/2/5 s), outage:L, "
        "outage-lengths (1/2/5/10/30/60 s as each drive allows; error by outage length, m and "
        "% of distance).",
    ),
]
SeedOpt = Annotated[
    int, typer.Option(metavar="INT", help="Master seed (GPS draws, dropouts, synthetic data).")
]
IncludePoorTruthOpt = Annotated[
    bool, typer.Option(help="Also score drives whose truth is poor (median accuracy > 1 m).")
]
SyntheticDurationOpt = Annotated[
    float | None,
    typer.Option(
        metavar="SECONDS",
        help="Without --data: one synthetic mixed drive of this length [s] instead of the "
        "built-in set (e.g. 14400 for a 4-hour soak test; at most 28800, 8 h, about 0.2 GB of "
        "memory per hour).",
    ),
]


# ------------------------------------------------------------------ predictors
def predictors_option(default: str) -> object:
    """The ``--predictors/-p`` option, its help naming the command's ``default``."""
    return typer.Option(
        "--predictors",
        "-p",
        metavar="NAMES",
        help="Predictor names (see `bench predictors`), comma-separated or repeated (-p kf -p "
        "lstm), or module:Class of a Predictor subclass of your own (from PYTHONPATH or "
        f"the current folder), e.g. kf,lstm,mypkg.mymodule:MyPredictor. Default: {default}.",
    )


ModelOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--model",
        metavar="NAME=PATH",
        help="The model file of one predictor, e.g. lstm-authors=PATH.onnx, or lstm=DIR (a folder "
        "`bench train` wrote); lstm@mine=DIR runs it beside the bundled lstm. Repeatable.",
    ),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="NAME.OPTION=VALUE",
        help="A constructor option of one predictor of the run, over its tuned value, e.g. "
        "--set kf.jerk_psd=4.0 or kf@slow.jerk_psd=1 or mymod:MyPredictor.tau_s=0.5 (split at "
        "the last '.' before '='). VALUE is a JSON literal (4, 0.5, true, \"text\", [1, 2]), "
        "else taken as text, and read by the option's type: a yes/no option takes true/false "
        "(also yes/no, on/off, 1/0), nothing else. Repeatable; `bench predictors NAME` lists "
        "each option and what it takes.",
    ),
]
GateOpt = Annotated[
    bool,
    typer.Option(
        "--gate/--no-gate",
        help="GPS outlier gate: drop fixes implying impossible motion before the predictors see "
        "them (counted in the report). --no-gate: the paper's ungated input.",
    ),
]
WorkersOpt = Annotated[int, typer.Option(metavar="N", help="Parallel processes (one drive each).")]

# ------------------------------------------------------------------ outputs
TableFormatOpt = Annotated[
    str,
    typer.Option(
        "--table-format",
        metavar="md,csv,latex",
        help="Report forms, comma-separated: md (report.md, always written), csv (every report "
        "table as tables/NAME.csv, full precision, CI bounds in their own columns), latex "
        "(tables/NAME.tex, booktabs). Example: --table-format md,csv.",
    ),
]
PlotFormatOpt = Annotated[
    str,
    typer.Option(
        "--plot-format",
        metavar="FORMATS",
        help="Figure formats, comma-separated: png, svg, pdf (e.g. png,pdf); none for no "
        "figures (results, report, tables and traces only: a run ~2 s quicker on the built-in "
        "drives).",
    ),
]
DrivePlotsOpt = Annotated[
    str,
    typer.Option(
        "--drive-plots",
        metavar="N|all",
        help="Error-over-time plots per drive (drives/): every drive of a run with at most N, "
        "else the N drives with the largest mean future error; 'all' for every drive, 0 "
        "for none.",
    ),
]
WideOpt = Annotated[
    bool,
    typer.Option(
        "--wide",
        help="Print the full summary: every column of the headline table (median, RMSE, p95, "
        "max, counts, x IMU limit, latency p99, ...), the paired tables and each note in full "
        "(-v implies it). By default: one table that fits 100 columns and one line per "
        "finding; report.md and results.json hold every figure either way.",
    ),
]
#: the hidden ``--format`` of one release, where it meant another option
OldFormatOpt = Annotated[str | None, typer.Option("--format", hidden=True)]


def renamed(old: str, new: str, command: str) -> None:
    """The one-line notice for an option spelled the way of the last release."""
    from posbench.cli.terminal import warn

    warn(f"{old} is deprecated in {command}: use {new} (the old spelling goes in the next release)")
