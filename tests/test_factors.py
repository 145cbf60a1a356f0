"""Every factor constructor: error at a known point (hand computation) and whitened Jacobian
against central differences on the manifold."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

import factors as F
from graphnav.estimators.dead_reckoning import unicycle_step


def _retract(values: gtsam.Values, key: int, d: np.ndarray) -> gtsam.Values:
    out = gtsam.Values(values)
    sym = chr(gtsam.Symbol(key).chr())
    if sym == "l":
        out.update(key, values.atPoint2(key) + d)
    else:
        out.update(key, values.atPose2(key).retract(d))
    return out


def _dim(values: gtsam.Values, key: int) -> int:
    return 2 if chr(gtsam.Symbol(key).chr()) == "l" else 3


def check_jacobian(factor, values: gtsam.Values, eps: float = 1e-6, tol: float = 1e-5) -> None:
    """The linearised (whitened) Jacobian equals the numerical derivative of the whitened error."""
    A, b = factor.linearize(values).jacobian()
    whiten = factor.noiseModel().whiten
    e0 = whiten(factor.unwhitenedError(values))
    np.testing.assert_allclose(-b, e0, atol=1e-9)
    cols = []
    for key in factor.keys():
        for i in range(_dim(values, key)):
            d = np.zeros(_dim(values, key))
            d[i] = eps
            ep = whiten(factor.unwhitenedError(_retract(values, key, d)))
            em = whiten(factor.unwhitenedError(_retract(values, key, -d)))
            cols.append((ep - em) / (2 * eps))
    np.testing.assert_allclose(A, np.column_stack(cols), atol=tol, rtol=1e-4)


@pytest.fixture
def vals() -> gtsam.Values:
    v = gtsam.Values()
    v.insert(F.X(0), gtsam.Pose2(1.0, 2.0, 0.3))
    v.insert(F.X(1), gtsam.Pose2(2.5, 2.8, 0.55))
    v.insert(F.L(0), np.array([10.0, 6.0]))
    v.insert(F.B(0), gtsam.Pose2(0.0, 0.0, -0.04))
    return v


def test_gnss_error_and_jacobian(vals):
    f = F.gnss_factor(F.X(0), 0.5, 2.5, 3.0, robust=None)
    np.testing.assert_allclose(f.unwhitenedError(vals), [0.5, -0.5], atol=1e-12)
    check_jacobian(f, vals)


def test_compass_wraps_and_jacobian():
    v = gtsam.Values()
    v.insert(F.X(0), gtsam.Pose2(0.0, 0.0, math.radians(179.0)))
    f = F.compass_factor(F.X(0), math.radians(-179.0), math.radians(2.0))
    np.testing.assert_allclose(f.unwhitenedError(v), [math.radians(-2.0)], atol=1e-12)
    check_jacobian(f, v)


def test_biased_compass_only_yaw_counts(vals):
    f = F.biased_compass_factor(F.B(0), F.X(0), 0.33, math.radians(2.0))
    e = f.unwhitenedError(vals)
    assert e[2] == pytest.approx(0.3 - (-0.04) - 0.33, abs=1e-12)  # yaw - theta_B - measured
    w = f.noiseModel().whiten(e)
    assert w[0] == 0.0 and w[1] == 0.0
    check_jacobian(f, vals)
    assert F.compass_bias(gtsam.Pose2(0, 0, -0.04)) == pytest.approx(0.04)


def test_icp_between_full_covariance(vals):
    cov = np.array([[0.04, 0.01, 0.001], [0.01, 0.09, -0.002], [0.001, -0.002, 0.0004]])
    meas = np.array([1.4, 0.4, 0.2])
    f = F.icp_between(F.X(0), F.X(1), meas, cov)
    x0, x1 = vals.atPose2(F.X(0)), vals.atPose2(F.X(1))
    expect = gtsam.Pose2.Logmap(gtsam.Pose2(*meas).between(x0.between(x1)))
    np.testing.assert_allclose(f.unwhitenedError(vals), expect, atol=1e-12)
    # the noise model is the full covariance: its information matrix is cov^-1
    R = f.noiseModel().R()
    np.testing.assert_allclose(R.T @ R, np.linalg.inv(cov), rtol=1e-9)
    check_jacobian(f, vals)


@pytest.mark.parametrize("w", [0.0, 1e-8, 0.2, -0.5])
def test_odometry_increment_matches_unicycle(w):
    delta, _ = F.odometry_increment(1.3, w, 0.7, 0.1, 0.01)
    end = unicycle_step(np.zeros(3), 1.3, w, 0.7)
    np.testing.assert_allclose([delta.x(), delta.y(), delta.theta()], end, atol=1e-8)


def test_odometry_covariance_is_eq3_propagation():
    """Monte Carlo of the speed/ROT errors (eqs. 4-5) through the motion model vs. J Sigma J^T."""
    rng = np.random.default_rng(0)
    v, w, dt, sv, sw = 1.5, 0.3, 1.0, 0.1, 0.05
    mean, cov = F.odometry_increment(v, w, dt, sv, sw, lateral=0.0, floor=0.0)
    xs = []
    for dv, dw in zip(rng.normal(0, sv, 20000), rng.normal(0, sw, 20000), strict=True):
        p = unicycle_step(np.zeros(3), v + dv, w + dw, dt)
        xs.append(gtsam.Pose2.Logmap(mean.between(gtsam.Pose2(*p))))
    emp = np.cov(np.array(xs).T)
    np.testing.assert_allclose(np.diag(cov), np.diag(emp), rtol=0.05)
    assert cov[1, 2] == pytest.approx(emp[1, 2], rel=0.1)


def test_compose_with_cov_monte_carlo():
    rng = np.random.default_rng(1)
    a, b = gtsam.Pose2(1.0, 0.2, 0.3), gtsam.Pose2(0.8, -0.1, -0.2)
    ca, cb = np.diag([0.01, 0.02, 0.003]), np.diag([0.02, 0.01, 0.002])
    m, c = F.compose_with_cov(a, ca, b, cb)
    xs = []
    for da, db in zip(
        rng.multivariate_normal(np.zeros(3), ca, 20000),
        rng.multivariate_normal(np.zeros(3), cb, 20000),
        strict=True,
    ):
        s = a.retract(da).compose(b.retract(db))
        xs.append(gtsam.Pose2.Logmap(m.between(s)))
    np.testing.assert_allclose(c, np.cov(np.array(xs).T), atol=2e-3)


def test_odometry_between_jacobian(vals):
    delta, cov = F.odometry_increment(1.2, 0.1, 1.0, 0.1, 0.02)
    check_jacobian(F.odometry_between(F.X(0), F.X(1), delta, cov), vals)


def test_beacon_factor_error_and_jacobian(vals):
    pose, lm = vals.atPose2(F.X(0)), vals.atPoint2(F.L(0))
    d = lm - np.array([pose.x(), pose.y()])
    bearing = math.atan2(d[1], d[0]) - pose.theta()
    rng_ = float(np.hypot(*d))
    f = F.beacon_factor(F.X(0), F.L(0), rng_ + 0.3, bearing - 0.01, 0.5, math.radians(0.5))
    np.testing.assert_allclose(f.unwhitenedError(vals), [0.01, -0.3], atol=1e-9)  # (bearing, range)
    check_jacobian(f, vals)


def test_beacon_prior_and_initialisation(vals):
    f = F.beacon_prior(F.L(0), 9.0, 6.5, 0.2)
    np.testing.assert_allclose(f.unwhitenedError(vals), [1.0, -0.5], atol=1e-12)
    check_jacobian(f, vals)
    pose = np.array([3.0, -1.0, 2.0])
    p = F.init_from_sighting(pose, 25.0, -0.4)
    d = p - pose[:2]
    assert np.hypot(*d) == pytest.approx(25.0)
    assert math.atan2(d[1], d[0]) - pose[2] == pytest.approx(-0.4)


def test_pose_from_two_beacons_exact():
    pose = np.array([12.0, -7.0, 2.5])
    beacons = [np.array([40.0, 10.0]), np.array([-30.0, 25.0])]
    obs = []
    for b in beacons:
        d = b - pose[:2]
        obs.append((float(np.hypot(*d)), math.atan2(d[1], d[0]) - pose[2]))
    est = F.pose_from_two_beacons(beacons[0], obs[0], beacons[1], obs[1])
    np.testing.assert_allclose(est, pose, atol=1e-9)


def test_robust_kernels_downweight_outliers(vals):
    plain = F.gnss_factor(F.X(0), 31.0, 2.0, 3.0, robust=None)  # 30 m off: 10 sigma
    cases = (("huber", 1.345, 1.345 / 10.0), ("cauchy", 2.3849, 1.0 / (1.0 + (10.0 / 2.3849) ** 2)))
    for kind, k, weight in cases:
        f = F.gnss_factor(F.X(0), 31.0, 2.0, 3.0, robust=kind, k=k)
        A, _ = f.linearize(vals).jacobian()
        A0, _ = plain.linearize(vals).jacobian()
        np.testing.assert_allclose(A, math.sqrt(weight) * A0, rtol=1e-6)
    assert F.robustify(gtsam.noiseModel.Unit.Create(2), None) is not None
    with pytest.raises(ValueError):
        F.robustify(gtsam.noiseModel.Unit.Create(2), "tukeyish")


@pytest.mark.parametrize("planar", [True, False])
@pytest.mark.parametrize("substeps", [1, 3])
def test_preintegrate_arrays_integrates_each_sample_as_given(planar: bool, substeps: int) -> None:
    """The samples (a zero-length one skipped) reach GTSAM as a per-sample loop passes them: the same
    preintegration to the bit."""
    rng = np.random.default_rng(5)
    p = gtsam.PreintegrationParams.MakeSharedU(0.0 if planar else 9.80665)
    p.setAccelerometerCovariance(np.eye(3) * 1e-4)
    p.setGyroscopeCovariance(np.eye(3) * 1e-6)
    p.setIntegrationCovariance(np.eye(3) * 1e-8)
    bias = gtsam.imuBias.ConstantBias(np.array([0.01, -0.02, 0.0]), np.array([0.0, 0.0, 0.003]))
    acc, omega = rng.normal(size=(40, 3)), rng.normal(size=(40, 3)) * 0.2
    dt = np.full(40, 0.01)
    dt[7] = 0.0
    got = F.preintegrate_arrays(p, bias, acc, omega, dt, substeps, planar=planar)
    ref = gtsam.PreintegratedImuMeasurements(p, bias)
    ba, bg = np.asarray(bias.accelerometer()), np.asarray(bias.gyroscope())
    for k in range(40):
        if dt[k] <= 0.0:
            continue
        a, h = acc[k].copy(), dt[k] / substeps
        if planar:
            half = 0.5 * (omega[k, 2] - bg[2]) * h
            c, s = np.cos(np.array([half]))[0], np.sin(np.array([half]))[0]
            ux, uy = a[0] - ba[0], a[1] - ba[1]
            a = np.array([c * ux - s * uy + ba[0], s * ux + c * uy + ba[1], 0.0])
        for _ in range(substeps):
            ref.integrateMeasurement(a, omega[k], float(h))
    assert got.deltaTij() == ref.deltaTij()
    assert np.array_equal(got.preintegrated(), ref.preintegrated())
    assert np.array_equal(got.preintMeasCov(), ref.preintMeasCov())
