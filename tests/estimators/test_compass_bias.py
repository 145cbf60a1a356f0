"""The filters' compass-bias state (issue 22 item 1): the compass reads ``yaw + b``, b a random walk with the
graph's prior and density (:class:`graphnav.graph.smoother_config.CompassConfig`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.estimators.ekf import EkfStepper, compass_bias_on, run_ekf
from graphnav.estimators.imu_model import compass_bias_model
from graphnav.estimators.ins_ekf import InsEkf
from graphnav.estimators.ukf import UnscentedNav
from graphnav.geometry import wrap_angle
from graphnav.graph.smoother_config import CompassConfig
from graphnav.log import Heading, NavLog
from graphnav.sim.harbour import HarbourConfig, simulate_harbour

DEVIATION_DEG = 4.0


@pytest.fixture(scope="module")
def biased_log() -> NavLog:
    """400 s of the harbour (IMU, GNSS + Doppler, speed log) with a compass deviation of 4 deg."""
    cfg = HarbourConfig(compass_deviation=math.radians(DEVIATION_DEG), lidar_hz=0.0)
    return simulate_harbour(1, cfg, duration=400.0)


def _heading_rms_deg(res, log: NavLog, after: float) -> float:
    tr = log.columns("truth")
    tj = res.trajectory
    yaw = np.interp(tr["t"], tj.t, np.unwrap(tj.poses[:, 2]))
    e = wrap_angle(yaw - tr["yaw"])[tr["t"] >= after]
    return math.degrees(float(np.sqrt(np.mean(e * e))))


@pytest.mark.parametrize("name", ["ekf", "ukf", "fuzzy-ukf"])
def test_the_filters_estimate_a_compass_deviation(biased_log, name):
    """By default (a compass with GNSS) each filter carries the bias, finds the 4 deg deviation within
    1 deg (about 3 of its own sigmas, ~0.35 deg) and, from 200 s on, halves its heading error (2-4 deg
    without the state: the deviation, less what the GNSS-aided IMU pulls back; 0.4-0.8 deg with it)."""
    res = estimators.run(name, biased_log)
    off = estimators.run(name, biased_log, compass_bias=False)
    assert res.info["compass_bias_state"] and not off.info["compass_bias_state"]
    b, sb = res.info["compass_bias_final_deg"], res.info["compass_bias_sigma_deg"]
    assert abs(b - DEVIATION_DEG) < min(1.0, 3.5 * sb), (b, sb)
    on_rms, off_rms = _heading_rms_deg(res, biased_log, 200.0), _heading_rms_deg(off, biased_log, 200.0)
    assert on_rms < 0.5 * off_rms and off_rms > 0.5 * DEVIATION_DEG, (on_rms, off_rms)


def test_the_auto_rule_wants_a_compass_and_gnss(biased_log):
    """auto: on with a compass and GNSS; a log without compass records has no bias state."""
    assert run_ekf(biased_log).info["compass_bias_state"]
    no_compass = NavLog([r for r in biased_log.records if not isinstance(r, Heading)], meta=biased_log.meta)
    assert not run_ekf(no_compass).info["compass_bias_state"]
    assert not estimators.run("ukf", no_compass).info["compass_bias_state"]
    # the stepper's own rule (the live filter): the IMU motion, or the vessel model with the current states
    assert compass_bias_on("auto", "imu", False) and compass_bias_on("auto", "vessel", True)
    assert not compass_bias_on("auto", "vessel", False) and compass_bias_on(True, "vessel", False)
    assert not compass_bias_on("false", "imu", True)


def test_the_bias_model_is_the_graphs():
    c = CompassConfig()
    assert compass_bias_model() == (math.radians(c.bias_sigma_deg), math.radians(c.bias_drift_deg))


def _ins(compass_bias: bool, sb: float = 0.0, q: float = 0.0) -> InsEkf:
    n = 10 + compass_bias
    x = np.zeros(n)
    x[3] = 2.0
    P = np.diag([1.0, 1.0, 0.01, 0.04, 0.04, 1e-4, 1e-4, 1e-6, 0.25, 0.25] + [sb * sb] * compass_bias)
    return InsEkf(x, P, bias=True, current=True, acc_density=0.004, gyro_density=1e-3, acc_bias_rw=1e-5,
                  gyro_bias_rw=1e-6, current_rw=0.005, compass_bias=compass_bias, compass_bias_rw=q, gate=None)


def _drive(f: InsEkf) -> None:
    rng = np.random.default_rng(3)
    for k in range(200):
        f.predict_imu(0.05 * math.sin(0.1 * k), 0.02, 0.01, 0.1)
        if k % 10 == 0:
            f.update_position((0.2 * k + rng.normal(0, 1), rng.normal(0, 1)), 1.0, k * 0.1)
            f.update_heading(0.01 * k * 0.1 + rng.normal(0, 0.02), 0.02, k * 0.1)
            f.update_velocity((2.0 + rng.normal(0, 0.1), rng.normal(0, 0.1)), 0.1, k * 0.1)
        if k % 7 == 0:
            f.predict_vessel(0.05, accel_density=0.05, yaw_density=0.01)


def test_a_known_zero_bias_is_no_bias():
    """The bias state with no prior variance and no walk (b = 0 known) leaves the EKF as without it."""
    a, b = _ins(False), _ins(True)
    _drive(a)
    _drive(b)
    np.testing.assert_allclose(b.x[:10], a.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.P[:10, :10], a.P, rtol=0, atol=1e-12)
    assert b.x[10] == 0.0 and np.all(b.P[10] == 0.0)


def test_the_ekf_compass_update_reads_yaw_plus_bias():
    """One compass update against the Kalman update with H = e_yaw + e_b written out; the bias walks with
    its density (variance q T) through a prediction."""
    f = _ins(True, sb=math.radians(10.0), q=1e-3)
    f.x[2], f.x[10] = 0.3, 0.05
    P0, x0 = f.P.copy(), f.x.copy()
    f.update_heading(0.4, 0.02)
    H = np.zeros((1, 11))
    H[0, 2] = H[0, 10] = 1.0
    S = H @ P0 @ H.T + 0.02 ** 2
    K = P0 @ H.T / S
    np.testing.assert_allclose(f.x, x0 + (K * (0.4 - 0.35)).ravel(), atol=1e-12)
    np.testing.assert_allclose(f.P, (np.eye(11) - K @ H) @ P0, atol=1e-12)
    p = f.P[10, 10]
    f.predict_imu(0.0, 0.0, 0.0, 2.0)
    assert f.P[10, 10] == pytest.approx(p + 1e-6 * 2.0, rel=1e-12)


def test_a_reinitialised_compass_keeps_the_bias():
    """A re-initialisation (sustained disagreement) restarts the yaw at the reading less the bias."""
    f = InsEkf(np.array([0, 0, 0, 1, 0, 0.1]), np.diag([1, 1, 1e-6, 0.01, 0.01, 1e-4]), bias=False,
               current=False, acc_density=0.004, gyro_density=1e-4, compass_bias=True, gate=0.999, reinit_n=3,
               reinit_after_s=1e9, confirm_n=1)
    for k in range(20):
        f.update_heading(1.0, 0.01, float(k))
    assert f.counts["reinit"] >= 1
    assert f.x[5] == pytest.approx(0.1) and f.x[2] == pytest.approx(0.9, abs=1e-3)


def test_the_ukf_compass_update_reads_theta_plus_bias():
    """UnscentedNav's (linear) compass update with the bias: the Kalman update with H = e_theta + e_b."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    P0 = A @ A.T * 0.01 + np.eye(6) * 1e-3
    x0 = np.array([1.0, 2.0, 0.5, 0.1, 0.3, 0.02])
    f = UnscentedNav(x0, P0, q_acc=0.01, q_gyro=0.001, compass_bias=True, q_compass_bias=1e-3)
    idx = np.array([0, 1, 4])
    z = np.array([1.1, 1.9, 0.35])
    eps, HPH = f.innovation(idx, z)
    H = np.zeros((3, 6))
    H[0, 0] = H[1, 1] = H[2, 4] = H[2, 5] = 1.0
    np.testing.assert_allclose(eps, z - H @ x0, atol=1e-14)
    np.testing.assert_allclose(HPH, H @ P0 @ H.T, atol=1e-14)
    np.testing.assert_allclose(f.channel_var(), np.diag(H @ P0 @ H.T), atol=1e-14)
    R = np.diag([1.0, 1.0, 1e-4])
    f.update(idx, eps, HPH, R)
    K = P0 @ H.T @ np.linalg.inv(H @ P0 @ H.T + R)
    np.testing.assert_allclose(f.x, x0 + K @ eps, atol=1e-12)
    np.testing.assert_allclose(f.P, (np.eye(6) - K @ H) @ P0, atol=1e-12)
    assert f._Q(2.0)[5, 5] == pytest.approx(1e-6 * 2.0)


def test_a_compass_started_yaw_is_correlated_with_the_bias():
    """The yaw from a compass reading is that reading less the bias: var yaw + var b, covariance -var b."""
    sb = compass_bias_model()[0]
    st = EkfStepper(np.array([0.0, 0.0, 0.2]), np.diag([1.0, 1.0, 1e-4]), motion="imu", compass_yaw=True,
                    imu={"compass_bias": True, "bias": False})
    P = st.f.P
    assert P[2, 2] == pytest.approx(1e-4 + sb * sb) and P[2, -1] == pytest.approx(-sb * sb)
    assert P[-1, -1] == pytest.approx(sb * sb)
