"""The fuzzy coefficient (eq. 22-28) and the covariance matcher of the fuzzy adaptive UKF."""

from __future__ import annotations

import numpy as np
import pytest
import skfuzzy as fuzz
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.estimators.fuzzy import FuzzyAlpha, Thresholds, alpha_direct, input_memberships, output_memberships
from graphnav.estimators.fuzzy_ukf import FuzzyCovarianceMatcher

TH = Thresholds()


def test_input_memberships_at_the_breakpoints_of_eq_22_to_24():
    mu = input_memberships([0.0, 1.0 - TH.ep2, 1.0, 1.0 + TH.ep2, 1.0 + TH.ep1, TH.max, 100.0])
    large, equal, small = mu.T
    np.testing.assert_allclose(large, [0, 0, 0, 0, (TH.ep1 - TH.ep2) / (TH.max - 1 - TH.ep2), 1, 1])
    np.testing.assert_allclose(equal, [0, 1, 1, 1, 0, 0, 0])
    np.testing.assert_allclose(small, [1, 0, 0, 0, 0, 0, 0])


def test_output_memberships_are_eq_25_to_27():
    a = np.array([0.0, 0.46, 1.0 - TH.al_ep1, 1.0, 1.0 + TH.al_ep2, 3.0, TH.al_max])
    o = output_memberships(a)
    np.testing.assert_allclose(o[:, 2], [1.0, 0.5, 1 - 0.8 / 0.92, 0, 0, 0, 0])
    np.testing.assert_allclose(o[:, 1], [0, 0, 0, 1, 1, 0, 0])
    np.testing.assert_allclose(o[:, 0], [0, 0, 0, 0, 0, (3.0 - 1.08) / (5.0 - 1.08), 1])


def test_closed_form_centroids_when_one_rule_fires_fully():
    # DoM >= max: only "large" fires with strength 1 -> centroid of the ramp 1+al_ep2 .. al_max
    a0, a1 = 1 + TH.al_ep2, TH.al_max
    assert alpha_direct(10.0) == pytest.approx(a0 + 2 / 3 * (a1 - a0), abs=1e-3)
    # DoM = 0: only "small" fires -> centroid of the triangle 0 .. 1 - al_ep2
    assert alpha_direct(0.0) == pytest.approx((1 - TH.al_ep2) / 3, abs=1e-3)
    # DoM in the dead band: only "equal" -> symmetric trapezoid centred at 1
    assert alpha_direct(1.0) == pytest.approx(1.0, abs=1e-9)
    assert alpha_direct(1.0 + TH.ep2 * 0.9) == pytest.approx(1.0, abs=1e-9)


def _skfuzzy_alpha(dom: float) -> float:
    """The same Mamdani system built from scikit-fuzzy's primitives (trapmf, interp_membership, defuzz)."""
    d_u = np.linspace(0.0, 20.0, 200001)
    a_u = np.linspace(0.0, TH.al_max, 20001)
    in_l = fuzz.trapmf(d_u, [1 + TH.ep2, TH.max, 20.0, 20.0])
    in_e = fuzz.trapmf(d_u, [1 - TH.ep1, 1 - TH.ep2, 1 + TH.ep2, 1 + TH.ep1])
    in_s = fuzz.trapmf(d_u, [0.0, 0.0, 0.0, 1 - TH.ep2])
    out_l = fuzz.trapmf(a_u, [1 + TH.al_ep2, TH.al_max, TH.al_max, TH.al_max])
    out_e = fuzz.trapmf(a_u, [1 - TH.al_ep1, 1 - TH.al_ep2, 1 + TH.al_ep2, 1 + TH.al_ep1])
    out_s = fuzz.trapmf(a_u, [0.0, 0.0, 0.0, 1 - TH.al_ep2])
    agg = np.zeros_like(a_u)
    for mf_in, mf_out in ((in_l, out_l), (in_e, out_e), (in_s, out_s)):
        w = fuzz.interp_membership(d_u, mf_in, dom)
        agg = np.fmax(agg, np.fmin(w, mf_out))
    return float(fuzz.defuzz(a_u, agg, "centroid"))


@pytest.mark.parametrize("dom", [0.0, 0.2, 0.5, 0.8, 0.83, 0.9, 1.0, 1.12, 1.18, 1.22, 1.5, 3.0, 6.5, 9.0])
def test_matches_scikit_fuzzy(dom):
    ref = _skfuzzy_alpha(dom)
    assert alpha_direct(dom) == pytest.approx(ref, abs=2e-3)
    assert FuzzyAlpha()(dom) == pytest.approx(ref, abs=2e-3)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 12.0), st.floats(0.0, 12.0))
def test_alpha_is_monotone_and_bounded(d1, d2):
    f = FuzzyAlpha()
    lo, hi = sorted((d1, d2))
    assert f(lo) <= f(hi) + 1e-9
    assert 0.0 < f(lo) <= TH.al_max


def test_table_interpolation_is_close_to_direct_evaluation():
    x = np.random.default_rng(0).uniform(0.0, 9.0, 400)
    np.testing.assert_allclose(FuzzyAlpha()(x), alpha_direct(x), atol=5e-4)


def test_window_covariance_is_the_recursive_mean_of_eq_17_18():
    rng = np.random.default_rng(1)
    N = 7
    m = FuzzyCovarianceMatcher(np.ones(3), 40, window=N, r_update="scale_prior", c_a="raw")
    mc = FuzzyCovarianceMatcher(np.ones(3), 40, window=N, r_update="scale_prior")  # c_a="centered"
    eps_hist = []
    for k in range(40):
        eps = rng.normal(0.5, 2.0, 3)
        eps_hist.append(eps)
        m(k, np.arange(3), eps, np.zeros((3, 3)), np.ones(3))
        mc(k, np.arange(3), eps, np.zeros((3, 3)), np.ones(3))
        window = np.array(eps_hist[-N:])
        np.testing.assert_allclose(m.hist["c_a"][k], np.mean(window ** 2, axis=0), rtol=1e-9)
        if len(window) > 1:  # the sample covariance about the window mean
            np.testing.assert_allclose(mc.hist["c_a"][k], np.var(window, axis=0, ddof=1), rtol=1e-9)


