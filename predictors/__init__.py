"""Predictors behind one streaming interface, and the registry that names them."""

from posbench.predictors.base import Predictor
from posbench.predictors.catalogue import register
from posbench.predictors.registry import available, create, predictor_class

__all__ = ["Predictor", "available", "create", "predictor_class", "register"]
