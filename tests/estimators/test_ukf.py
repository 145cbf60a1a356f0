"""The paper's UKF (ukf), its bias-augmented variant (ukf-bias) and the fuzzy adaptive UKF."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, unscented_transform

from graphnav import estimators
from graphnav.estimators.ukf import TABLE2, UnscentedNav, inflate, merwe_weights, sigma_points, wrapped_mean
from graphnav.evaluation.evaluate import summarize
from graphnav.evaluation.metrics import ate
from graphnav.log import Gnss, Heading, Imu, NavLog, PosePrior
from graphnav.sim.solent import simulate_solent


@pytest.mark.parametrize("n,alpha,beta,kappa", [(5, 0.5, 2.0, 0.0), (8, 0.3, 2.0, 1.0), (5, 1e-2, 2.0, 0.0)])
def test_sigma_points_and_weights_match_filterpy(n, alpha, beta, kappa):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n))
    P = A @ A.T + n * np.eye(n)
    x = rng.normal(size=n)
    ref = MerweScaledSigmaPoints(n, alpha, beta, kappa)
    wm, wc, lam = merwe_weights(n, alpha, beta, kappa)
    np.testing.assert_allclose(wm, ref.Wm, rtol=1e-12)
    np.testing.assert_allclose(wc, ref.Wc, rtol=1e-12)
    np.testing.assert_allclose(sigma_points(x, P, lam), ref.sigma_points(x, P), rtol=1e-10, atol=1e-10)


def _f(X, ax, ay, wz, T):
    """Reference discretisation of eq. 12 (eq. 1-4) for one sigma point."""
    px, py, vx, vy, th = X
    an = np.array([math.cos(th) * ax - math.sin(th) * ay, math.sin(th) * ax + math.cos(th) * ay])
    return np.array([px + T * vx + 0.5 * T * T * an[0], py + T * vy + 0.5 * T * T * an[1],
                     vx + T * an[0], vy + T * an[1], (th + T * wz + math.pi) % (2 * math.pi) - math.pi])


def _circ_mean(sigmas, Wm):
    m = Wm @ sigmas
    m[4] = math.atan2(Wm @ np.sin(sigmas[:, 4]), Wm @ np.cos(sigmas[:, 4]))
    return m


def _resid(a, b):
    d = a - b
    d[4] = (d[4] + math.pi) % (2 * math.pi) - math.pi
    return d


def test_prediction_matches_filterpy_unscented_transform_across_the_angle_wrap():
    x = np.array([10.0, -4.0, 0.8, -0.3, math.pi - 0.01])  # heading right at the +-pi seam
    P = np.diag([4.0, 3.0, 0.04, 0.05, 1e-4])
    P[0, 2] = P[2, 0] = 0.1
    f = UnscentedNav(x, P, q_acc=TABLE2["q_acc"], q_gyro=math.radians(TABLE2["q_gyro_deg"]))
    Q = f._Q(1.0)
    f.predict(0.05, -0.02, 0.03, 1.0)
    pts = MerweScaledSigmaPoints(5, 0.5, 2.0, 0.0, subtract=_resid)
    sig = np.array([_f(s, 0.05, -0.02, 0.03, 1.0) for s in pts.sigma_points(x, P)])
    m, Pp = unscented_transform(sig, pts.Wm, pts.Wc, Q, mean_fn=_circ_mean, residual_fn=_resid)
    assert abs((f.x[4] - m[4] + math.pi) % (2 * math.pi) - math.pi) < 1e-7
    np.testing.assert_allclose(f.x[:4], m[:4], atol=1e-9)
    np.testing.assert_allclose(f.P, Pp, rtol=1e-6, atol=1e-10)
    assert -math.pi <= f.x[4] < math.pi


def test_wrapped_mean_of_points_straddling_pi():
    X = np.zeros((3, 5))
    X[:, 4] = [math.pi - 0.1, -math.pi + 0.1, math.pi - 0.05]
    m = wrapped_mean(X, np.array([0.25, 0.25, 0.5]), 4)
    assert abs(abs(m[4]) - (math.pi - 0.025)) < 1e-12


def test_heading_innovation_is_wrapped():
    f = UnscentedNav(np.array([0, 0, 0, 0, 3.1]), np.eye(5), q_acc=0.01, q_gyro=0.01)
    eps, _ = f.innovation(np.array([0, 1, 4]), np.array([0.0, 0.0, -3.1]))
    assert eps[2] == pytest.approx(2 * math.pi - 6.2)


def _linear_log(rng, n=40, T=1.0):
    """Zero body acceleration: the model is linear, so the UKF must equal the Kalman filter."""
    recs = [PosePrior(0.0, 5.0, -3.0, 0.2, 2.0, 0.1)]
    for k in range(n + 1):
        t = k * T
        gx, gy = 5 + 0.7 * t + rng.normal(0, 6), -3 - 0.4 * t + rng.normal(0, 6)
        recs.append(Gnss(t, float(gx), float(gy), 6.0))
        recs.append(Heading(t, float(0.2 + 0.01 * t + rng.normal(0, 0.01)), 0.01))
        if k:
            recs.append(Imu(t, 0.0, 0.0, float(0.01 + rng.normal(0, 0.001))))
    return NavLog.from_unsorted(recs)


def test_ukf_equals_the_kalman_filter_on_a_linear_model():
    log = _linear_log(np.random.default_rng(4))
    res = estimators.run("ukf", log, bias=False, compass_bias=False, **TABLE2)  # the paper's 5-state UKF, Table 2
    T = 1.0
    F = np.eye(5)
    F[0, 2] = F[1, 3] = T
    qa = TABLE2["q_acc"] ** 2
    Q = np.zeros((5, 5))
    for i in (0, 1):
        Q[i, i], Q[i, i + 2], Q[i + 2, i], Q[i + 2, i + 2] = qa / 4, qa / 2, qa / 2, qa
    Q[4, 4] = math.radians(TABLE2["q_gyro_deg"]) ** 2
    H = np.zeros((3, 5))
    H[0, 0] = H[1, 1] = H[2, 4] = 1.0
    R = np.diag([TABLE2["r_gps_x"] ** 2, TABLE2["r_gps_y"] ** 2, math.radians(TABLE2["r_com_deg"]) ** 2])
    x = np.array([5.0, -3.0, 0.0, 0.0, 0.2])
    P = np.diag([4.0, 4.0, 4.0, 4.0, 0.01])
    g, h, imu = log.columns("gnss"), log.columns("heading"), log.columns("imu")
    est = []
    for k in range(len(g["t"])):
        if k:
            x = F @ x
            x[4] += T * imu["wz"][k - 1]
            P = F @ P @ F.T + Q
        z = np.array([g["x"][k], g["y"][k], h["yaw"][k]])
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        x = x + K @ (z - H @ x)
        P = (np.eye(5) - K @ H) @ P
        est.append(x[[0, 1, 4]].copy())
    np.testing.assert_allclose(res.trajectory.poses, np.array(est), atol=1e-8)
    np.testing.assert_allclose(res.trajectory.cov[-1], P[np.ix_([0, 1, 4], [0, 1, 4])], atol=1e-9)


def test_online_estimates_and_step_times_are_reported():
    log = _linear_log(np.random.default_rng(5), n=10)
    seen = []
    res = estimators.run("fuzzy-ukf", log, on_estimate=lambda t, p, c: seen.append((t, p, c)))
    assert len(seen) == len(res.trajectory) == 11
    assert len(res.step_ms) == 10 and np.all(res.step_ms > 0)
    s = summarize("fuzzy-ukf", res, log, runtime_s=0.1)
    assert s["step_ms_median"] > 0


def test_unknown_option_is_an_error():
    with pytest.raises(ValueError, match="unknown"):
        estimators.run("ukf", _linear_log(np.random.default_rng(6), n=3), q_acell=1.0)


def test_registry_and_unmet():
    assert {"ukf", "ukf-bias", "fuzzy-ukf"} <= set(estimators.names())
    no_imu = NavLog([Gnss(0.0, 0.0, 0.0, 1.0)])
    assert estimators.get("ukf").unmet(no_imu) is not None


@pytest.fixture(scope="module")
def uncalibrated():
    """Scenario 1 with Table 3's biases left in the IMU (no calibration)."""
    return simulate_solent(scenario=1, seed=11, calibrate=False)


