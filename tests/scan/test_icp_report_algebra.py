"""The matcher's compiled small numerics against numpy references, compiled and as plain Python (the path
without numba): the covariance and degeneracy algebra (``_icp_fast.report_algebra`` against
:func:`graphnav.scan.covariance.from_sums` and :func:`graphnav.scan.degeneracy.analyse_both`) and a scatter's
line by half angles (``_icp_fast._line_of_moments``)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.scan import _icp_fast, covariance, degeneracy

KERNELS = [pytest.param(_icp_fast.report_algebra, id="compiled"),
           pytest.param(getattr(_icp_fast.report_algebra, "py_func", _icp_fast.report_algebra), id="python")]


def _sums(seed: int, n: int, lever: float, rank: int) -> tuple:
    """Sums of ``n`` random point-to-point pairs as ``report_sums`` forms them: ``H = sum w J^T J``, ``B_lidar``,
    ``B_sampling``, and a point-to-line information of rank ``rank`` (1..3)."""
    rng = np.random.default_rng(seed)
    j = rng.normal(size=(n, 2, 3)) * np.array([1.0, 1.0, lever])
    w = rng.uniform(0.1, 2.0, n)
    s = rng.uniform(1e-4, 1e-2, (n, 2, 2))
    s = s @ s.transpose(0, 2, 1) + 1e-6 * np.eye(2)
    h = np.einsum("n,nai,naj->ij", w, j, j)
    bl = np.einsum("n,nai,nab,nbj->ij", w * w, j, s, j)
    bs = np.einsum("n,nai,naj->ij", w * w * rng.uniform(1e-4, 1e-3, n), j, j)
    rows = rng.normal(size=(n, 3))
    rows[:, rank:] = 0.0 if rank < 3 else rows[:, rank:]
    rows = rows @ np.linalg.qr(rng.normal(size=(3, 3)))[0]  # the weak directions along no axis
    info = (rows * rng.uniform(0.0, 1.0, n)[:, None]).T @ rows
    return h, bl, bs, info


def _check(kernel, k: float, h, bl, bs, info, radius: float, max_condition: float, max_sigma: float) -> None:
    ref = covariance.from_sums(k, 10, h, bl, bs, 0.1, info, radius, max_condition=max_condition, max_sigma=max_sigma)
    cov, var, sig, vec, weak, cond, finite_cov, n_weak, weakest = kernel(k, h, bl, bs, info, radius, max_condition,
                                                                         max_sigma)
    d = ref.degeneracy
    assert finite_cov == np.isfinite(ref.cov).all() and n_weak == d.weak.sum()
    assert np.allclose(weakest, vec[:, 0] * [1.0, 1.0, 1.0 / radius], rtol=1e-15, atol=0)
    assert np.array_equal(np.isnan(cov), np.isnan(ref.cov))
    finite = np.isfinite(ref.cov).all()
    if finite:
        assert np.allclose(cov, ref.cov, rtol=1e-9, atol=1e-12 * np.abs(ref.cov).max())
    else:
        assert np.isinf(var).all() and np.isinf(sig).all()
    assert np.isclose(cond, d.condition, rtol=1e-7) or min(cond, d.condition) > 1e12
    assert np.array_equal(weak, d.weak)
    ev = np.linalg.eigvalsh(0.5 * (info + info.T))
    for i in range(3):  # eigenvectors up to their sign, and the 1-sigma along them (distinct eigenvalues)
        if min(abs(ev[i] - ev[m]) for m in range(3) if m != i) > 1e-6 * abs(ev).max():
            assert abs(abs(vec[:, i] @ d.vectors[:, i]) - 1.0) < 1e-9
            if finite:
                assert np.isclose(sig[i], d.sigmas[i], rtol=1e-7, atol=1e-12 * d.sigmas.max())


@pytest.mark.parametrize("kernel", KERNELS)
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(5, 400), lever=st.floats(0.1, 100.0),
       rank=st.integers(1, 3), radius=st.floats(0.5, 50.0), max_sigma=st.floats(1e-4, 1.0))
def test_the_compiled_algebra_gives_the_numpy_covariance_and_weak_directions(kernel, seed, n, lever, rank, radius,
                                                                              max_sigma):
    h, bl, bs, info = _sums(seed, n, lever, rank)
    _check(kernel, 1.7, h, bl, bs, info, radius, 200.0, max_sigma)


@pytest.mark.parametrize("kernel", KERNELS)
def test_no_scale_or_a_singular_h_gives_no_covariance_and_every_direction_weak(kernel):
    h, bl, bs, info = _sums(1, 50, 10.0, 3)
    for k, hh in ((np.nan, h), (1.0, np.zeros((3, 3))), (1.0, np.full((3, 3), np.nan))):
        _check(kernel, k, hh, bl, bs, info, 2.0, 200.0, 1.0)
        cov, var, sig, _, weak, _, finite_cov, n_weak, _ = kernel(k, hh, bl, bs, info, 2.0, 200.0, 1.0)
        assert np.isnan(cov).all() and weak.all() and not finite_cov and n_weak == 3


@pytest.mark.parametrize("kernel", KERNELS)
def test_a_corridor_is_weak_along_it(kernel):
    """Known answer: walls along x constrain y and the rotation, not x."""
    rows = np.array([[0.0, 1.0, 0.3], [0.0, -1.0, 0.2], [0.0, 1.0, -0.5], [0.0, -1.0, -0.1]])
    info = rows.T @ rows
    h = info + 1e-3 * np.eye(3)
    _check(kernel, 1.0, h, 1e-4 * np.eye(3), 1e-5 * np.eye(3), info, 1.0, 200.0, 1.0)
    _, _, _, vec, weak, cond, _, _, _ = kernel(1.0, h, 1e-4 * np.eye(3), 1e-5 * np.eye(3), info, 1.0, 200.0, 1.0)
    assert weak.tolist() == [True, False, False] and cond > 1e12
    assert np.allclose(np.abs(vec[:, 0]), [1.0, 0.0, 0.0])


def test_the_prior_rule_is_the_reference_one():
    """:func:`covariance.from_kernel` with a guess's covariance: the same weak directions as ``from_sums``."""
    h, bl, bs, info = _sums(7, 80, 5.0, 3)
    for prior in (np.diag([1e-8, 1.0, 1.0]), np.eye(3), np.diag([1.0, 1e-9, 1e-9]), np.full((3, 3), np.nan)):
        ref = covariance.from_sums(1.2, 10, h, bl, bs, 0.1, info, 3.0, max_condition=200.0, max_sigma=1.0,
                                   prior_cov=prior)
        got = covariance.from_kernel(1.2, 10, 0.1, 3.0, _icp_fast.report_algebra(1.2, h, bl, bs, info, 3.0, 200.0, 1.0),
                                     prior_cov=prior)
        assert np.array_equal(got.degeneracy.weak, ref.degeneracy.weak)
        assert np.array_equal(got.geometry.weak, ref.geometry.weak)
    assert degeneracy.with_prior(ref.geometry, np.full(3, np.inf), np.eye(3)) is ref.geometry


