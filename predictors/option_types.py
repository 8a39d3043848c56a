"""Predictor options parsed by their declared types: the one place where a value given on
the command line (``--set kf.use_imu=no``), in a config file, a tuning file or from Python
becomes what a constructor takes, or one line saying why it cannot.

An option's type is the one its constructor declares (``use_imu: bool``, ``fit:
Literal["closed", "lbfgs"]``, ``imu: AccelInput | None``, ``horizons_s: Sequence[float]``);
a class whose ``**kwargs`` are named options of its own (the Kalman filters' flat names)
declares theirs with a classmethod ``flat_option_types()`` (name -> type). Nothing else is
needed: a plugin's annotated constructor is parsed the same way, and an option declared
without a type (or with one this module does not know) is passed on as given.

What each type takes (:func:`takes_text` says it in words, for ``--help``, ``bench
predictors`` and the messages):

- ``bool``: true or false; also the words yes/no, on/off and 1/0 (any case). Nothing else:
  ``maybe``, ``[1]`` or ``{"x": 1}`` are refused, never read as true.
- ``int``: a whole number; ``float``: a finite number (never a bool, never text).
- ``str``: text; ``Literal[...]``: one of its values.
- ``Sequence[T]`` / ``tuple[T, ...]``: a list whose items each take ``T``.
- an option dataclass (``AccelInput``): an object of its fields (``{"gate": 0}``), each
  parsed by the field's type; its own instance as it is.
- ``X | None``: ``null`` as well as what ``X`` takes.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import numbers
import os
import sys
import types
import typing
from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import Any, Literal, get_args, get_origin

#: the words a yes/no option takes besides JSON's true and false (compared in lower case)
TRUE_WORDS = ("true", "yes", "on", "1")
FALSE_WORDS = ("false", "no", "off", "0")
BOOL_TEXT = "true or false (also yes/no, on/off, 1/0)"


class OptionValueError(ValueError):
    """A value an option does not take. ``str()`` is one line: the option (``imu.gate``),
    what it takes, and the value given."""

    def __init__(self, option: str, value: Any, takes: str, message: str | None = None) -> None:
        self.option, self.value, self.takes, self.message = option, value, takes, message
        super().__init__(message or f"{option} takes {takes}, not {shown(value)}")

    def __reduce__(self) -> tuple[Any, ...]:
        # pickle (worker processes, Ray) rebuilds from ``args`` = (text,) by default, which
        # does not fit ``__init__``: rebuild it from its own arguments
        return type(self), (self.option, self.value, self.takes, self.message)


def shown(value: Any) -> str:
    """A value as a user would write it: JSON where it is JSON (``null``, ``true``,
    ``[1]``), else Python's repr (``'maybe'``)."""
    if isinstance(value, str):
        return repr(value)
    try:
        return json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        return repr(value)


# ------------------------------------------------------------------ declared types
def _resolve(annotation: Any, module: str) -> Any:
    """An annotation as a type (a string one evaluated in ``module``'s namespace); ``Any``
    where it cannot be resolved (a name imported only for type checking)."""
    if annotation is inspect.Parameter.empty:
        return Any
    if not isinstance(annotation, str):
        return annotation
    namespace = {**vars(typing), **vars(sys.modules[module])} if module in sys.modules else {}
    try:
        return eval(annotation, namespace)  # noqa: S307 - the class's own annotation text
    except Exception:  # noqa: BLE001 - an annotation we cannot evaluate is not checked
        return Any


@lru_cache(maxsize=256)
def declared_types(cls: type) -> dict[str, Any]:
    """Option name -> declared type of ``cls``'s constructor (keyword parameters), plus the
    flat options ``cls.flat_option_types()`` declares; ``Any`` where none is declared."""
    try:
        params = inspect.signature(cls).parameters.values()
    except (TypeError, ValueError):
        return {}
    init = getattr(cls, "__init__", None)
    module = getattr(init, "__module__", None) or cls.__module__
    out = {
        p.name: _resolve(p.annotation, module)
        for p in params
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }
    flat = getattr(cls, "flat_option_types", None)
    if callable(flat):
        out = {**flat(), **out}
    return out


def declared_meanings(cls: type) -> dict[str, str]:
    """Option name -> what it means (its doc, unit and range in one line), for the options
    ``cls.flat_option_docs()`` declares; none for the others."""
    docs = getattr(cls, "flat_option_docs", None)
    return {name: d.text() for name, d in docs().items()} if callable(docs) else {}


