"""Option checks, run before any drive is loaded or any worker starts (by the command line
and by the Python API alike).

Each check raises :class:`~posbench.errors.UsageError` with one line naming the option (as
``bench`` spells it) and what is wrong, so a typo costs a second instead of a whole run (and
never surfaces as a traceback from a worker process). The checks of values are pure; those
of paths look at the file system, and an output folder is tried for real (made, written and
removed again), so that one the run could not write fails here, never after the replay.
"""

from __future__ import annotations

import errno
import math
import os
import tempfile
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
#: longest --synthetic-duration [s]: the longest drive posbench takes (8 h,
#: :data:`posbench.scenarios.time_axis.MAX_SPAN_S`, not imported here: that module needs numpy,
#: the command line's start does not). The generator holds about 0.13 GB per simulated hour
#: (100 Hz truth, 50 Hz IMU and speed) and a run about 0.2 GB
MAX_SYNTHETIC_S = 8 * 3600.0


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
    """A GPS dropout profile (``none``, ``random:P``, ``outages``, ``outage:L``,
    ``outage-lengths``), checked by
    the parser that applies it (:func:`posbench.scenarios.dropouts.parse_dropouts`)."""
    from posbench.scenarios.dropouts import parse_dropouts

    try:
        parse_dropouts(profile)
    except DataError as e:
        raise UsageError(f"--dropouts: {e.detail}") from None
    return profile


def check_synthetic_duration(seconds: float | None, data: Sequence[Any] | None) -> float | None:
    """``--synthetic-duration`` [s]: only without ``--data``, more than :data:`MIN_SYNTHETIC_S`
    and at most :data:`MAX_SYNTHETIC_S` (the memory the drive takes grows with its length)."""
    if seconds is None:
        return None
    if data:
        raise UsageError(
            "--synthetic-duration is for runs without --data (it sets the length "
            "of the synthetic drive)"
        )
    if not (MIN_SYNTHETIC_S < seconds <= MAX_SYNTHETIC_S):  # False for NaN too
        raise UsageError(
            f"--synthetic-duration must be more than {MIN_SYNTHETIC_S:g} s and at most "
            f"{MAX_SYNTHETIC_S:.0f} s ({MAX_SYNTHETIC_S / 3600:g} h, the longest drive posbench "
            f"takes; a run holds about 0.2 GB of memory per simulated hour); got {_num(seconds)}"
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
def _nearest_existing(path: Path) -> Path:
    """``path`` (absolute) or the nearest folder above it that exists; a name too long to
    exist counts as missing."""
    p = path.absolute()
    while p != p.parent:
        try:
            if p.exists():
                return p
        except OSError:  # e.g. ENAMETOOLONG: it cannot exist
            pass
        p = p.parent
    return p


def _limit(folder: Path, name: str, default: int) -> int:
    """The file system's ``os.pathconf`` limit ``name`` at ``folder`` (``default`` where it
    does not say)."""
    try:
        return int(os.pathconf(folder, name))
    except (OSError, ValueError):
        return default


def _why(e: OSError, path: Path) -> str:
    """Why ``path`` cannot be written, from the error the try raised, in words."""
    if e.errno == errno.ENAMETOOLONG:
        anc = _nearest_existing(path)
        longest = max(path.absolute().parts, key=lambda part: len(os.fsencode(part)))
        name_max = _limit(anc, "PC_NAME_MAX", 255)
        if len(os.fsencode(longest)) > name_max:
            return (
                f"a name in it has {len(longest)} characters, more than the file system "
                f"allows ({name_max} bytes)"
            )
        path_max = _limit(anc, "PC_PATH_MAX", 4096)
        return f"the path is longer than the file system allows ({path_max} bytes)"
    if e.errno in (errno.EACCES, errno.EPERM):
        return "no permission to write there"
    if e.errno == errno.EROFS:
        return "the file system is read-only"
    if e.errno == errno.ENOENT:  # mkdir in /proc, /sys: the parent exists, takes nothing new
        return f"{_nearest_existing(path)} takes no new files or folders"
    return (e.strerror or str(e)).lower()


def _try_writing(folder: Path, option: str, shown: Path, name: str | None = None) -> None:
    """Whether a command can write in ``folder``, tried for real: the folders missing on the
    way made, a file written there (``name``, else a temporary one) and removed, then the
    folders made removed again, so the check leaves no trace.

    Raises:
        UsageError: naming ``option`` and ``shown`` (the path as given), and why not.
    """
    anc = _nearest_existing(folder)
    if not anc.is_dir():
        raise UsageError(f"{option} {shown}: cannot be created, {anc} is a file")
    missing = list(folder.absolute().relative_to(anc).parts)
    made: list[Path] = []
    try:
        here = anc
        for part in missing:
            here = here / part
            try:
                here.mkdir()
            except FileExistsError:  # made meanwhile by another process, or a "..": not ours
                continue
            made.append(here)
        if name is None:
            with tempfile.TemporaryFile(dir=folder):
                pass
        else:
            (folder / name).open("x").close()
            (folder / name).unlink()
    except OSError as e:
        raise UsageError(f"{option} {shown}: cannot be written: {_why(e, shown)}") from None
    finally:
        for p in reversed(made):
            try:
                p.rmdir()
            except OSError:
                pass


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
    """An output folder the command can write: an existing folder, or one that can be made.
    Tried for real (made, a file written in it, all removed again: the check leaves no
    trace), so that every command that takes ``--out`` refuses, before any drive is loaded,
    a folder it could not write (no permission, a read-only or system file system, a name
    longer than the file system allows)."""
    if _nearest_existing(path) == path.absolute() and not path.is_dir():
        raise UsageError(f"{option} {path}: exists and is not a folder; give a folder path")
    _try_writing(path, option, path)
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
    """An output file: an existing file that may be overwritten, or one that can be written
    (tried for real as :func:`check_out_dir` does, and removed again)."""
    if _nearest_existing(path) == path.absolute():
        if path.is_dir():
            raise UsageError(f"{option} {path}: is a folder; give a file path")
        if not os.access(path, os.W_OK):
            raise UsageError(f"{option} {path}: no permission to overwrite this file")
        return path
    _try_writing(path.parent, option, path, name=path.name)
    return path


def check_data_paths(paths: Sequence[str | Path] | None, option: str = "--data") -> None:
    """Local ``--data`` paths and ``file://`` URLs exist (other fsspec URLs such as
    ``s3://...`` are fetched later)."""
    from posbench.scenarios.remote import as_url, local_path

    for p in paths or []:
        local = local_path(p)
        if local is not None and not local.exists():
            raise UsageError(f"{option} {as_url(p) or p}: no such file or folder")


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
