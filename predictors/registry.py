"""Names -> predictor factories with their default configuration.

Entries are imported lazily (``module:Class``) so that listing or running one
predictor does not pay for the imports of the others (filterpy ~2 s).
"""

from __future__ import annotations

import importlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from predictors.base import Predictor


@dataclass(frozen=True)
class Entry:
    """A registered predictor: where its class lives, its defaults, a one-line description."""

    target: str
    description: str
    defaults: dict[str, Any] = field(default_factory=dict)


_REGISTRY: dict[str, Entry] = {
    "cv": Entry("predictors.cv:ConstantVelocity",
                "constant velocity from the last two fixes"),
    "poly": Entry("predictors.poly:PolyExtrapolator",
                  "the paper's cubic regression over recent fixes, extrapolated"),
    "kf": Entry("predictors.kf:LinearKalman",
                "linear Kalman filter, constant-acceleration state, IMU accel (world frame) as observation"),
    "kf-paper": Entry("predictors.kf_paper:PaperKalman",
                      "the paper's Kalman baseline as its authors published it"),
    "ekf": Entry("predictors.ekf:CtraEkf",
                 "extended Kalman filter, CTRA model with IMU yaw rate/accel and wheel speed"),
    "lstm": Entry("predictors.lstm.predictor:LstmPredictor",
                  "the paper's system: cubic resampling + MLP-LSTM-MLP (ONNX) + cubic"),
    "lstm-authors": Entry("predictors.lstm.authors:AuthorsLstmPredictor",
                          "the paper authors' published ONNX network (needs --model PATH)"),
}


def register(name: str, target: str, description: str, **defaults: Any) -> None:
    """Add (or replace) a predictor under ``name``; ``target`` is ``"module:Class"``."""
    _REGISTRY[name] = Entry(target, description, dict(defaults))


#: separates a registered name from an instance alias: ``lstm@mine`` is ``lstm`` under its own name
ALIAS_SEP = "@"


def base_name(name: str) -> str:
    """The registered name behind ``name``: ``lstm@mine`` -> ``lstm``; ``kf`` -> ``kf``.

    An alias lets one run hold two instances of one predictor with different options
    (e.g. two LSTM models), each reported under its full name.
    """
    return name.split(ALIAS_SEP, 1)[0]


def is_known(name: str) -> bool:
    """Whether ``name`` (or, for an alias, its base) is registered and the alias is non-empty."""
    base, sep, alias = name.partition(ALIAS_SEP)
    return base in _REGISTRY and (not sep or bool(alias.strip()))


def available() -> dict[str, Entry]:
    """All registered names and entries."""
    return dict(_REGISTRY)


def predictor_class(name: str) -> type[Predictor]:
    """The class registered under ``name`` or its base (raises KeyError listing the known names)."""
    name = base_name(name)
    if name not in _REGISTRY:
        raise KeyError(f"unknown predictor {name!r}; known: {', '.join(sorted(_REGISTRY))}")
    module, cls = _REGISTRY[name].target.split(":")
    return getattr(importlib.import_module(module), cls)


def tuned_params(name: str, condition: str | None) -> dict[str, Any]:
    """Tuned parameters of ``name`` for a GPS condition (``none``, ``rtk``, ``consumer``,
    ``native``) from ``predictors/tuned.json``; empty if none were tuned."""
    if condition is None:
        return {}
    path = Path(__file__).with_name("tuned.json")
    if not path.exists():
        return {}
    data = json.loads(path.read_text())
    return dict(data.get(name, {}).get(condition, {}).get("params", {}))


def create(name: str, condition: str | None = None, **config: Any) -> Predictor:
    """A new predictor ``name`` (a registered name or ``name@alias``): registry defaults, then
    tuned parameters for the GPS ``condition`` (if given and tuned), then ``config``."""
    cls = predictor_class(name)
    base = base_name(name)
    kwargs = {**_REGISTRY[base].defaults, **tuned_params(base, condition), **config}
    return cls(**kwargs)
