import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from graphnav.geometry import (
    accumulate,
    heading_deg_to_yaw,
    se2_between,
    se2_compose,
    se2_from_matrix,
    se2_inverse,
    se2_matrix,
    wrap_angle,
    yaw_to_heading_deg,
)

finite = st.floats(-1e3, 1e3, allow_nan=False)
angle = st.floats(-20.0, 20.0, allow_nan=False)
pose = st.tuples(finite, finite, angle)


@given(angle)
def test_wrap_range_and_equivalence(a):
    w = wrap_angle(a)
    assert -np.pi <= w < np.pi
    assert np.isclose(np.cos(w), np.cos(a), atol=1e-9) and np.isclose(np.sin(w), np.sin(a), atol=1e-9)


def test_heading_conventions_known_points():
    # east = yaw 0 = heading 090; north = yaw pi/2 = heading 000; west = 270; south = 180
    assert yaw_to_heading_deg(0.0) == 90.0
    assert np.isclose(yaw_to_heading_deg(np.pi / 2), 0.0)
    assert np.isclose(yaw_to_heading_deg(np.pi), 270.0)
    assert np.isclose(yaw_to_heading_deg(-np.pi / 2), 180.0)
    assert np.isclose(heading_deg_to_yaw(45.0), np.pi / 4)


@given(st.floats(0.0, 359.999))
def test_heading_roundtrip(h):
    back = yaw_to_heading_deg(heading_deg_to_yaw(h))
    assert 0.0 <= back < 360.0
    assert abs(wrap_angle(np.radians(back - h))) < 1e-9


@given(pose, pose)
def test_compose_matches_matrices(a, b):
    m = se2_matrix(a) @ se2_matrix(b)
    c = se2_compose(a, b)
    ref = se2_from_matrix(m)
    assert np.allclose(c[:2], ref[:2], atol=1e-6)
    assert abs(wrap_angle(c[2] - ref[2])) < 1e-9


@given(pose, pose)
def test_between_inverse_identities(a, b):
    d = se2_between(a, b)
    back = se2_compose(a, d)
    assert np.allclose(back[:2], np.asarray(b)[:2], atol=1e-6)
    assert abs(wrap_angle(back[2] - b[2])) < 1e-9
    e = se2_compose(se2_inverse(a), a)
    assert np.allclose(e, 0.0, atol=1e-6)


def test_accumulate_square_closes():
    inc = np.tile([[10.0, 0.0, np.pi / 2]], (4, 1))
    poses = accumulate(inc)
    assert poses.shape == (5, 3)
    assert np.allclose(poses[-1], [0.0, 0.0, 0.0], atol=1e-9)
    assert np.allclose(poses[1], [10.0, 0.0, np.pi / 2])
