"""The streaming :class:`Predictor` contract every predictor implements.

The runner alone drives a predictor: it calls ``reset()`` once per drive, then
feeds observations in time order (``observe_*``), and between them asks
``position_at(t)`` for a time ``t`` at or after the last observation. A
predictor never sees an observation stamped after a query's time.

Units and frames: t in seconds from the drive's start; x, y in local metres
(ENU: x east, y north); ax, ay in the vehicle frame (x forward, y left, m/s^2);
yaw in radians (ENU, 0 = east, counter-clockwise); yaw_rate in rad/s; v in m/s.
Missing values are passed as NaN.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import ClassVar, Literal, get_args

import numpy as np

#: the GPS conditions a run replays a drive under: its own receiver's fixes (``native``), or
#: fixes drawn from its truth with no noise, an RTK receiver's or a consumer receiver's
GpsCondition = Literal["native", "none", "rtk", "consumer"]
GPS_CONDITIONS: tuple[str, ...] = get_args(GpsCondition)


class Predictor(ABC):
    """Base class: override ``reset``, ``observe_gps`` and ``position_at``; IMU and
    speed observations are ignored unless a subclass overrides their methods."""

    #: registry name, set by subclasses
    name: ClassVar[str] = ""

    @abstractmethod
    def reset(self) -> None:
        """Forget everything: a new drive starts."""

    @abstractmethod
    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        """A GNSS fix at time t [s], position (x, y) [m, ENU]; ``sigma`` [m] is the fix's
        stated per-axis 1-sigma accuracy (east and north alike, uncorrelated: covariance
        ``sigma**2 * I2`` m^2, :class:`~posbench.scenarios.drive.GpsStream`), None when the source
        states none. The runner passes ``sigma`` only to an ``observe_gps`` that declares a
        parameter of that name (:func:`accepts_sigma`): a predictor written with the
        three-argument form keeps working and never sees it."""

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        """An IMU sample at t [s]: ax, ay [m/s^2, vehicle frame], yaw [rad], yaw_rate [rad/s]."""

    def observe_speed(self, t: float, v: float) -> None:
        """A wheel / CAN speed sample at t [s], v [m/s]."""

    @abstractmethod
    def position_at(self, t: float) -> tuple[float, float]:
        """Estimated (x, y) [m] at time t [s] >= the last observation; (nan, nan) if unknown."""

    def covariance_at(self, t: float) -> np.ndarray | None:
        """Covariance [m^2] of the answer ``position_at(t)`` just gave: a 2x2 array over
        (x, y) in local ENU, or None for "no uncertainty" (this default: a predictor that
        does not model its error never gets a made-up one). The runner asks it right after
        each ``position_at(t)``, with the same t and no observation in between; its time is
        measured apart from the query's."""
        return None

    def config(self) -> dict:
        """The predictor's configuration, recorded in results for reproducibility."""
        return {}

    def warm_up(self) -> None:
        """One-time start-up work done before a run's clock starts (loading compiled code,
        say), so that no timed step pays it; the runner calls it once for each predictor it
        builds. The default does nothing."""

    # optional seams of learned predictors: the defaults describe a predictor without a model

    def model_description(self) -> dict | None:
        """The learned model behind the predictor, recorded in results: ``{"model": str,
        "bundled": bool}`` (the model file, or a text naming the bundled one; whether the
        package's bundled model is used). None for a predictor without a learned model."""
        return None

    def training_drives(self) -> tuple[str, ...]:
        """Names of the drives the predictor's model was trained on, as its model records
        them: results on those drives are not held-out. () when there is no learned model
        or the model does not record its training drives."""
        return ()


class ModelFileSeams:
    """:meth:`Predictor.model_description` and :meth:`Predictor.training_drives` of a
    predictor whose learned model is a file with its ``model.json`` (listed before
    :class:`Predictor` among the bases). The predictor sets ``model_path`` (the .onnx
    file), ``info`` (its model.json) and ``bundled``; ``bundled_text`` names the package's
    bundled model in results."""

    #: the text recorded in results for the bundled model
    bundled_text: ClassVar[str] = ""

    # set by the predictor this is mixed into (declared here so the seams type-check)
    #: the model's .onnx file
    model_path: Path
    #: its model.json, as loaded
    info: dict
    #: whether the package's bundled model is used
    bundled: bool

    def model_description(self) -> dict:
        """``{"model": the model file's path (or :attr:`bundled_text`), "bundled": bool}``."""
        return {
            "model": self.bundled_text if self.bundled else str(self.model_path),
            "bundled": self.bundled,
        }

    def training_drives(self) -> tuple[str, ...]:
        """The drive names model.json records under ``data.train_drives`` (() if none)."""
        data = self.info.get("data") or {}
        return tuple(str(d) for d in data.get("train_drives") or ())


def accepts_sigma(observe_gps: Callable[..., object]) -> bool:
    """Whether an ``observe_gps`` (bound or not) takes the fix accuracy: it declares a
    parameter named ``sigma`` (or ``**kwargs``). Checked once per predictor by the runner
    and by :class:`~posbench.replay.gps_outliers.GatedPredictor`, not per fix."""
    try:
        params = inspect.signature(observe_gps).parameters.values()
    except (TypeError, ValueError):  # a builtin without a signature: the old form
        return False
    return any(
        p.name == "sigma"
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        or p.kind is p.VAR_KEYWORD
        for p in params
    )
