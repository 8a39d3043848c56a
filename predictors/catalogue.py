"""The predictors posbench knows by name: the built-in table (:data:`REGISTRY`), what
:func:`register` adds to it, and :class:`Entry`, the record a name resolves to (where its
class lives, its default options, where it comes from). Nothing here imports a predictor;
:mod:`posbench.predictors.registry` resolves names and loads classes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: where a predictor comes from (:attr:`Entry.source`)
BUILT_IN = "built-in"
REGISTERED = "registered"
ENTRY_POINT = "entry point"
IMPORT_PATH = "import path"


@dataclass(frozen=True)
class Entry:
    """A known predictor: where its class lives (``module:Class``), its default options,
    a one-line description, where it comes from (:data:`BUILT_IN`, :data:`REGISTERED`,
    :data:`ENTRY_POINT`, :data:`IMPORT_PATH`) and, for an entry point, the distribution
    that declares it (``NAME VERSION``)."""

    target: str
    description: str
    defaults: dict[str, Any] = field(default_factory=dict)
    source: str = BUILT_IN
    distribution: str | None = None


#: the built-in predictors, then the :func:`register`-ed ones: name -> entry
REGISTRY: dict[str, Entry] = {
    "cv": Entry(
        "posbench.predictors.cv:ConstantVelocity", "constant velocity from the last two fixes"
    ),
    "poly": Entry(
        "posbench.predictors.poly:PolyExtrapolator",
        "the paper's cubic regression over recent fixes, extrapolated",
    ),
    "kf": Entry(
        "posbench.predictors.kalman.kf:KalmanBank",
        "linear Kalman filters (constant acceleration; IMU-aided and fixes-only, "
        "4 process noises), the one that predicts the fixes best answers",
    ),
    "kf-paper": Entry(
        "posbench.predictors.kf_paper:PaperKalman",
        "the paper's Kalman baseline as its authors published it",
    ),
    "ekf": Entry(
        "posbench.predictors.kalman.ekf:EkfBank",
        "extended Kalman filters (CTRA; IMU- and speed-aided and fixes-only, "
        "4 process noises), the one that predicts the fixes best answers",
    ),
    "lstm": Entry(
        "posbench.predictors.lstm.predictor:LstmPredictor",
        "the paper's system: cubic resampling + MLP-LSTM-MLP (ONNX) + cubic",
    ),
    "lstm-authors": Entry(
        "posbench.predictors.lstm.authors:AuthorsLstmPredictor",
        "the paper authors' published ONNX network (needs --model PATH)",
    ),
    "hybrid": Entry(
        "posbench.predictors.hybrid.predictor:HybridPredictor",
        "the kf as prior + a learned residual (ONNX), applied as far as it has earned it",
    ),
}


def register(name: str, target: str, description: str, **defaults: Any) -> None:
    """Add (or replace) a predictor under ``name``; ``target`` is ``"module:Class"``."""
    REGISTRY[name] = Entry(
        target,
        description,
        dict(defaults),
        source=BUILT_IN if name in BUILT_IN_NAMES else REGISTERED,
    )


#: the names of the built-in predictors
BUILT_IN_NAMES = frozenset(REGISTRY)
