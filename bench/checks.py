"""Option checks, run before any drive is loaded or any worker starts (by the command line
and by the Python API alike).

Each check raises :class:`~posbench.errors.UsageError` with one line naming the option (as
``bench`` spells it) and what is wrong, so a typo costs a second instead of a whole run (and
never surfaces as a traceback from a worker process). The checks of values are pure; those
of paths look at the file system but never create or change anything there.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from posbench.errors import UsageError
from posbench.scenarios.errors import DataError


def parse_pairs(values: list[str] | None, what: str) -> dict[str, str]:
    """``KEY=VALUE`` strings as a dict (``what`` names the option in the error)."""
    out: dict[str, str] = {}
    for v in values or []:
        if "=" not in v:
            raise UsageError(f"{what} expects ROLE=VALUE, got {v!r}")
        k, val = v.split("=", 1)
        out[k.strip()] = val.strip()
    return out


#: longest --horizon [s]: the predictors extrapolate between fixes, not over minutes
MAX_HORIZON_S = 10.0
#: shortest --synthetic-duration [s]
MIN_SYNTHETIC_S = 1.0


def _num(value: float) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def check_choice(value: str, choices: Iterable[str], option: str) -> str:
    """``value`` if it is one of ``choices``, else a :class:`UsageError` listing them."""
    choices = tuple(choices)
    if value not in choices:
        raise UsageError(f"{option} must be one of {', '.join(choices)}; got {value!r}")
    return value


def check_at_least(value: float, minimum: float, option: str, unit: str = "") -> float:
    """``value`` if it is a finite number >= ``minimum`` (``unit`` only words the message)."""
    if not (math.isfinite(value) and value >= minimum):
        raise UsageError(f"{option} must be at least {_num(minimum)}{unit}; got {_num(value)}")
    return value


def check_horizon(seconds: float, option: str = "--horizon") -> float:
    """A look-ahead [s]: more than 0 and at most :data:`MAX_HORIZON_S`."""
    if not (math.isfinite(seconds) and 0.0 < seconds <= MAX_HORIZON_S):
        raise UsageError(
            f"{option} must be more than 0 s and at most {MAX_HORIZON_S:g} s; got {_num(seconds)}"
        )
    return seconds


def check_dropouts(profile: str) -> str:
    """A GPS dropout profile (``none``, ``random:P``, ``outages``, ``outage:L``), checked by
    the parser that applies it (:func:`posbench.scenarios.degrade.parse_dropouts`)."""
    from posbench.scenarios.degrade import parse_dropouts

    try:
        parse_dropouts(profile)
    except DataError as e:
        raise UsageError(f"--dropouts: {e.detail}") from None
    return profile


def check_synthetic_duration(seconds: float | None, data: Sequence[Any] | None) -> float | None:
    """``--synthetic-duration`` [s]: only without ``--data``, finite and > 1 s."""
    if seconds is None:
        return None
    if data:
        raise UsageError(
            "--synthetic-duration is for runs without --data (it sets the length "
            "of the synthetic drive)"
        )
    if not (math.isfinite(seconds) and seconds > MIN_SYNTHETIC_S):
        raise UsageError(
            f"--synthetic-duration must be more than {MIN_SYNTHETIC_S:g} s; got {_num(seconds)}"
        )
    return seconds


def parse_predictor_names(
    values: str | Iterable[str], option: str = "--predictors"
) -> tuple[str, ...]:
    """Predictor names, in order (not yet checked against the registry): comma-separated
    text, or several such texts (``-p kf -p lstm`` as well as ``-p kf,lstm``)."""
    texts = [values] if isinstance(values, str) else list(values)
    names = tuple(n.strip() for text in texts for n in str(text).split(",") if n.strip())
    if not names:
        raise UsageError(f"{option} names no predictor; e.g. {option} cv,kf")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UsageError(f"{option} lists {', '.join(twice)} more than once")
    return names


def parse_seeds(value: str | int | Sequence[int], option: str = "--seeds") -> list[int]:
    """``--seeds``: a count N (the seeds 0 .. N-1) or a list of distinct seeds >= 0, as text
    (``5``, ``0,1,2,3,4``) or as Python values (``5``, ``[0, 1, 2, 3, 4]``)."""
    try:
        if isinstance(value, str):
            values = [int(p.strip()) for p in value.split(",")]
        elif isinstance(value, int):
            values = [value]
        else:
            values = [int(v) for v in value]
            if len(values) == 1:  # a list of one seed is that seed, not a count
                if values[0] < 0:
                    raise UsageError(f"{option}: seeds must be >= 0; got {values[0]}")
                return values
    except (TypeError, ValueError):
        raise UsageError(
            f"{option} takes a count (e.g. 5: seeds 0..4) or a list of seeds "
            f"(e.g. 0,1,2,3,4); got {value!r}"
        ) from None
    if len(values) == 1:
        if values[0] < 1:
            raise UsageError(f"{option} count must be at least 1; got {values[0]}")
        return list(range(values[0]))
    bad = [v for v in values if v < 0]
    if bad:
        raise UsageError(f"{option}: seeds must be >= 0; got {bad[0]}")
    twice = sorted({v for v in values if values.count(v) > 1})
    if twice:
        raise UsageError(f"{option} lists {', '.join(map(str, twice))} more than once")
    return values


def resolve_baseline(value: str | None, names: Sequence[str]) -> str | None:
    """``--baseline``: the predictor the others are compared with. Default (None): ``kf``
    when it is in the run, else no comparison; ``none``: no comparison; otherwise it must
    be one of the run's predictors."""
    from posbench.config import default_baseline

    if value is None:
        return default_baseline(names)
    value = value.strip()
    if value.lower() == "none":
        return None
    if value not in names:
        raise UsageError(
            f"--baseline {value}: not among the predictors to run "
            f"({', '.join(names)}); name one of them, or 'none'"
        )
    return value


