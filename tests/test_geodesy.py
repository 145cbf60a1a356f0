"""graphnav.geodesy (over pymap3d) against the closed-form WGS84 equations, and round trips."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from graphnav.geodesy import WGS84_A, WGS84_E2, WGS84_F, LocalFrame, ecef_to_geodetic, geodetic_to_ecef

LAT, LON, H = st.floats(-89.9, 89.9), st.floats(-180, 180), st.floats(-500, 10_000)


def closed_form_ecef(lat_deg, lon_deg, h):
    """Geodetic -> ECEF, the textbook closed form: N = a / sqrt(1 - e^2 sin^2 lat),
    X = (N + h) cos lat cos lon, Y = (N + h) cos lat sin lon, Z = (N (1 - e^2) + h) sin lat."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.array([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - WGS84_E2) + h) * np.sin(lat)])


def closed_form_enu_rotation(lat_deg, lon_deg):
    """Rows: east, north, up unit vectors at (lat, lon), in ECEF."""
    la, lo = np.radians(lat_deg), np.radians(lon_deg)
    return np.array([[-np.sin(lo), np.cos(lo), 0.0],
                     [-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)],
                     [np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)]])


def test_known_points():
    b = WGS84_A * (1.0 - WGS84_F)  # semi-minor axis
    assert np.allclose(geodetic_to_ecef(0.0, 0.0, 0.0), [WGS84_A, 0.0, 0.0], atol=1e-6)
    assert np.allclose(geodetic_to_ecef(0.0, 90.0, 10.0), [0.0, WGS84_A + 10.0, 0.0], atol=1e-6)
    assert np.allclose(geodetic_to_ecef(90.0, 0.0, 0.0), [0.0, 0.0, b], atol=1e-6)
    assert np.allclose(ecef_to_geodetic([0.0, 0.0, -b - 5.0]), [-90.0, 0.0, 5.0], atol=1e-6)


def test_known_distances():
    f = LocalFrame(54.5, 18.55)  # Gdynia
    # one arc-minute of latitude is ~1855 m at 54.5 N (WGS84 meridian arc)
    x, y = f.to_local(54.5 + 1 / 60, 18.55)
    assert abs(x) < 0.05 and 1850.0 < y < 1860.0
    # one arc-minute of longitude is ~cos(lat) * 1855 m
    x, y = f.to_local(54.5, 18.55 + 1 / 60)
    assert abs(x - 1078.6) < 2.0 and abs(y) < 0.2


@given(LAT, LON, H)
def test_ecef_matches_closed_form(lat, lon, h):
    assert np.allclose(geodetic_to_ecef(lat, lon, h), closed_form_ecef(lat, lon, h), rtol=0, atol=1e-6)


@given(LAT, LON, H)
def test_ecef_to_geodetic_inverts_closed_form(lat, lon, h):
    g = ecef_to_geodetic(closed_form_ecef(lat, lon, h))
    assert abs(g[0] - lat) < 1e-9 and abs(g[2] - h) < 1e-4
    assert abs((g[1] - lon + 180.0) % 360.0 - 180.0) < 1e-9


@given(LAT, LON, st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-100, 100))
def test_local_matches_closed_form(lat0, lon0, dlat, dlon, h0):
    """to_local = the east and north rows of R(lat0, lon0) applied to ECEF(p, h0) - ECEF(origin, h0)."""
    lat = float(np.clip(lat0 + dlat, -89.99, 89.99))
    x, y = LocalFrame(lat0, lon0, h0).to_local(lat, lon0 + dlon)
    d = closed_form_ecef(lat, lon0 + dlon, h0) - closed_form_ecef(lat0, lon0, h0)
    enu = closed_form_enu_rotation(lat0, lon0) @ d
    assert abs(x - enu[0]) < 1e-6 and abs(y - enu[1]) < 1e-6


@given(st.floats(-80, 80), st.floats(-179, 179), st.floats(-2000, 2000), st.floats(-2000, 2000))
def test_local_roundtrip(lat0, lon0, x, y):
    f = LocalFrame(lat0, lon0)
    lat, lon = f.to_geodetic(x, y)
    x2, y2 = f.to_local(lat, lon)
    assert abs(x2 - x) < 1e-3 and abs(y2 - y) < 1e-3


@given(st.floats(-89, 89), st.floats(-180, 180), st.floats(-100, 1000))
def test_ecef_roundtrip(lat, lon, h):
    g = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h))
    assert np.allclose(g, [lat, lon, h], atol=1e-6)


def test_arrays_and_scalars():
    f = LocalFrame(43.5, 16.4)
    lat, lon = f.to_geodetic(np.array([0.0, 100.0, -50.0]), np.array([0.0, 0.0, 200.0]))
    assert lat.shape == (3,) and abs(lat[0] - 43.5) < 1e-12 and abs(lon[0] - 16.4) < 1e-12
    x, y = f.to_local(lat, lon)
    assert np.allclose(x, [0.0, 100.0, -50.0], atol=1e-3) and np.allclose(y, [0.0, 0.0, 200.0], atol=1e-3)
    xs, ys = f.to_local(43.5, 16.4)
    assert np.ndim(xs) == 0 and abs(float(xs)) < 1e-9 and abs(float(ys)) < 1e-9
    assert geodetic_to_ecef([1.0, 2.0], [3.0, 4.0]).shape == (2, 3)


@given(st.floats(-89.0, 89.0), st.floats(-180.0, 180.0), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5),
       st.floats(-100.0, 100.0))
def test_one_fix_is_pymap3d_geodetic2enu_to_the_bit(lat0, lon0, dlat, dlon, h0):
    """A reader's one fix (Python floats: the origin's ECEF kept) gives pymap3d's ``geodetic2enu``
    exactly, as the array path does."""
    import pymap3d

    f = LocalFrame(lat0, lon0, h0)
    lat, lon = lat0 + dlat, lon0 + dlon
    e, n, _ = pymap3d.geodetic2enu(lat, lon, h0, lat0, lon0, h0, ell=pymap3d.Ellipsoid.from_name("wgs84"))
    for x, y in (f.to_local(lat, lon), f.to_local(np.array(lat), np.array(lon)), f.to_local(lat, lon)):
        assert float(x) == float(e) and float(y) == float(n)


def test_pymap3d_is_imported_at_the_first_conversion():
    """Importing graphnav.geodesy (every reader does) costs no pymap3d import (0.02 s, dateutil with it): a run on a
    local-frame log converts nothing; the first conversion imports it and converts as ever."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    code = ("import sys\n"
            "from graphnav import geodesy\n"
            "import graphnav.io, graphnav.graph.log_runs\n"
            "before = 'pymap3d' in sys.modules\n"
            "x, y = geodesy.LocalFrame(50.0, -1.0).to_local(50.001, -1.0)\n"
            "print(before, 'pymap3d' in sys.modules, round(float(y), 3))\n")
    repo = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=repo, check=True,
                       env={**os.environ, "PYTHONPATH": str(repo)})
    before, after, north = r.stdout.split()
    assert (before, after) == ("False", "True")
    assert abs(float(north) - 111.229) < 2e-3  # 0.001 deg of latitude at 50 deg: M pi / 180 / 1000 = 111.229 m
