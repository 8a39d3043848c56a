"""Command-line option checks, run before any drive is loaded or any worker starts.

Each check raises :class:`UsageError` with one line naming the option and what is
wrong, so a typo costs a second instead of a whole run (and never surfaces as a
traceback from a worker process). The checks of values are pure; those of paths
look at the file system but never create or change anything there.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

#: longest --horizon [s]: the predictors extrapolate between fixes, not over minutes
MAX_HORIZON_S = 10.0
#: shortest --synthetic-duration [s]
MIN_SYNTHETIC_S = 1.0


class UsageError(Exception):
    """A command-line mistake: reported in one line, exit status 2."""


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
        raise UsageError(f"{option} must be more than 0 s and at most {MAX_HORIZON_S:g} s; "
                         f"got {_num(seconds)}")
    return seconds


def check_dropouts(profile: str) -> str:
    """A GPS dropout profile (``none``, ``random:P``, ``outages``, ``outage:L``), checked by
    the parser that applies it (:func:`posbench.scenarios.degrade._parse_dropouts`)."""
    from posbench.scenarios.degrade import _parse_dropouts
    from posbench.scenarios.errors import DataError

    try:
        _parse_dropouts(profile)
    except DataError as e:
        raise UsageError(f"--dropouts: {e.detail}") from None
    return profile


def check_synthetic_duration(seconds: float | None, data: Sequence[Any] | None) -> float | None:
    """``--synthetic-duration`` [s]: only without ``--data``, finite and > 1 s."""
    if seconds is None:
        return None
    if data:
        raise UsageError("--synthetic-duration is for runs without --data (it sets the length "
                         "of the synthetic drive)")
    if not (math.isfinite(seconds) and seconds > MIN_SYNTHETIC_S):
        raise UsageError(f"--synthetic-duration must be more than {MIN_SYNTHETIC_S:g} s; "
                         f"got {_num(seconds)}")
    return seconds


def parse_predictor_names(text: str, option: str = "--predictors") -> tuple[str, ...]:
    """Comma-separated predictor names, in order (not yet checked against the registry)."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise UsageError(f"{option} names no predictor; e.g. {option} cv,kf")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UsageError(f"{option} lists {', '.join(twice)} more than once")
    return names