LINE = [pytest.param(_icp_fast._line_of_moments, id="compiled"),
        pytest.param(getattr(_icp_fast._line_of_moments, "py_func", _icp_fast._line_of_moments), id="python")]


@pytest.mark.parametrize("line", LINE)
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(phi=st.floats(-np.pi, np.pi), l1=st.floats(1e-6, 1e3), ratio=st.floats(0.0, 1.0), n=st.integers(2, 30))
def test_the_line_of_a_scatter_is_its_major_axis(line, phi, l1, ratio, n):
    """Normal and flatness of a scatter by half angles: the trigonometric form it replaces (``phi = atan2(2 cxy,
    cxx - cyy) / 2``, normal ``(-sin phi, cos phi)``) and numpy's eigenvectors (minor axis, up to sign)."""
    c, s = np.cos(phi), np.sin(phi)
    rot = np.array([[c, -s], [s, c]])
    cm = n * rot @ np.diag([l1, ratio * l1]) @ rot.T
    cxx, cyy, cxy = cm[0, 0], cm[1, 1], cm[0, 1]
    nx, ny, flat = line(cxx, cyy, cxy)
    ph = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    assert np.hypot(nx, ny) == pytest.approx(1.0, abs=1e-12)
    assert np.allclose([nx, ny], [-np.sin(ph), np.cos(ph)], atol=1e-9)
    ev, vec = np.linalg.eigh(cm)
    assert flat == pytest.approx((ev[1] - ev[0]) / (ev[1] + ev[0]), abs=1e-9)
    if ev[1] - ev[0] > 1e-6 * ev[1]:  # a defined axis
        assert abs(abs(nx * vec[0, 0] + ny * vec[1, 0]) - 1.0) < 1e-9


@pytest.mark.parametrize("line", LINE)
def test_the_line_of_known_scatters(line):
    assert line(4.0, 0.0, 0.0) == pytest.approx((0.0, 1.0, 1.0))  # along x: normal y
    assert line(0.0, 4.0, 0.0) == pytest.approx((-1.0, 0.0, 1.0))  # along y: normal -x (phi = pi/2)
    nx, ny, flat = line(1.0, 1.0, 1.0)  # along the diagonal
    assert (nx, ny, flat) == pytest.approx((-np.sqrt(0.5), np.sqrt(0.5), 1.0))
    assert line(2.0, 2.0, 0.0) == pytest.approx((0.0, 1.0, 0.0))  # a circle: no line
    assert line(0.0, 0.0, 0.0) == pytest.approx((0.0, 1.0, 0.0))  # one point
