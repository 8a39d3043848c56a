"""Geodetic -> local metric projections.

- ``"enu"`` (default, used by all metrics): local East-North-Up tangent plane
  about an origin (the drive's first fix), via pymap3d on the WGS-84 ellipsoid,
  altitude ignored (0 m). True metres near the origin.
- ``"mercator"``: the paper's spherical Mercator approximation
  x = R*lon + 500000, y = R*ln(tan(pi/4 + lat/2)), R = 6378137 m, shifted so the
  origin is (0, 0). Offered for parity with the paper only: its scale is
  1/cos(lat) too large (about +52 % at KITTI's 49 deg N, +43 % at 45.8 deg N),
  so errors computed in it are not metres.
"""

from __future__ import annotations

import numpy as np

from posbench.scenarios.errors import DataError
from posbench.scenarios.text import quoted

EARTH_RADIUS_M = 6378137.0
PROJECTIONS = ("enu", "mercator")


def validate_latlon(lat: np.ndarray, lon: np.ndarray, source: str, what: str = "fix") -> None:
    """Raise :class:`DataError` naming the first bad row if lat/lon are NaN, inf or out of range."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    bad = ~np.isfinite(lat) | ~np.isfinite(lon) | (np.abs(lat) > 90.0) | (np.abs(lon) > 180.0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise DataError(
            source,
            f"{what} {i}: invalid lat/lon ({quoted(lat[i])}, {quoted(lon[i])}); "
            f"{int(bad.sum())} invalid in all",
        )


def mercator_scale_error(lat_deg: float) -> float:
    """Relative scale error of the paper's spherical Mercator at a latitude (0.52 = +52 %)."""
    return 1.0 / np.cos(np.radians(lat_deg)) - 1.0


def to_local(
    lat: np.ndarray, lon: np.ndarray, origin_lat: float, origin_lon: float, projection: str = "enu"
) -> tuple[np.ndarray, np.ndarray]:
    """Project lat/lon [deg] to local (x, y) [m] about the origin [deg]."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    if projection == "enu":
        import pymap3d

        e, n, _ = pymap3d.geodetic2enu(lat, lon, np.zeros_like(lat), origin_lat, origin_lon, 0.0)
        return np.asarray(e, dtype=float), np.asarray(n, dtype=float)
    if projection == "mercator":

        def merc(la: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            x = EARTH_RADIUS_M * np.radians(lo) + 500000.0
            y = EARTH_RADIUS_M * np.log(np.tan(np.pi / 4 + np.radians(la) / 2))
            return x, y

        x, y = merc(lat, lon)
        x0, y0 = merc(np.asarray(origin_lat), np.asarray(origin_lon))
        return x - x0, y - y0
    raise ValueError(f"unknown projection {projection!r}; choose one of {PROJECTIONS}")


def ecef_to_local(
    xyz: np.ndarray, origin_lat: float, origin_lon: float, origin_alt: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """ECEF positions [m] (N, 3) to local ENU (east, north) [m] about an origin."""
    import pymap3d

    xyz = np.asarray(xyz, dtype=float)
    e, n, _ = pymap3d.ecef2enu(xyz[:, 0], xyz[:, 1], xyz[:, 2], origin_lat, origin_lon, origin_alt)
    return np.asarray(e, dtype=float), np.asarray(n, dtype=float)
