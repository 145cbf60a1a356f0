import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from graphnav.geodesy import LocalFrame, ecef_to_geodetic, geodetic_to_ecef


def test_known_distances():
    f = LocalFrame(54.5, 18.55)  # Gdynia
    # one arc-minute of latitude is ~1855 m at 54.5 N (WGS84 meridian arc)
    x, y = f.to_local(54.5 + 1 / 60, 18.55)
    assert abs(x) < 0.05 and 1850.0 < y < 1860.0
    # one arc-minute of longitude is ~cos(lat) * 1855 m
    x, y = f.to_local(54.5, 18.55 + 1 / 60)
    assert abs(x - 1078.6) < 2.0 and abs(y) < 0.2


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
