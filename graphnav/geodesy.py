"""Geodetic latitude/longitude <-> the local metric frame (east-north tangent plane, WGS84)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, h: ArrayLike = 0.0) -> NDArray[np.float64]:
    """WGS84 geodetic (deg, deg, m) -> ECEF (m), shape (..., 3)."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    x = (n + h) * np.cos(lat) * np.cos(lon)
    y = (n + h) * np.cos(lat) * np.sin(lon)
    z = (n * (1.0 - WGS84_E2) + h) * np.sin(lat)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def ecef_to_geodetic(p: ArrayLike) -> NDArray[np.float64]:
    """ECEF (m) -> WGS84 (lat deg, lon deg, h m), Bowring's iteration (sub-mm near the surface)."""
    p = np.asarray(p, dtype=float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    lon = np.arctan2(y, x)
    rho = np.hypot(x, y)
    lat = np.arctan2(z, rho * (1.0 - WGS84_E2))
    for _ in range(5):
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = rho / np.cos(lat) - n
        lat = np.arctan2(z, rho * (1.0 - WGS84_E2 * n / (n + h)))
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = rho / np.cos(lat) - n
    return np.stack([np.degrees(lat), np.degrees(lon), h], axis=-1)


@dataclass(frozen=True)
class LocalFrame:
    """A local east-north-up tangent frame at the origin (``lat0``, ``lon0`` in degrees, ``h0`` m).

    ``x`` is east and ``y`` north in metres; heights are ignored (a surface vessel).
    """

    lat0: float
    lon0: float
    h0: float = 0.0

    def _rot(self) -> NDArray[np.float64]:
        la, lo = np.radians(self.lat0), np.radians(self.lon0)
        return np.array(
            [
                [-np.sin(lo), np.cos(lo), 0.0],
                [-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)],
                [np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)],
            ]
        )

    def to_local(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> tuple[NDArray, NDArray]:
        """(lat, lon) in degrees -> (x east, y north) in metres."""
        d = geodetic_to_ecef(lat_deg, lon_deg, self.h0) - geodetic_to_ecef(self.lat0, self.lon0, self.h0)
        enu = d @ self._rot().T
        return enu[..., 0], enu[..., 1]

    def to_geodetic(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray, NDArray]:
        """(x east, y north) in metres on the tangent plane -> (lat, lon) in degrees."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        enu = np.stack([x, y, np.zeros_like(x)], axis=-1)
        p = geodetic_to_ecef(self.lat0, self.lon0, self.h0) + enu @ self._rot()
        g = ecef_to_geodetic(p)
        return g[..., 0], g[..., 1]
