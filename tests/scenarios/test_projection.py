"""Projections: ENU is true metres, the paper's Mercator is documented as scaled."""

import numpy as np
import pytest

from posbench.scenarios.errors import DataError
from posbench.scenarios.projection import mercator_scale_error, to_local, validate_latlon


def test_enu_true_metres_one_km_north():
    # 1 km north of 49 N: ENU north ~1000 m (WGS-84 meridian radius), east 0
    dlat = 1000.0 / 111_250.0
    x, y = to_local(np.array([49.0 + dlat]), np.array([8.4]), 49.0, 8.4, "enu")
    assert abs(x[0]) < 1e-6 and y[0] == pytest.approx(1000.0, rel=2e-3)


def test_mercator_scale_error_matches_formula():
    lat = 49.0
    d = 1e-4  # deg of longitude
    xe, _ = to_local(np.array([lat]), np.array([8.4 + d]), lat, 8.4, "enu")
    xm, _ = to_local(np.array([lat]), np.array([8.4 + d]), lat, 8.4, "mercator")
    assert xm[0] / xe[0] - 1 == pytest.approx(mercator_scale_error(lat), abs=0.01)
    assert mercator_scale_error(49.0) == pytest.approx(0.524, abs=0.001)


def test_validate_latlon_names_row():
    with pytest.raises(DataError, match=r"f\.csv: fix 2: invalid lat/lon"):
        validate_latlon(np.array([1.0, 2.0, np.nan]), np.array([1.0, 2.0, 3.0]), "f.csv")
    with pytest.raises(DataError, match="fix 0"):
        validate_latlon(np.array([91.0]), np.array([0.0]), "f.csv")
