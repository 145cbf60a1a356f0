import math

import gtsam
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from graphnav.geometry import (
    accumulate,
    cov_to_world,
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


@given(st.lists(st.floats(-1e4, 1e4, allow_nan=False), min_size=1, max_size=20))
def test_wrap_scalar_path_equals_the_array_path(a):
    arr = wrap_angle(np.array(a))
    assert [wrap_angle(x) for x in a] == list(arr)  # bit-identical: one formula, two code paths


@given(st.floats(-4.0, 4.0), st.integers(0, 2**31 - 1))
def test_cov_to_world_matches_sampled_gtsam_retractions(yaw, seed):
    # body-tangent covariance (what GTSAM's marginals give) pushed through Pose2.retract, measured in
    # the world (x, y, yaw) axes: R C R^T to first order (here exactly, the samples are small)
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(3, 3)) * np.array([0.02, 0.02, 0.002])[:, None]
    c_body = a @ a.T + np.diag([1e-6, 1e-6, 1e-8])
    p = gtsam.Pose2(1.0, -2.0, yaw)
    xi = rng.multivariate_normal(np.zeros(3), c_body, size=4000)
    d = np.array([[q.x() - p.x(), q.y() - p.y(), wrap_angle(q.theta() - p.theta())]
                  for q in (p.retract(v) for v in xi)])
    c_emp = np.cov(d.T)
    c = cov_to_world(yaw, c_body)
    assert np.allclose(c, c.T)
    # the same samples' body covariance rotated exactly: only the retraction's second order differs
    r = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(c_emp, r @ np.cov(xi.T) @ r.T, atol=5e-6)
    np.testing.assert_allclose(cov_to_world(yaw, np.cov(xi.T)), r @ np.cov(xi.T) @ r.T, atol=1e-15)


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
