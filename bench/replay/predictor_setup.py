"""Which predictors a run builds, and with which constructor options (as the command line
gives them: :mod:`posbench.replay.predictor_options`).

Every name and option is checked, and every predictor built once, before any drive is loaded
(:func:`validate_predictors`); :func:`plan_predictors` also asks those instances which
learned model they use and which drives it was trained on, so ``bench run`` builds each
predictor once at plan time (:func:`learned_models` builds them for that alone). A
``--tuning`` file is checked entry by entry the same way (:func:`check_tuning_file`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from posbench.config import RunConfig
from posbench.errors import UsageError
from posbench.predictors.base import Predictor
from posbench.replay.predictor_options import check_option_names, flag_text
from posbench.scenarios.errors import DataError
from posbench.scenarios.text import quoted


# -------------------------------------------------------------- predictors
def build_predictor(cfg: RunConfig, name: str, condition: str | None) -> Predictor:
    """Predictor ``name`` as run ``cfg`` builds it for a drive replayed under GPS
    ``condition`` (:func:`posbench.config.gps_condition`): its defaults, then its tuned
    parameters for that condition where the run uses them (``cfg.tuning`` over the
    package's), then ``cfg.predictor_options``. The one factory of the replay workers, the
    paper figures and the learned-model record, so each builds the predictor the run scores
    (the checks at plan time build it option by option, to name the one to blame)."""
    from posbench.predictors.registry import create

    return create(
        name,
        condition if cfg.use_tuned else None,
        tuning_file=cfg.tuning,
        **cfg.predictor_options.get(name, {}),
    )


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
    from posbench.predictors.registry import predictor_class

    out: dict[str, dict[str, Any]] = {}
    for name in cfg.predictors:
        if not _declares_model(predictor_class(name)):
            continue  # no learned model: not worth building (an ONNX session, ...)
        model = _learned_model(build_predictor(cfg, name, None))
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