@lru_cache(maxsize=64)
def field_types(cls: type) -> dict[str, Any]:
    """Field name -> type of an option dataclass."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(cls)}


# ------------------------------------------------------------------ parsing
def _is_union(tp: Any) -> bool:
    return get_origin(tp) in (typing.Union, types.UnionType)


def _is_sequence(tp: Any) -> bool:
    origin = get_origin(tp)
    return origin in (tuple, list, Sequence, typing.Sequence) or (
        isinstance(origin, type) and origin is not str and issubclass(origin, Sequence)
    )


def _item_type(tp: Any) -> Any:
    args = [a for a in get_args(tp) if a is not Ellipsis]
    return args[0] if args else Any


def takes_text(tp: Any) -> str:
    """What an option of type ``tp`` takes, in words (``true or false (also yes/no, on/off,
    1/0)``, ``a number``, ``one of 'closed', 'lbfgs'``, ``a list of numbers or null``)."""
    if tp is Any or tp is object:
        return "any value"
    if _is_union(tp):
        args = get_args(tp)
        parts = [takes_text(a) for a in args if a is not type(None)]
        text = " or ".join(parts)
        return f"{text} or null" if type(None) in args else text
    if get_origin(tp) is Literal:
        return "one of " + ", ".join(shown(v) for v in get_args(tp))
    if tp is bool:
        return BOOL_TEXT
    if tp is int:
        return "a whole number"
    if tp is float:
        return "a number"
    if tp is str:
        return "text"
    if _is_sequence(tp):
        item = _item_type(tp)
        inner = {
            float: "numbers",
            int: "whole numbers",
            str: "texts",
            bool: "true/false values",
        }.get(item)
        return f"a list of {inner}" if inner else f"a list (each item {takes_text(item)})"
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return f"an object of {tp.__name__} fields ({', '.join(field_types(tp))})"
    return f"a {getattr(tp, '__name__', str(tp))}"


def _is_bool(value: Any) -> bool:
    """A bool, Python's or numpy's."""
    return isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b"


def parse_bool(option: str, value: Any) -> bool:
    """``value`` as a yes/no option takes it (module docstring), else OptionValueError."""
    if _is_bool(value):
        return bool(value)
    if isinstance(value, numbers.Integral) and value in (0, 1):
        return bool(value)
    if isinstance(value, str):
        word = value.strip().lower()
        if word in TRUE_WORDS:
            return True
        if word in FALSE_WORDS:
            return False
    raise OptionValueError(option, value, BOOL_TEXT)


def parse_value(option: str, value: Any, tp: Any) -> Any:
    """``value`` parsed as option ``option`` of declared type ``tp`` (module docstring).

    Raises:
        OptionValueError: a value the type does not take (one line naming the option).
    """
    if tp is Any or tp is object or tp is None:
        return value
    if _is_union(tp):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        choices = [a for a in args if a is not type(None)]
        errors = []
        for arg in choices:
            try:
                return parse_value(option, value, arg)
            except OptionValueError as e:
                errors.append(e)
        nested = [e for e in errors if e.option != option]
        if len(choices) == 1 and nested:  # X | None given an X with a bad field: name it
            raise nested[0]
        raise OptionValueError(option, value, takes_text(tp))
    if get_origin(tp) is Literal:
        if isinstance(value, str | int | float) and not isinstance(value, bool):
            for c in get_args(tp):
                if value == c and type(value) is type(c):
                    return c
        raise OptionValueError(option, value, takes_text(tp))
    if tp is bool:
        return parse_bool(option, value)
    if tp is int:
        if isinstance(value, numbers.Integral) and not _is_bool(value):
            return int(value)
        if isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer():
            return int(float(value))
        raise OptionValueError(option, value, "a whole number")
    if tp is float:
        if isinstance(value, numbers.Real) and not _is_bool(value):
            if math.isfinite(value):
                return float(value)
            raise OptionValueError(option, value, "a finite number")
        raise OptionValueError(option, value, "a number")
    if tp is str:
        if isinstance(value, str | os.PathLike):  # a model's path may come as a Path
            return value
        raise OptionValueError(option, value, "text")
    if _is_sequence(tp):
        if isinstance(value, list | tuple):
            item = _item_type(tp)
            return tuple(parse_value(f"{option}[{i}]", v, item) for i, v in enumerate(value))
        raise OptionValueError(option, value, takes_text(tp))
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _parse_fields(option, value, tp)
    return value  # a type this module does not know (a Path, a class of a plugin's)


def _parse_fields(option: str, value: Any, cls: type) -> Any:
    """An option dataclass given as itself (kept) or as an object of its fields, each parsed
    by its type (returned as a dict; the constructor applies it to its default)."""
    if isinstance(value, cls):
        return value
    if not isinstance(value, Mapping):
        raise OptionValueError(option, value, takes_text(cls))
    fields = field_types(cls)
    out = {}
    for key, v in value.items():
        if key not in fields:
            known = ", ".join(fields)
            raise OptionValueError(
                f"{option}.{key}",
                v,
                takes_text(cls),
                f"{option} has no field {key!r}; {cls.__name__}'s fields: {known}",
            )
        out[key] = parse_value(f"{option}.{key}", v, fields[key])
    return out


def parse_options(cls: type, options: Mapping[str, Any]) -> dict[str, Any]:
    """``options`` for ``cls``'s constructor, each parsed by its declared type
    (:func:`declared_types`); an option ``cls`` does not declare is passed on as given (the
    constructor refuses it, or takes it through ``**kwargs``).

    Raises:
        OptionValueError: the first value its option does not take.
    """
    declared = declared_types(cls)
    return {k: parse_value(k, v, declared.get(k, Any)) for k, v in options.items()}
