"""The data side of posbench: drives, loaders, synthetic data, scenarios, GPS degradation."""

from posbench.scenarios.drive import (
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders import find_recordings, iter_load, load, load_many

__all__ = [
    "DataError",
    "Drive",
    "DriveMeta",
    "GpsStream",
    "ImuStream",
    "SpeedStream",
    "TruthStream",
    "find_recordings",
    "iter_load",
    "load",
    "load_many",
]