def check_topics(
    topics: Mapping[str, str] | None, roles: Iterable[str] = ("gps", "imu", "speed", "truth")
) -> None:
    """``--topic ROLE=NAME`` pairs: known roles, non-empty names."""
    roles = tuple(roles)
    bad = sorted(set(topics or {}) - set(roles))
    if bad:
        raise UsageError(f"--topic roles are {', '.join(roles)}; got {', '.join(bad)}")
    empty = sorted(r for r, name in (topics or {}).items() if not name)
    if empty:
        raise UsageError(f"--topic {empty[0]}= needs a topic name, e.g. --topic {empty[0]}=/fix")


# ------------------------------------------------------------------- paths
def _first_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_creatable(path: Path, option: str) -> None:
    anc = _first_existing(path)
    if not anc.is_dir():
        raise UsageError(f"{option} {path}: cannot be created, {anc} is a file")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: cannot be created, no permission to write in {anc}")


def parse_drive_plots(value: str | int | None, option: str = "--drive-plots") -> int | None:
    """``--drive-plots``: a count >= 0, or ``all`` / None (no limit)."""
    if value is None or (isinstance(value, str) and value.strip().lower() == "all"):
        return None
    try:
        n = int(value)
    except (TypeError, ValueError):
        n = -1
    if n < 0:
        raise UsageError(f"{option} takes a count >= 0 or 'all', got {value!r}")
    return n


def parse_plot_formats(
    value: str | Iterable[str], option: str = "--plot-format"
) -> tuple[str, ...]:
    """Figure formats (``png,pdf`` or ``("png", "pdf")``) as a tuple of known ones, in the
    order given (:func:`posbench.figures.style.check_formats`)."""
    from posbench.figures.style import check_formats

    try:
        return check_formats(value)
    except ValueError as e:
        shown = value if isinstance(value, str) else ",".join(map(str, value))
        raise UsageError(f"{option} {shown!r}: {e}") from None


def check_out_dir(path: Path, option: str = "--out") -> Path:
    """An output folder: an existing folder, or one that can be created (nothing is created
    here: a failed check leaves no trace)."""
    if path.exists():
        if not path.is_dir():
            raise UsageError(f"{option} {path}: exists and is not a folder; give a folder path")
        if not os.access(path, os.W_OK | os.X_OK):
            raise UsageError(f"{option} {path}: no permission to write in this folder")
        return path
    _check_creatable(path, option)
    return path


def resolve_color_by(value: str | None, names: Sequence[str], rerun: Path | None) -> str | None:
    """``--rerun-color-by``: the predictor whose error colours the rerun map's track; default
    the first predictor of the run. Needs ``--rerun`` and one of the run's predictors."""
    if value is None:
        return names[0] if names else None
    value = value.strip()
    if rerun is None:
        raise UsageError(
            f"--rerun-color-by {value}: colours the track of a rerun recording; "
            f"give --rerun FILE.rrd too"
        )
    if value not in names:
        raise UsageError(
            f"--rerun-color-by {value}: not among the predictors to run "
            f"({', '.join(names)}); name one of them"
        )
    return value


def check_out_file(path: Path, option: str) -> Path:
    """An output file: not an existing folder, and its folder exists or can be created."""
    if path.is_dir():
        raise UsageError(f"{option} {path}: is a folder; give a file path")
    if path.exists():
        if not os.access(path, os.W_OK):
            raise UsageError(f"{option} {path}: no permission to overwrite this file")
        return path
    _check_creatable(path, option)
    return path


def check_data_paths(paths: Sequence[str | Path] | None, option: str = "--data") -> None:
    """Local ``--data`` paths exist (fsspec URLs such as ``s3://...`` are fetched later)."""
    from posbench.scenarios.remote import as_url

    for p in paths or []:
        if as_url(p) is None and not Path(p).exists():
            raise UsageError(f"{option} {p}: no such file or folder")


def check_drive_options(
    gps_profile: str,
    projection: str,
    horizon_s: float,
    gps_latency_s: float,
    dropouts: str,
    seed: int,
    synthetic_duration_s: float | None,
    data: Sequence[str | Path] | None,
) -> None:
    """The options that place drives, fixes and queries (``bench run``, ``bench queries``),
    checked before any work: GPS profile, projection, horizon [s], GPS latency [s], dropout
    profile, seed, synthetic duration [s] and data paths."""
    from posbench.config import GPS_PROFILES
    from posbench.scenarios.projection import PROJECTIONS

    check_choice(gps_profile, GPS_PROFILES, "--gps-profile")
    check_choice(projection, PROJECTIONS, "--projection")
    check_horizon(horizon_s)
    check_at_least(gps_latency_s, 0.0, "--gps-latency", " s")
    check_dropouts(dropouts)
    check_at_least(seed, 0, "--seed")
    check_synthetic_duration(synthetic_duration_s, data)
    check_data_paths(data)
