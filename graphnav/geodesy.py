"""Geodetic latitude/longitude <-> the local metric frame (east-north tangent plane, WGS84).

A thin layer over pymap3d (``geodetic2ecef``, ``ecef2geodetic``: You 2000, non-iterative;
``geodetic2enu``, ``enu2geodetic``): graphnav's conventions only (degrees in and out, the local
frame is east-north, heights dropped for a surface vessel). tests/test_geodesy.py cross-checks it
against the closed-form WGS84 equations.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


@cache
def _pm() -> tuple[Any, Any]:
    """pymap3d and its WGS84 ellipsoid, imported at the first conversion: importing it takes 0.02 s (it pulls in
    dateutil), and a run on a log in a local frame converts nothing."""
    import pymap3d

    return pymap3d, pymap3d.Ellipsoid.from_name("wgs84")


def _arr(v: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(v, dtype=float)


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, h: ArrayLike = 0.0) -> NDArray[np.float64]:
    """WGS84 geodetic (deg, deg, m) -> ECEF (m), shape (..., 3)."""
    lat, lon, h = np.broadcast_arrays(_arr(lat_deg), _arr(lon_deg), _arr(h))
    pymap3d, wgs84 = _pm()
    x, y, z = pymap3d.geodetic2ecef(lat, lon, h, ell=wgs84, deg=True)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1).astype(float)


def ecef_to_geodetic(p: ArrayLike) -> NDArray[np.float64]:
    """ECEF (m), shape (..., 3) -> WGS84 (lat deg, lon deg, h m), same shape."""
    p = _arr(p)
    pymap3d, wgs84 = _pm()
    lat, lon, h = pymap3d.ecef2geodetic(p[..., 0], p[..., 1], p[..., 2], ell=wgs84, deg=True)
    return np.stack(np.broadcast_arrays(lat, lon, h), axis=-1).astype(float)


@dataclass(frozen=True)
class LocalFrame:
    """A local east-north-up tangent frame at the origin (``lat0``, ``lon0`` in degrees, ``h0`` m).

    ``x`` is east and ``y`` north in metres; heights are ignored (a surface vessel): a point is
    taken at the origin's height ``h0`` going in, on the tangent plane (up = 0) coming out.
    """

    lat0: float
    lon0: float
    h0: float = 0.0

    @cached_property
    def _ecef0(self) -> tuple[float, float, float]:
        """The origin in ECEF (m), as ``pymap3d.geodetic2enu`` computes it on every call."""
        pymap3d, wgs84 = _pm()
        return pymap3d.geodetic2ecef(self.lat0, self.lon0, self.h0, ell=wgs84, deg=True)

    def to_local(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> tuple[NDArray, NDArray]:
        """(lat, lon) in degrees -> (x east, y north) in metres."""
        pymap3d, wgs84 = _pm()
        if type(lat_deg) is float and type(lon_deg) is float:  # one fix (a reader's): geodetic2enu's steps, the
            x1, y1, z1 = pymap3d.geodetic2ecef(lat_deg, lon_deg, self.h0, ell=wgs84, deg=True)  # origin's kept
            x0, y0, z0 = self._ecef0
            e, n, _u = pymap3d.uvw2enu(x1 - x0, y1 - y0, z1 - z0, self.lat0, self.lon0, deg=True)
            return _arr(e), _arr(n)
        lat, lon = np.broadcast_arrays(_arr(lat_deg), _arr(lon_deg))
        e, n, _u = pymap3d.geodetic2enu(lat, lon, np.full(lat.shape, self.h0), self.lat0, self.lon0, self.h0,
                                        ell=wgs84, deg=True)
        return _arr(e), _arr(n)

    def to_geodetic(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray, NDArray]:
        """(x east, y north) in metres on the tangent plane -> (lat, lon) in degrees."""
        x, y = np.broadcast_arrays(_arr(x), _arr(y))
        pymap3d, wgs84 = _pm()
        lat, lon, _h = pymap3d.enu2geodetic(x, y, np.zeros(x.shape), self.lat0, self.lon0, self.h0,
                                            ell=wgs84, deg=True)
        return _arr(lat), _arr(lon)


def origin_frame(meta: dict) -> tuple[LocalFrame | None, str | None]:
    """The geodetic origin a log records (``meta["origin"] = {"lat", "lon", "h"}``, degrees and m) as
    a :class:`LocalFrame`, and ``None``; or ``None`` and the reason there is none (absent, or not
    finite numbers in range). Never a default: a log without an origin has no WGS84 position."""
    o = meta.get("origin") if isinstance(meta, dict) else None
    if o is None:
        return None, "the log has no geodetic origin (meta['origin'] = {lat, lon, h})"
    try:
        lat, lon = float(o["lat"]), float(o["lon"])
        h = float(o.get("h", 0.0) or 0.0)
    except (TypeError, ValueError, KeyError, AttributeError):
        return None, f"the log's meta['origin'] is not {{lat, lon, h}} numbers: {str(o)[:60]}"
    if not (np.isfinite([lat, lon, h]).all() and -90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        return None, f"the log's meta['origin'] is out of range: lat {lat}, lon {lon}, h {h}"
    return LocalFrame(lat, lon, h), None
