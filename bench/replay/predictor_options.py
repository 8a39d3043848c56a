"""The predictors' constructor options as the command line gives them: ``--set`` and
``--model`` parsed, merged into ``{predictor: {option: value}}`` with how each was given (for
messages), and their names checked against the predictor's constructor.

``--set NAME.OPTION=VALUE`` (:func:`parse_set`): ``NAME`` is a predictor of the run as
written in ``--predictors`` (``kf``, ``kf@slow``, ``mypkg.mymodule:MyPredictor``); the text
before ``=`` is split at its LAST ``.``, so ``--set kf@v1.2.jerk_psd=4`` sets ``jerk_psd`` of
``kf@v1.2`` and ``--set mypkg.mod:Damped.tau_s=0.5`` sets ``tau_s`` of ``mypkg.mod:Damped``
(option names are Python identifiers: they never hold a dot). ``VALUE`` is read as a JSON
literal (``4``, ``0.5``, ``true``, ``null``, ``"text"``, ``[1, 2]``); anything that is not JSON
is taken as a string (``--set lstm.fit=lbfgs``).

``--model NAME=PATH`` (:func:`model_options`) is the same as ``--set NAME.model=PATH``; both
may be given only if they name the same file (:func:`merge_options`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from posbench.errors import UsageError
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
