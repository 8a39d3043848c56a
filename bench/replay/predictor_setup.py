"""Which predictors a run builds, and with which constructor options.

``--set NAME.OPTION=VALUE`` (:func:`parse_set`): ``NAME`` is a predictor of the run as
written in ``--predictors`` (``kf``, ``kf@slow``, ``mypkg.mymodule:MyPredictor``); the text
before ``=`` is split at its LAST ``.``, so ``--set kf@v1.2.jerk_psd=4`` sets ``jerk_psd`` of
``kf@v1.2`` and ``--set mypkg.mod:Damped.tau_s=0.5`` sets ``tau_s`` of ``mypkg.mod:Damped``
(option names are Python identifiers: they never hold a dot). ``VALUE`` is read as a JSON
literal (``4``, ``0.5``, ``true``, ``null``, ``"text"``, ``[1, 2]``); anything that is not JSON
is taken as a string (``--set lstm.fit=lbfgs``).

``--model NAME=PATH`` (:func:`model_options`) is the same as ``--set NAME.model=PATH``; both
may be given only if they name the same file (:func:`merge_options`). Every name and option
is checked, and every predictor built once, before any drive is loaded
(:func:`validate_predictors`); :func:`plan_predictors` also asks those instances which
learned model they use and which drives it was trained on, so ``bench run`` builds each
predictor once at plan time (:func:`learned_models` builds them for that alone).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from posbench.config import RunConfig
from posbench.errors import UsageError
from posbench.predictors.base import Predictor
from posbench.scenarios.errors import DataError
from posbench.scenarios.text import quoted

#: how a user gave each option: ``(predictor, option) -> "--set kf.jerk_psd=4"``, for messages
Given = dict[tuple[str, str], str]
EXAMPLE = "e.g. --set kf.jerk_psd=4.0"


#: the first characters of a value meant as JSON (an object, a list, a quoted text): such a
#: value that does not parse is a mistake to name, never a bare word
JSON_STARTS = ("{", "[", '"')


def parse_value(text: str) -> Any:
    """A ``--set`` value: the JSON literal it spells, else the text itself (a bare word such
    as ``lbfgs`` or ``no``; the option's declared type decides what it means).

    Raises:
        ValueError: text that starts as JSON does (``{``, ``[``, ``"``) but does not parse,
            with the parser's reason and column.
    """
    try:
        return json.loads(text)
    except ValueError as e:
        if text.lstrip().startswith(JSON_STARTS):
            reason = getattr(e, "msg", str(e))
            col = getattr(e, "colno", None)
            raise ValueError(
                f"{quoted(text)} is not valid JSON ({reason}"
                f"{f' at column {col}' if col else ''}); quote it for the shell, "
                """e.g. --set 'kf.imu={"gate": 0}'"""
            ) from None
        return text


def parse_set(values: Sequence[str] | None) -> tuple[dict[str, dict[str, Any]], Given]:
    """``--set NAME.OPTION=VALUE`` strings as ``{name: {option: value}}`` (in the order given),
    with the text of each as given (for messages). Raises :class:`UsageError` (one line)."""
    options: dict[str, dict[str, Any]] = {}
    given: Given = {}
    for text in values or []:
        flag = f"--set {text}"
        key, eq, value = text.partition("=")
        key = key.strip()
        if not eq:
            raise UsageError(f"{flag}: expected NAME.OPTION=VALUE, {EXAMPLE}")
        name, dot, option = key.rpartition(".")
        if not dot:
            raise UsageError(f"{flag}: names no option; expected NAME.OPTION=VALUE, {EXAMPLE}")
        if not name:
            raise UsageError(f"{flag}: names no predictor; expected NAME.OPTION=VALUE, {EXAMPLE}")
        if not option.isidentifier():
            raise UsageError(
                f"{flag}: {option!r} is not an option name (a Python identifier); "
                f"expected NAME.OPTION=VALUE, {EXAMPLE}"
            )
        if not value.strip():
            raise UsageError(f"{flag}: no value; write '\"\"' for an empty text, {EXAMPLE}")
        if (name, option) in given:
            raise UsageError(f"{flag}: {name}.{option} is set twice (also {given[name, option]})")
        try:
            options.setdefault(name, {})[option] = parse_value(value.strip())
        except ValueError as e:
            raise UsageError(f"{flag}: {e}") from None
        given[name, option] = flag
    return options, given


def _same_file(a: Any, b: Any) -> bool:
    """Whether two model values name the same file (a folder stands for its model.onnx)."""

    def norm(v: Any) -> str:
        p = Path(str(v))
        p = p / "model.onnx" if p.is_dir() else p
        return os.path.realpath(p)

    return norm(a) == norm(b)


_MISSING = object()


def merge_options(
    models: Mapping[str, Mapping[str, Any]], sets: Mapping[str, Mapping[str, Any]], given: Given
) -> tuple[dict[str, dict[str, Any]], Given]:
    """``--model`` options and ``--set`` options as one ``{name: {option: value}}``, with
    the text of each option as given. ``--model lstm=A`` with ``--set lstm.model=B`` is an
    error unless A and B name the same file."""
    merged = {n: dict(o) for n, o in models.items()}
    out_given: Given = {(n, k): f"--model {n}={v}" for n, o in models.items() for k, v in o.items()}
    for name, opts in sets.items():
        for option, value in opts.items():
            flag = flag_text(given, name, option, value)
            before = merged.get(name, {}).get(option, _MISSING)
            if before is not _MISSING and not (option == "model" and _same_file(before, value)):
                raise UsageError(f"{out_given[name, option]} and {flag} disagree; give one of them")
            merged.setdefault(name, {})[option] = value
            out_given.setdefault((name, option), flag)
    return merged, out_given


def model_options(models: Mapping[str, str | Path]) -> dict[str, dict[str, str]]:
    """``--model NAME=PATH`` (name -> path) as per-predictor constructor options; a folder
    PATH holding a ``model.onnx`` (what ``bench train --out`` writes) stands for that file."""
    out = {}
    for name, path in models.items():
        onnx = Path(path) / "model.onnx"
        out[name] = {"model": str(onnx) if onnx.is_file() else str(path)}
    return out


def flag_text(given: Mapping[tuple[str, str], str], name: str, option: str, value: Any) -> str:
    """How option ``option`` of ``name`` was given (``--model NAME=PATH`` when unknown)."""
    return given.get((name, option)) or (
        f"--model {name}={value}" if option == "model" else f"--set {name}.{option}={value}"
    )


def check_option_names(
    name: str, options: Mapping[str, Any], given: Mapping[tuple[str, str], str]
) -> None:
    """Every option in ``options`` is a keyword of the constructor of predictor ``name``
    (found with :func:`inspect.signature`; a constructor with ``**kwargs`` takes any)."""
    from posbench.predictors.registry import constructor_options, predictor_class

    accepted, any_keyword = constructor_options(predictor_class(name))
    if any_keyword:
        return
    for option, value in options.items():
        if option not in accepted:
            takes = f"its options: {', '.join(accepted)}" if accepted else "it takes no options"
            raise UsageError(
                f"{flag_text(given, name, option, value)}: predictor {name} has no "
                f"option {option!r}; {takes} (see `bench predictors {name}`)"
            )


# -------------------------------------------------------------- predictors
def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:300] if text else type(exc).__name__


def _failure_detail(exc: BaseException) -> str:
    """``Type: first line`` of an exception (a DataError's or an option value's own line,
    without its type: both are written for the user)."""
    from posbench.predictors.option_types import OptionValueError

    return (
        _first_line(exc)
        if isinstance(exc, DataError | OptionValueError)
        else f"{type(exc).__name__}: {_first_line(exc)}"
    )


def _load_failure(
    name: str, given: Any, path: str | None, exc: BaseException, flag: str | None = None
) -> str:
    """One line: which predictor (and model file, given as ``flag``) could not be built, and why."""

    if isinstance(exc, DataError):
        # the path is in the message already unless it is the model file itself
        detail = (
            exc.detail
            if exc.path is not None and exc.path in (str(given), path)
            else _first_line(exc)
        )
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


def validate_predictors(
    names: Sequence[str],
    options: Mapping[str, Mapping[str, Any]],
    given: Mapping[tuple[str, str], str] | None = None,
) -> dict[str, dict[str, Any]]:
    """Check the requested predictors and their constructor options before any work.

    Each name must be a built-in, an entry point or an importable ``module:Class`` of a
    Predictor subclass (:func:`posbench.predictors.registry.resolve`), each option set must belong
    to a requested name and name a keyword of its constructor, a ``model`` path must exist (a
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
    return plan_predictors(names, options, given)[0]


def _check_predictors(
    names: Sequence[str],
    options: Mapping[str, Mapping[str, Any]],
    given: Mapping[tuple[str, str], str],
) -> dict[str, dict[str, Any]]:
    """Every check of :func:`validate_predictors` but building: the options with ``model``
    folders resolved."""
    from posbench.predictors.registry import (
        PredictorError,
        base_name,
        is_import_path,
        is_known,
        known_names_text,
        predictor_class,
    )

    unknown = [n for n in names if not is_import_path(n) and not is_known(n)]
    if unknown:
        raise UsageError(
            f"unknown predictor(s) {', '.join(unknown)}; known: "
            f"{known_names_text()} (NAME@ALIAS runs a second instance; "
            "module:Class a Predictor subclass of your own)"
        )
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
        hint = (
            f"add it, or use {alias} for a second {n}"
            if is_known(n) or n in names
            else "add it to --predictors"
        )
        raise UsageError(
            f"{flag_text(given, n, option, value)}: {n} is not among the "
            f"predictors to run ({', '.join(names)}); {hint}"
        )
    for n in names:
        if base_name(n) == "lstm-authors" and "model" not in options.get(n, {}):
            raise UsageError(
                f"{n} needs the authors' network: --model {n}=PATH.onnx "
                "(e.g. ../shared/models/authors/gps_interpolation_model2.onnx)"
            )
    for name, opts in options.items():
        check_option_names(name, opts, given)
    resolved: dict[str, dict[str, Any]] = {}
    for name, opts in options.items():
        resolved[name] = typed_options(name, opts, given)
        if "model" in opts:
            resolved[name]["model"] = _model_path(name, opts["model"])
    return resolved


def typed_options(
    name: str, options: Mapping[str, Any], given: Mapping[tuple[str, str], str]
) -> dict[str, Any]:
    """``options`` of predictor ``name`` parsed by their declared types
    (:func:`posbench.predictors.option_types.parse_options`: ``--set kf.use_imu=no`` is
    False); a value an option does not take is one line naming how it was given, what it
    takes and the value."""
    from posbench.predictors.option_types import OptionValueError, parse_options
    from posbench.predictors.registry import predictor_class

    try:
        return parse_options(predictor_class(name), options)
    except OptionValueError as e:
        top = e.option.split(".")[0].split("[")[0]
        raise UsageError(
            f"{flag_text(given, name, top, options.get(top))}: {name}.{e}; see "
            f"`bench predictors {name}`"
        ) from None


def plan_predictors(
    names: Sequence[str],
    options: Mapping[str, Mapping[str, Any]],
    given: Mapping[tuple[str, str], str] | None = None,
) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, Any]]]:
    """:func:`validate_predictors`, and the learned models behind the predictors
    (:func:`learned_models`), asked of the instances built for the check: every predictor
    is built once. Returns (resolved options, learned models)."""
    from posbench.predictors.registry import predictor_class

    resolved = _check_predictors(names, options, given or {})
    models: dict[str, dict[str, Any]] = {}
    for name in names:
        pred = _build_once(name, resolved.get(name, {}), options.get(name, {}), given or {})
        model = _learned_model(pred) if _declares_model(predictor_class(name)) else None
        if model is not None:
            models[name] = model
    return resolved, models


def _build_once(
    name: str,
    opts: Mapping[str, Any],
    as_given: Mapping[str, Any],
    given: Mapping[tuple[str, str], str],
) -> Predictor:
    """Predictor ``name`` built with ``opts``; a failure names the option to blame. The model
    file (if any) is tried first, then the other options are added one at a time in the order
    given: the first that makes the constructor fail is named."""
    from posbench.predictors.registry import create

    built: list[Predictor] = []

    def build(kw: Mapping[str, Any]) -> BaseException | None:
        try:
            built.append(create(name, None, **kw))
        except Exception as e:  # noqa: BLE001 - ValueError, DataError, onnxruntime's own types
            return e
        return None

    exc = build(opts)
    if exc is None:
        return built[0]
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
            raise UsageError(
                f"{flag_text(given, name, k, as_given.get(k))}: predictor {name} "
                f"rejects {k}={quoted(opts[k])}: {_failure_detail(failed)}"
            )
    raise UsageError(
        f"predictor {name} cannot be created with "
        f"{', '.join(flag_text(given, name, k, as_given.get(k)) for k in others)}: "
        f"{_failure_detail(exc)}"
    )


def learned_models(cfg: RunConfig) -> dict[str, dict[str, Any]]:
    """Per predictor of the run that declares a learned model (``lstm``, ``lstm@mine``,
    ``lstm-authors``, ...; :meth:`~posbench.predictors.base.Predictor.model_description`): the model
    file it uses, whether that is the bundled one, and the drive names the model was
    trained on (:meth:`~posbench.predictors.base.Predictor.training_drives`), so results on those
    drives can be told apart. Each predictor is created with the run's options for it
    (:func:`plan_predictors` asks the instances it built for its checks instead)."""
    from posbench.predictors.registry import create, predictor_class

    out: dict[str, dict[str, Any]] = {}
    for name in cfg.predictors:
        if not _declares_model(predictor_class(name)):
            continue  # no learned model: not worth building (an ONNX session, ...)
        model = _learned_model(create(name, None, **cfg.predictor_options.get(name, {})))
        if model is not None:
            out[name] = model
    return out


def _declares_model(cls: type[Predictor]) -> bool:
    """Whether predictor class ``cls`` overrides a learned-model seam."""
    return (
        cls.model_description is not Predictor.model_description
        or cls.training_drives is not Predictor.training_drives
    )


def _learned_model(pred: Predictor) -> dict[str, Any] | None:
    """The learned model behind ``pred`` as results.json's ``models`` holds it (model file,
    bundled, training drives), or None: it declares none."""
    desc = pred.model_description()
    drives = list(pred.training_drives())
    if desc is None and not drives:
        return None
    desc = desc or {}
    return {
        "model": str(desc.get("model", "")),
        "bundled": bool(desc.get("bundled")),
        "train_drives": drives,
    }


def check_tuning_file(
    path: Path | str | None, names: Sequence[str], options: Mapping[str, Mapping[str, Any]]
) -> None:
    """Check a ``--tuning`` file before any work: readable, shaped as ``bench tune --out``
    writes it, and each of its entries accepted by the run's predictor of that name
    (:func:`tuning_entry_refusal`: each such predictor is built once per GPS condition the
    file holds for it)."""
    if path is None:
        return
    from posbench.predictors.registry import PredictorError, base_name, read_tuning

    try:
        data = read_tuning(path)
    except PredictorError as e:
        raise UsageError(f"--tuning: {e}") from None
    for name in names:
        for condition in data.get(base_name(name), {}):
            why = tuning_entry_refusal(path, name, condition, options.get(name, {}))
            if why is not None:
                raise UsageError(f"--tuning {path}: {why}")


def tuning_entry_refusal(
    path: Path | str, name: str, condition: str, options: Mapping[str, Any]
) -> str | None:
    """Why ``bench run --tuning path`` refuses the entry of predictor ``name`` under GPS
    ``condition`` (one line, without the file's name), or None where it takes it: the
    predictor built with the file's parameters and the run's ``options`` for it. ``bench
    tune`` asks the same before it saves (:func:`posbench.predictor_tools.tuning.save_tuned`),
    so it never writes an entry the run refuses."""
    from posbench.predictors.registry import base_name, create

    try:
        create(name, condition, tuning_file=path, **options)
    except Exception as e:  # noqa: BLE001 - any constructor failure is the file's
        return (
            f"{base_name(name)} ({condition}) cannot be created with its parameters: "
            f"{_failure_detail(e)}"
        )
    return None