def test_ukf_bias_estimates_an_uncalibrated_bias_and_beats_ukf(uncalibrated):
    log = uncalibrated
    rb = estimators.run("ukf-bias", log, sigma_bias_acc=0.05, sigma_bias_gyro_deg=0.5)
    r = estimators.run("ukf", log, bias=False, compass_bias=False)  # the paper's conventional UKF
    true = np.array(log.meta["imu"]["bias_true"])
    est = np.array(rb.info["bias_final"])
    np.testing.assert_allclose(est, true, rtol=0.3)
    ref = log.truth()
    assert ate(rb.trajectory, ref)["rmse"] < 0.5 * ate(r.trajectory, ref)["rmse"]


def test_fuzzy_ukf_learns_the_larger_noise_of_scenario_2():
    log = simulate_solent(scenario=2, seed=12)
    res = estimators.run("fuzzy-ukf", log)
    r_late = np.sqrt(np.nanmedian(res.info["r_hat"][len(res.trajectory) // 2:], axis=0))
    # true 20 m / 20 m / 5 deg against Table 2's 6 m / 7 m / 0.5 deg
    assert 10.0 < r_late[0] < 40.0 and 10.0 < r_late[1] < 40.0
    assert 2.5 < math.degrees(r_late[2]) < 10.0


def test_fuzzy_ukf_does_not_diverge_on_a_residual_imu_bias():
    """Scenario 2, seed 3 (residual accelerometer bias ~6 mm/s^2 after calibration): with eq. 17's
    raw second moment the drift-biased innovations raised the GNSS R_hat to ~19x the true 20 m
    sigma and the position error grew to ~400 m (RMSE 186 m, 14x the ukf's 13 m). C_A centred on
    the window mean keeps R_hat near the true noise and the error bounded, though the filter, now
    with the right R, trusts the biased IMU model more than the ukf (within 3x the ukf's RMSE);
    inflating P^- on a significant innovation mean (the default) brings it to the ukf's level."""
    log = simulate_solent(scenario=2, seed=3)
    ref = log.truth()
    paper = {"bias": False, "compass_bias": False, **TABLE2}  # the paper's 5-state filters, Table 2's noise
    e_ukf = ate(estimators.run("ukf", log, **paper).trajectory, ref)["rmse"]
    fz = estimators.run("fuzzy-ukf", log, **paper)
    cen = estimators.run("fuzzy-ukf", log, mean_test=None, **paper)
    raw = estimators.run("fuzzy-ukf", log, c_a="raw", mean_test=None, **paper)
    assert ate(fz.trajectory, ref)["rmse"] < 1.5 * e_ukf
    assert ate(cen.trajectory, ref)["rmse"] < 3.0 * e_ukf
    assert ate(raw.trajectory, ref)["rmse"] > 3.0 * e_ukf  # the run reproduces the divergence
    sigma_true = np.array([log.meta["noise"]["gnss_x"][0], log.meta["noise"]["gnss_y"][0]])
    late = len(fz.trajectory) // 2
    for res in (fz, cen):
        assert np.all(np.sqrt(np.nanmax(res.info["r_hat"][late:, :2], axis=0)) < 3.0 * sigma_true)
    assert np.sqrt(np.nanmax(raw.info["r_hat"][late:, 0])) > 3.0 * sigma_true[0]


def test_inflate_scales_the_blocks_and_keeps_p_positive_definite():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(8, 8))
    P = A @ A.T + 1e-3 * np.eye(8)
    lam = np.array([4.0, 2.0, 9.0])
    Pi = inflate(P, lam)
    s = np.array([2.0] * 4 + [3.0] + [1.0] * 3)  # sqrt(max(4, 2)) on px..vy, sqrt(9) on theta
    np.testing.assert_allclose(Pi, P * np.outer(s, s))
    np.linalg.cholesky(Pi)
    corr = lambda M: M / np.sqrt(np.outer(np.diag(M), np.diag(M)))  # noqa: E731
    np.testing.assert_allclose(corr(Pi), corr(P))
    np.testing.assert_array_equal(inflate(P, np.ones(3)), P)


@pytest.mark.parametrize("bias,current,scale", [(False, False, False), (True, False, False), (True, True, False),
                                               (False, True, False), (True, True, True), (False, True, True)])
def test_the_compiled_span_predicts_as_the_numpy_step_does(bias, current, scale):
    """:meth:`UnscentedNav.predict_span` (one compiled call over many IMU samples) against :meth:`predict`
    sample by sample: the same states, covariances and per-step outputs, across the +-pi seam, with
    uneven sample times (Q recomputed), bias, current and speed-log scale states."""
    from graphnav.estimators import _ukf_fast
    if not _ukf_fast.COMPILED:
        pytest.skip("numba is not installed: the filter keeps its numpy step")
    rng = np.random.default_rng(3)
    n = 5 + 3 * bias + 2 * current + scale
    x0 = np.concatenate([[10.0, -4.0, 0.8, -0.3, math.pi - 0.02], rng.normal(0, 0.01, n - 5)])
    A = rng.normal(0, 0.1, (n, n))
    P0 = A @ A.T + np.diag(np.full(n, 0.01))
    kw = dict(q_acc=0.05, q_gyro=0.01, q_bias_acc=1e-3 if bias else 0.0, q_bias_gyro=1e-4 if bias else 0.0,
              current=current, q_current=0.005 if current else 0.0, log_scale=scale, q_log_scale=0.01 if scale else 0.0)
    m = 40
    t = np.cumsum(np.r_[0.0, np.where(np.arange(m) % 7 == 3, 0.02, 0.01)])
    tab = {"t": t, "ax": rng.normal(0, 0.3, m + 1), "ay": rng.normal(0, 0.3, m + 1), "wz": rng.normal(0.5, 0.2, m + 1)}
    ref, fast = UnscentedNav(x0, P0, **kw), UnscentedNav(x0, P0, **kw)
    poses, cov, states = np.zeros((m + 1, 3)), np.zeros((m + 1, 3, 3)), np.zeros((m + 1, n))
    fast.predict_span(tab, 1, m + 1, poses, cov, states)
    for k in range(1, m + 1):
        ref.predict(tab["ax"][k], tab["ay"][k], tab["wz"][k], t[k] - t[k - 1])
        np.testing.assert_allclose(states[k], ref.x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(poses[k], ref.x[[0, 1, 4]], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(cov[k], ref.P[np.ix_([0, 1, 4], [0, 1, 4])], rtol=1e-10, atol=1e-14)
    assert any(abs(s[4]) > 3.0 for s in states[1:]) and any(s[4] * states[1, 4] < 0 for s in states[1:])  # crossed
    np.testing.assert_allclose(fast.P, ref.P, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(fast.x, ref.x, rtol=1e-12, atol=1e-12)


def test_a_run_gives_the_same_track_with_and_without_the_compiled_spans(monkeypatch):
    """The UKF over a log (the USV harbour, 60 s: a 100 Hz IMU between the 1 Hz GNSS and compass) with its
    prediction spans compiled and with the numpy step: the same estimates and step count."""
    from graphnav.sim.harbour import simulate_harbour
    log = simulate_harbour(0, duration=60.0)
    fast = estimators.run("ukf-bias", log)
    from graphnav.estimators import _ukf_fast
    monkeypatch.setattr(_ukf_fast, "COMPILED", False)
    slow = estimators.run("ukf-bias", log)
    assert len(fast.trajectory.t) == len(slow.trajectory.t) > 100
    np.testing.assert_allclose(fast.trajectory.poses, slow.trajectory.poses, rtol=0, atol=1e-8)
    np.testing.assert_allclose(fast.trajectory.cov, slow.trajectory.cov, rtol=1e-6, atol=1e-12)
