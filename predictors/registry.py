"""Names -> predictor classes: built-ins, entry points of installed packages, import paths.

A predictor is named in one of three ways, resolved in this order:

- a **built-in** (or :func:`~posbench.predictors.catalogue.register`-ed) name: ``cv``,
  ``kf``, ``lstm``, ... (:mod:`posbench.predictors.catalogue`);
- an **entry point** of the group ``posbench.predictors`` that an installed
  distribution declares (``name = module:Class`` in its ``entry_points.txt``); a
  built-in name always wins over an entry point of the same name;
- an **import path** ``module:Class`` (``mypkg.mymodule:MyPredictor``) of a
  :class:`~posbench.predictors.base.Predictor` subclass importable from ``sys.path``.

Any of them may carry an alias, ``NAME@ALIAS``: a second instance under its own name.
Everything is imported lazily: listing names reads distribution metadata only, and a
class is imported when it is needed (filterpy costs ~2 s; a broken plugin must not
break a run that does not use it). Every failure is a :class:`PredictorError` with
one line naming the predictor and what is wrong.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from posbench.predictors.base import Predictor
from posbench.predictors.catalogue import ENTRY_POINT, IMPORT_PATH, REGISTRY, Entry

#: the entry-point group installed packages declare their predictors in
ENTRY_POINT_GROUP = "posbench.predictors"

#: the tuned noise parameters per predictor and GPS condition (``bench tune`` writes them)
TUNED_FILE = Path(__file__).with_name("tuned.json")

#: separates a predictor name from an instance alias: ``lstm@mine`` is ``lstm`` under its own name
ALIAS_SEP = "@"

_IDENT = r"[A-Za-z_]\w*"
_IMPORT_PATH = re.compile(rf"{_IDENT}(\.{_IDENT})*:{_IDENT}(\.{_IDENT})*")
#: names an entry point may declare: usable in ``--predictors a,b`` and ``--set NAME.OPT=V``
_EP_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")


class PredictorError(Exception):
    """A predictor name that cannot be resolved or loaded: unknown, malformed, not
    importable, not a Predictor subclass. One line naming the predictor."""


#: a constructor parameter of this name receives the run's GPS condition (:func:`create`)
CONDITION_PARAM = "gps_condition"


# ------------------------------------------------------------------- entry points
@dataclass(frozen=True)
class _Plugins:
    entries: dict[str, Entry]
    notes: tuple[str, ...]


_plugins_cache: dict[tuple[str, ...], _Plugins] = {}


def _plugins() -> _Plugins:
    """The entry points of :data:`ENTRY_POINT_GROUP` (metadata only: nothing is imported),
    and notes on those left out. Cached per ``sys.path``."""
    key = tuple(sys.path)
    if key not in _plugins_cache:
        _plugins_cache.clear()
        _plugins_cache[key] = _read_entry_points()
    return _plugins_cache[key]


def _read_entry_points() -> _Plugins:
    try:
        eps = list(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))
    except Exception as e:  # noqa: BLE001 - a malformed installation must not break a run
        return _Plugins(
            {}, (f"entry points of group {ENTRY_POINT_GROUP} cannot be read: {_raised(e)}",)
        )
    entries: dict[str, Entry] = {}
    notes: list[str] = []
    for ep in eps:
        dist = getattr(ep, "dist", None)
        who = f"{dist.name} {dist.version}" if dist is not None else "unknown distribution"
        if not _EP_NAME.fullmatch(ep.name):
            notes.append(
                f"entry point {ep.name!r} of {who} is ignored: a predictor name "
                "takes letters, digits and _ . + - only"
            )
        elif ep.name in REGISTRY:
            notes.append(
                f"entry point {ep.name} of {who} is ignored: {ep.name} is "
                f"{REGISTRY[ep.name].source}"
            )
        elif ep.name in entries:
            notes.append(
                f"entry point {ep.name} of {who} is ignored: "
                f"{entries[ep.name].distribution} declares {ep.name} too"
            )
        else:
            target = f"{ep.module}:{ep.attr}" if ep.attr else ep.value.strip()  # no [extras]
            entries[ep.name] = Entry(target, "", source=ENTRY_POINT, distribution=who)
    return _Plugins(entries, tuple(notes))


def entry_point_notes() -> tuple[str, ...]:
    """Entry points of :data:`ENTRY_POINT_GROUP` that are left out, and why (one line each)."""
    return _plugins().notes


# ------------------------------------------------------------------------ names
def base_name(name: str) -> str:
    """The predictor behind ``name``: ``lstm@mine`` -> ``lstm``; ``kf`` -> ``kf``;
    ``mypkg.mod:Cls@fast`` -> ``mypkg.mod:Cls``.

    An alias lets one run hold two instances of one predictor with different options
    (e.g. two LSTM models), each reported under its full name.
    """
    return name.split(ALIAS_SEP, 1)[0]


def is_import_path(name: str) -> bool:
    """Whether ``name`` (or its base, for an alias) is written as an import path
    ``module:Class`` (well formed or not: it holds a ``:``)."""
    return ":" in base_name(name)


def available() -> dict[str, Entry]:
    """Every predictor that can be named without an import path: the built-ins (and
    :func:`~posbench.predictors.catalogue.register`-ed ones), then the entry points of
    installed distributions. Nothing is imported."""
    out = dict(REGISTRY)
    out.update((n, e) for n, e in _plugins().entries.items() if n not in out)
    return out


def is_known(name: str) -> bool:
    """Whether ``name`` (or, for an alias, its base) is a built-in, registered or entry-point
    name, and the alias (if any) is non-empty. Import paths are not "known": see :func:`resolve`."""
    base, sep, alias = name.partition(ALIAS_SEP)
    return base in available() and (not sep or bool(alias.strip()))


def known_names_text() -> str:
    """The names that can be used, for an error message."""
    return ", ".join(sorted(available()))


def resolve(name: str) -> Entry:
    """The :class:`~posbench.predictors.catalogue.Entry` behind ``name`` (``NAME``,
    ``NAME@ALIAS``, ``module:Class``, ``module:Class@ALIAS``), without importing anything.
    Raises :class:`PredictorError` for an unknown name, an empty alias or a malformed import
    path."""
    base, sep, alias = name.partition(ALIAS_SEP)
    if sep and not alias.strip():
        raise PredictorError(
            f"unknown predictor {name!r}: the alias after {ALIAS_SEP} is empty "
            f"(NAME{ALIAS_SEP}ALIAS runs a second instance)"
        )
    if ":" in base:
        if not _IMPORT_PATH.fullmatch(base):
            raise PredictorError(
                f"{base!r} is not a predictor name: expected a registered name "
                "or module:Class (e.g. mypkg.mymodule:MyPredictor)"
            )
        return Entry(base, "", source=IMPORT_PATH)
    entry = available().get(base)
    if entry is None:
        raise PredictorError(
            f"unknown predictor {base!r}; known: {known_names_text()} (or "
            f"module:Class for a Predictor subclass of your own; "
            f"NAME{ALIAS_SEP}ALIAS runs a second instance)"
        )
    return entry


# ---------------------------------------------------------------------- classes
def _raised(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0][:300]}" if text else type(exc).__name__


#: what posbench 0.1 installed at the top of site-packages; since 0.2 all of it is posbench
OLD_TOP_LEVEL = {
    "predictors": "posbench.predictors",
    "scenarios": "posbench.scenarios",
    "metrics": "posbench.metrics",
    "bench": "posbench",
}


def _renamed_hint(missing: str | None) -> str:
    """For a plugin that still imports a package posbench 0.1 installed at the top (``from
    predictors.base import Predictor``): the name to import instead."""
    if missing is None:
        return ""
    top = missing.partition(".")[0]
    if top not in OLD_TOP_LEVEL:
        return ""
    new = OLD_TOP_LEVEL[top] + missing[len(top) :]
    return (
        f" (posbench 0.2 installs its packages under posbench: import {new} instead of {missing})"
    )


def _import_target(target: str, label: str, hint: bool = True) -> Any:
    """The object at ``module:attr.attr`` (``label`` starts every error line; ``hint``: say
    where a missing module is looked for)."""
    mod_name, _, attr = target.partition(":")
    if not mod_name or not attr:
        raise PredictorError(f"{label}: {target!r} is not module:Class")
    try:
        obj: Any = importlib.import_module(mod_name)
    except ModuleNotFoundError as e:
        if e.name == mod_name or mod_name.startswith(f"{e.name}."):
            where = (
                " (put the folder that holds it on PYTHONPATH, or run from that folder)"
                if hint
                else ""
            )
            raise PredictorError(f"{label}: no module named {mod_name!r}{where}") from None
        raise PredictorError(
            f"{label}: importing {mod_name} raised {_raised(e)}{_renamed_hint(e.name)}"
        ) from None
    except Exception as e:  # noqa: BLE001 - the plugin's own import error, in one line
        raise PredictorError(f"{label}: importing {mod_name} raised {_raised(e)}") from None
    where = mod_name
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise PredictorError(f"{label}: module {where} has no {part!r}")
        obj = getattr(obj, part)
        where = f"{where}.{part}"
    return obj


def load_class(entry: Entry, name: str) -> type[Predictor]:
    """Import the class of ``entry`` (named ``name``), checking it is a Predictor subclass."""
    label = (
        name
        if entry.source == IMPORT_PATH
        else (
            f"predictor {name} (entry point {entry.target} of {entry.distribution})"
            if entry.source == ENTRY_POINT
            else f"predictor {name}"
        )
    )
    cls = _import_target(entry.target, label, hint=entry.source == IMPORT_PATH)
    if not isinstance(cls, type):
        raise PredictorError(
            f"{label}: {entry.target.partition(':')[2]} is not a class (it is "
            f"a {type(cls).__name__}); expected a Predictor subclass"
        )
    if not issubclass(cls, Predictor):
        raise PredictorError(
            f"{label}: {cls.__name__} is not a subclass of posbench.predictors.base.Predictor"
        )
    return cls


def predictor_class(name: str) -> type[Predictor]:
    """The class behind ``name`` (see :func:`resolve`); raises :class:`PredictorError`."""
    return load_class(resolve(name), base_name(name))


def description(name: str) -> str:
    """One line describing ``name``: the registry's text for a built-in, else the first
    line of the class docstring (this imports the class; raises :class:`PredictorError`)."""
    entry = resolve(name)
    if entry.description:
        return entry.description
    doc = inspect.getdoc(predictor_class(name)) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def constructor_options(cls: type[Predictor]) -> tuple[dict[str, Any], bool]:
    """The keyword options ``cls(...)`` takes, with their defaults (``inspect.Parameter.empty``
    when required), and whether it takes any keyword at all (``**kwargs``).

    A class whose ``**kwargs`` are named options of its own (the Kalman filters' flat names,
    :class:`~posbench.predictors.kalman.inputs.FlatNames`) says which by a classmethod
    ``flat_options()`` (name -> default): those are listed too, and it takes no others."""
    try:
        params = inspect.signature(cls).parameters.values()
    except (TypeError, ValueError):  # no signature to read: accept anything
        return {}, True
    options = {
        p.name: p.default for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }
    flat = getattr(cls, "flat_options", None)
    if callable(flat):
        return {**flat(), **options}, False  # the flat names first: what users set
    return options, any(p.kind is p.VAR_KEYWORD for p in params)


# ----------------------------------------------------------------------- create
#: the parsed tuning files, by (path, modification time)
_tuning_cache: dict[tuple[str, int], dict[str, Any]] = {}


def read_tuning(path: Path | str) -> dict[str, Any]:
    """A tuning file (``bench tune --out``, or the package's :data:`TUNED_FILE`):
    ``{predictor: {gps_condition: {"params": {...}, "how": str, "drives": [...]}}}``.
    Raises :class:`PredictorError` naming the file when it is missing or malformed."""
    path = Path(path)
    try:
        key = (str(path.resolve()), path.stat().st_mtime_ns)
    except OSError as e:
        raise PredictorError(f"tuning file {path}: {e.strerror or e}") from None
    if key not in _tuning_cache:
        try:
            data = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise PredictorError(f"tuning file {path}: not readable JSON ({e})") from None
        ok = isinstance(data, dict) and all(
            isinstance(conds, dict)
            and all(
                isinstance(e, dict) and isinstance(e.get("params", {}), dict)
                for e in conds.values()
            )
            for conds in data.values()
        )
        if not ok:
            raise PredictorError(
                f"tuning file {path}: expected {{predictor: {{gps condition: "
                f'{{"params": {{...}}}}}}}} as `bench tune --out` writes'
            )
        _tuning_cache[key] = data
    return _tuning_cache[key]


def tuning_entry(
    name: str, condition: str | None, tuning: Path | str | None = None
) -> tuple[Path, dict[str, Any]] | None:
    """(file, entry) of the tuning ``name`` gets under a GPS ``condition`` (``none``,
    ``rtk``, ``consumer``, ``native``): the entry of the user's ``tuning`` file if it holds
    one, else the package's :data:`TUNED_FILE`; None where neither does (the predictor's
    defaults) or ``condition`` is None."""
    if condition is None:
        return None
    for path in ([Path(tuning)] if tuning else []) + [TUNED_FILE]:
        if path == TUNED_FILE and not path.exists():
            continue
        entry = read_tuning(path).get(name, {}).get(condition)
        if entry is not None:
            return path, entry
    return None


def tuned_params(
    name: str, condition: str | None, tuning: Path | str | None = None
) -> dict[str, Any]:
    """Tuned parameters of ``name`` for a GPS condition (:func:`tuning_entry`); empty if
    none were tuned."""
    found = tuning_entry(name, condition, tuning)
    return dict(found[1].get("params", {})) if found else {}


def create(
    name: str, condition: str | None = None, *, tuning_file: Path | str | None = None, **config: Any
) -> Predictor:
    """A new predictor ``name`` (any form :func:`resolve` takes): its registry defaults, then
    tuned parameters for the GPS ``condition`` (if given and tuned; from ``tuning_file``
    where it holds them, else the package's), then ``config``.

    A class whose constructor declares a parameter :data:`CONDITION_PARAM`
    (``gps_condition``) also receives ``gps_condition=condition`` (None included) unless
    ``config`` sets it: a predictor that keeps per-condition parameters of its own (the
    ``hybrid``'s prior, recorded in its model) picks them itself.

    Every option is parsed by its declared type
    (:func:`posbench.predictors.option_types.parse_options`): ``use_imu="no"`` is False, and
    a value an option does not take (``use_imu="maybe"``) raises
    :class:`~posbench.predictors.option_types.OptionValueError`, one line naming it."""
    from posbench.predictors.option_types import parse_options

    entry = resolve(name)
    cls = load_class(entry, base_name(name))
    kwargs = {**entry.defaults, **tuned_params(base_name(name), condition, tuning_file), **config}
    if CONDITION_PARAM not in kwargs and CONDITION_PARAM in constructor_options(cls)[0]:
        kwargs[CONDITION_PARAM] = condition
    return cls(**parse_options(cls, kwargs))