def parse_seeds(text: str, option: str = "--seeds") -> list[int]:
    """``--seeds``: a count N (the seeds 0 .. N-1) or a comma-separated list of distinct
    seeds >= 0, e.g. ``5`` or ``0,1,2,3,4``."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [int(p) for p in parts]
    except ValueError:
        raise UsageError(f"{option} takes a count (e.g. 5: seeds 0..4) or a list of seeds "
                         f"(e.g. 0,1,2,3,4); got {text!r}") from None
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
    from posbench.intervals import default_baseline

    if value is None:
        return default_baseline(names)
    value = value.strip()
    if value.lower() == "none":
        return None
    if value not in names:
        raise UsageError(f"--baseline {value}: not among the predictors to run "
                         f"({', '.join(names)}); name one of them, or 'none'")
    return value


def check_topics(topics: Mapping[str, str] | None,
                 roles: Iterable[str] = ("gps", "imu", "speed", "truth")) -> None:
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
        raise UsageError(f"--rerun-color-by {value}: colours the track of a rerun recording; "
                         f"give --rerun FILE.rrd too")
    if value not in names:
        raise UsageError(f"--rerun-color-by {value}: not among the predictors to run "
                         f"({', '.join(names)}); name one of them")
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
    from posbench.fetch import as_url

    for p in paths or []:
        if as_url(p) is None and not Path(p).exists():
            raise UsageError(f"{option} {p}: no such file or folder")


# -------------------------------------------------------------- predictors
def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:300] if text else type(exc).__name__


def _failure_detail(exc: BaseException) -> str:
    """``Type: first line`` of an exception (a DataError's own line, without its type)."""
    from posbench.scenarios.errors import DataError

    return _first_line(exc) if isinstance(exc, DataError) else \
        f"{type(exc).__name__}: {_first_line(exc)}"


def _load_failure(name: str, given: Any, path: str | None, exc: BaseException,
                  flag: str | None = None) -> str:
    """One line: which predictor (and model file, given as ``flag``) could not be built, and why."""
    from posbench.scenarios.errors import DataError

    if isinstance(exc, DataError):
        # the path is in the message already unless it is the model file itself
        detail = exc.detail if exc.path is not None and exc.path in (str(given), path) \
            else _first_line(exc)
    else:
        detail = _failure_detail(exc)
    if given is None:
        return f"predictor {name} cannot be created: {detail}"
    return f"{flag or f'--model {name}={given}'}: {name} cannot load it: {detail}"


def _model_path(name: str, path: Any) -> str:
    """A ``--model`` value as the file the predictor loads (a folder means its model.onnx)."""
    p = Path(str(path))
    if not p.exists():
        raise UsageError(f"--model {name}={path}: no such file or folder")
    if p.is_dir():
        onnx = p / "model.onnx"
        if not onnx.is_file():
            raise UsageError(f"--model {name}={path}: folder without a model.onnx")
        return str(onnx)
    return str(p)


def with_model_aliases(names: Sequence[str], options: Mapping[str, Any]) -> tuple[str, ...]:
    """``names`` plus every ``NAME@ALIAS`` given only in ``--model`` (in the order given).

    ``NAME@ALIAS`` runs a second instance of a registered predictor under its own name, so
    ``--model lstm@mine=DIR`` compares your model with the bundled ``lstm``.
    """
    from posbench.predictors.registry import ALIAS_SEP

    return tuple(names) + tuple(n for n in options if ALIAS_SEP in n and n not in names)


def validate_predictors(names: Sequence[str], options: Mapping[str, Mapping[str, Any]],
                        given: Mapping[tuple[str, str], str] | None = None
                        ) -> dict[str, dict[str, Any]]:
    """Check the requested predictors and their constructor options before any work.

    Each name must be a built-in, an entry point or an importable ``module:Class`` of a
    Predictor subclass (:func:`posbench.predictors.registry.resolve`), each option set must belong to
    a requested name and name a keyword of its constructor, a ``model`` path must exist (a
    folder stands for its ``model.onnx``), and each predictor is built once here with its
    options (registry defaults, no tuned parameters) so that a bad model file or value fails
    now, in one line naming the predictor and the option.

    Args:
        names: the final predictor names, in report order.
        options: per-name constructor options, e.g. ``{"lstm": {"model": "m/model.onnx"}}``.
        given: how each ``(name, option)`` was given on the command line, for messages
            (``--set kf.jerk_psd=4``); default ``--model NAME=PATH``.

    Returns:
        the options with ``model`` folders resolved to their ``model.onnx``.
    """
    from posbench.predictor_options import check_option_names, flag_text
    from posbench.predictors.registry import (
        PredictorError,
        base_name,
        is_import_path,
        is_known,
        known_names_text,
        predictor_class,
    )

    given = given or {}
    unknown = [n for n in names if not is_import_path(n) and not is_known(n)]
    if unknown:
        raise UsageError(f"unknown predictor(s) {', '.join(unknown)}; known: "
                         f"{known_names_text()} (NAME@ALIAS runs a second instance; "
                         "module:Class a Predictor subclass of your own)")
    for n in names:
        try:
            predictor_class(n)
        except PredictorError as e:
            raise UsageError(str(e)) from None
    stray = [n for n in options if n not in names]
    if stray:
        n = stray[0]
        option, value = next(iter(options[n].items()), ("model", "..."))
        alias = f"{n}@NAME=PATH" if option == "model" else f"{n}@NAME.{option}=VALUE"
        hint = (f"add it, or use {alias} for a second {n}" if is_known(n) or n in names
                else "add it to --predictors")
        raise UsageError(f"{flag_text(given, n, option, value)}: {n} is not among the "
                         f"predictors to run ({', '.join(names)}); {hint}")
    for n in names:
        if base_name(n) == "lstm-authors" and "model" not in options.get(n, {}):
            raise UsageError(f"{n} needs the authors' network: --model {n}=PATH.onnx "
                             "(e.g. ../shared/models/authors/gps_interpolation_model2.onnx)")
    for name, opts in options.items():
        check_option_names(name, opts, given)
    resolved: dict[str, dict[str, Any]] = {}
    for name, opts in options.items():
        resolved[name] = dict(opts)
        if "model" in opts:
            resolved[name]["model"] = _model_path(name, opts["model"])
    for name in names:
        _build_once(name, resolved.get(name, {}), options.get(name, {}), given)
    return resolved


def _build_once(name: str, opts: Mapping[str, Any], as_given: Mapping[str, Any],
                given: Mapping[tuple[str, str], str]) -> None:
    """Build predictor ``name`` with ``opts``; a failure names the option to blame. The model
    file (if any) is tried first, then the other options are added one at a time in the order
    given: the first that makes the constructor fail is named."""
    from posbench.predictor_options import flag_text
    from posbench.predictors.registry import create

    def build(kw: Mapping[str, Any]) -> BaseException | None:
        try:
            create(name, None, **kw)
        except Exception as e:  # noqa: BLE001 - ValueError, DataError, onnxruntime's own types
            return e
        return None

    exc = build(opts)
    if exc is None:
        return
    base = {k: v for k, v in opts.items() if k == "model"}
    others = [k for k in opts if k != "model"]
    if not others or build(base) is not None:  # the predictor itself, or its model file
        flag = flag_text(given, name, "model", as_given["model"]) if "model" in opts else None
        raise UsageError(_load_failure(name, as_given.get("model"), opts.get("model"), exc, flag))
    kw = dict(base)
    for k in others:
        kw[k] = opts[k]
        failed = build(kw)
        if failed is not None:
            raise UsageError(f"{flag_text(given, name, k, as_given.get(k))}: predictor {name} "
                             f"rejects {k}={opts[k]!r}: {_failure_detail(failed)}")
    raise UsageError(f"predictor {name} cannot be created with "
                     f"{', '.join(flag_text(given, name, k, as_given.get(k)) for k in others)}: "
                     f"{_failure_detail(exc)}")


#: what ``--format`` may list: report.md is always written; csv and latex add table files
REPORT_FORMATS = ("md", "csv", "latex")
#: table file formats beside report.md: full-precision CSV, booktabs LaTeX (the default: both)
TABLE_FORMATS = ("csv", "latex")


def parse_report_formats(text: str, option: str = "--format") -> tuple[str, ...]:
    """``--format md,csv,latex`` -> the table file formats to write beside report.md
    (``("csv", "latex")``; ``md`` alone: none)."""
    items = [f.strip().lower() for f in text.split(",") if f.strip()]
    if not items:
        raise UsageError(f"{option}: give one or more of {', '.join(REPORT_FORMATS)}")
    for f in items:
        if f not in REPORT_FORMATS:
            raise UsageError(f"{option}: unknown format {f!r}; use one or more of "
                             f"{', '.join(REPORT_FORMATS)} (e.g. md,csv)")
    return tuple(f for f in REPORT_FORMATS[1:] if f in items)
