"""Predictors behind one streaming interface, and the registry that names them."""

from posbench.predictors.base import Predictor
from posbench.predictors.registry import available, create, predictor_class, register

__all__ = ["Predictor", "available", "create", "predictor_class", "register"]
