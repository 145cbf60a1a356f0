"""The LiDAR error model (weighted-ICP paper, eq. 5-10) against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.scan.lidar import (
    SIGMA_R_REL,
    directional_error_sq,
    directional_error_sq_vec,
    ellipse_axes,
    mean_error,
    point_covariance,
    polar_to_points,
    sigma_range,
)


def test_polar_to_points_eq10_drops_missing_and_gates():
    r = np.array([1.0, np.nan, 0.0, 2.0, np.inf, -1.0, 50.0, 0.5])
    a = np.array([0.0, 1.0, 2.0, np.pi / 2, 0.3, 0.1, np.pi, np.pi])
    pts, rr, aa = polar_to_points(r, a)
    assert np.allclose(rr, [1.0, 2.0, 50.0, 0.5])
    assert np.allclose(pts[0], [1.0, 0.0])
    assert np.allclose(pts[1], [0.0, 2.0], atol=1e-12)
    assert np.allclose(pts[2], [-50.0, 0.0], atol=1e-9)
    pts, rr, _ = polar_to_points(r, a, min_range=0.8, max_range=40.0)
    assert np.allclose(rr, [1.0, 2.0])
    with pytest.raises(ValueError):
        polar_to_points([1.0, 2.0], [0.0])


def test_sigma_range_is_the_scanse_figure():
    assert sigma_range(10.0) == pytest.approx(10.0 * 0.004258)
    assert SIGMA_R_REL == 0.004258


@settings(max_examples=50, deadline=None)
@given(r=st.floats(0.5, 60.0), alpha=st.floats(-7.0, 7.0), s_rel=st.floats(1e-4, 0.02),
       s_a=st.floats(1e-5, 0.02))
def test_point_covariance_eq8_is_first_order_propagation(r, alpha, s_rel, s_a):
    """Eq. 8 equals J diag(sigma_r^2, sigma_alpha^2) J^T of p = (r cos a, r sin a)."""
    cov = point_covariance(r, alpha, s_rel, s_a)
    j = np.array([[np.cos(alpha), -r * np.sin(alpha)], [np.sin(alpha), r * np.cos(alpha)]])
    ref = j @ np.diag([(s_rel * r) ** 2, s_a**2]) @ j.T
    assert np.allclose(cov, ref, rtol=1e-9, atol=1e-15)
    # eq. 5-7: the semi-axes are the square roots of the eigenvalues, M^2 the trace
    a, b = ellipse_axes(r, s_rel, s_a)
    ev = np.sort(np.linalg.eigvalsh(cov))
    assert np.allclose(np.sqrt(ev), np.sort([a, b]), rtol=1e-6)
    assert mean_error(r, s_rel, s_a) ** 2 == pytest.approx(np.trace(cov), rel=1e-9)


@settings(max_examples=50, deadline=None)
@given(r=st.floats(0.5, 60.0), alpha=st.floats(-7.0, 7.0), beta=st.floats(-7.0, 7.0))
def test_directional_error_eq9_is_s_cov_st(r, alpha, beta):
    cov = point_covariance(r, alpha)
    s = np.array([np.cos(beta), np.sin(beta)])
    ref = s @ cov @ s
    assert directional_error_sq(r, alpha, beta) == pytest.approx(ref, rel=1e-9, abs=1e-15)
    radial = np.array([[np.cos(alpha), np.sin(alpha)]])
    vec = directional_error_sq_vec(np.array([r]), radial, s[None])[0]
    assert vec == pytest.approx(ref, rel=1e-9, abs=1e-15)


def test_directional_error_extremes_are_the_semi_axes():
    r, alpha = 20.0, 0.7
    a, b = ellipse_axes(r)
    assert directional_error_sq(r, alpha, alpha) == pytest.approx(b**2)  # along the beam: range error
    assert directional_error_sq(r, alpha, alpha + np.pi / 2) == pytest.approx(a**2)  # across: angular