def test_a_systematic_innovation_is_not_booked_as_sensor_noise():
    """A slowly growing innovation mean (model error, e.g. a residual IMU bias) inflates eq. 17's
    second moment and, through eq. 20-21, R without bound; the centred C_A keeps R at the noise."""
    rng = np.random.default_rng(4)
    r0 = np.array([36.0, 49.0, 1e-4])
    n = 1500
    raw = FuzzyCovarianceMatcher(r0, n, window=30, c_a="raw")
    cen = FuzzyCovarianceMatcher(r0, n, window=30)
    for k in range(n):
        eps = rng.normal(0.0, np.sqrt(r0)) + np.array([0.05, -0.05, 5e-4]) * k  # a ramp: drift
        raw(k, np.arange(3), eps, np.zeros((3, 3)), r0)
        cen(k, np.arange(3), eps, np.zeros((3, 3)), r0)
    late = slice(n // 2, None)
    assert np.all(np.median(raw.hist["r_hat"][late] / r0, axis=0) > 10.0)
    ratio = np.median(cen.hist["r_hat"][late] / r0, axis=0)
    assert np.all((ratio > 0.5) & (ratio < 2.0))


def test_compound_update_converges_to_the_true_noise_and_scale_prior_is_bounded():
    rng = np.random.default_rng(2)
    true_var = np.array([400.0, 400.0, 0.0076])  # 20 m, 20 m, 5 deg
    r0 = np.array([36.0, 49.0, np.radians(0.5) ** 2])
    n = 3000
    mc = FuzzyCovarianceMatcher(r0, n, window=30, r_update="compound")
    ms = FuzzyCovarianceMatcher(r0, n, window=30, r_update="scale_prior")
    for k in range(n):
        eps = rng.normal(0.0, np.sqrt(true_var))
        mc(k, np.arange(3), eps, np.zeros((3, 3)), r0)
        ms(k, np.arange(3), eps, np.zeros((3, 3)), r0)
    late = np.median(mc.hist["r_hat"][n // 2:], axis=0)
    np.testing.assert_allclose(late, true_var, rtol=0.5)
    assert np.all(ms.hist["r_hat"] <= r0 * (TH.al_max + 1e-9))


def test_matched_noise_leaves_r_nearly_unchanged():
    rng = np.random.default_rng(3)
    r0 = np.array([36.0, 49.0, 1e-4])
    n = 2000
    m = FuzzyCovarianceMatcher(r0, n, window=100, r_update="compound")
    for k in range(n):
        m(k, np.arange(3), rng.normal(0.0, np.sqrt(r0)), np.zeros((3, 3)), r0)
    ratio = np.median(m.hist["r_hat"][n // 2:] / r0, axis=0)
    assert np.all((ratio > 0.5) & (ratio < 2.0))


def test_inflation_fires_on_a_significant_innovation_mean_only():
    """White innovations matching C_T: lambda = 1 except at about the test's false-alarm rate; a
    constant offset of 3 C_T^(1/2) / sqrt(N) and more: lambda makes H P^- H^T cover mu^2."""
    rng = np.random.default_rng(6)
    r0 = np.array([36.0, 49.0, 1e-4])
    hph = 0.1 * r0
    n, N = 3000, 30
    m = FuzzyCovarianceMatcher(r0, n, window=N, r_update="scale_prior", mean_test=0.95)
    fired = 0
    for k in range(n):
        lam = m.inflation(np.arange(3), hph)
        fired += int(np.any(lam > 1.0)) if k >= N else 0
        m(k, np.arange(3), rng.normal(0.0, np.sqrt(hph + r0)), np.diag(hph), r0)
    assert fired / (n - N) < 0.2  # three channels at 5 %, serially correlated window means
    off = 3.0 * np.sqrt((hph + r0) / N) * np.array([1.5, -2.0, 3.0])
    m2 = FuzzyCovarianceMatcher(r0, n, window=N, r_update="scale_prior", mean_test=0.95)
    for k in range(N):
        m2(k, np.arange(3), off, np.diag(hph), r0)
    lam = m2.inflation(np.arange(3), hph)
    np.testing.assert_allclose(lam * hph, off ** 2)
    assert np.all(FuzzyCovarianceMatcher(r0, n, window=N, mean_test=None).inflation(np.arange(3), hph) == 1.0)


def test_bad_options_are_rejected():
    with pytest.raises(ValueError, match="r_update"):
        FuzzyCovarianceMatcher(np.ones(3), 10, r_update="sometimes")
    with pytest.raises(ValueError, match="window"):
        FuzzyCovarianceMatcher(np.ones(3), 10, window=0)
    with pytest.raises(ValueError, match="window"):
        FuzzyCovarianceMatcher(np.ones(3), 10, window=1)  # no covariance about the mean of one
    FuzzyCovarianceMatcher(np.ones(3), 10, window=1, c_a="raw")
    with pytest.raises(ValueError, match="c_a"):
        FuzzyCovarianceMatcher(np.ones(3), 10, c_a="sometimes")
    with pytest.raises(ValueError, match="mean_test"):
        FuzzyCovarianceMatcher(np.ones(3), 10, mean_test=1.5)
