"""The general EKF: closed forms, a filterpy cross-check, gating, angle wrapping, recovery."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.estimators.ekf import PoseEkf, icp_available, run_ekf
from graphnav.geometry import wrap_angle
from graphnav.log import Gnss, Heading, NavLog, Odometry, PosePrior, Truth


def drive(seed: int = 0, *, T: float = 120.0, v: float = 2.0, w: float = 0.05, yaw0: float = 0.0,
          sig_v: float = 0.05, sig_w: float = math.radians(0.2), sig_g: float = 1.0,
          sig_h: float = math.radians(2.0), jump: tuple[float, float, float] | None = None) -> NavLog:
    """A constant-turn drive: 10 Hz odometry, 1 Hz GNSS and compass, exact truth."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    x, y, th = 0.0, 0.0, yaw0
    recs: list = [PosePrior(0.0, 0.0, 0.0, yaw0, 0.5, math.radians(2.0))]
    for k in range(int(T / dt) + 1):
        t = k * dt
        recs.append(Truth(t, x, y, wrap_angle(th)))
        recs.append(Odometry(t, v + rng.normal(0, sig_v), w + rng.normal(0, sig_w), sig_v, sig_w))
        if k % 10 == 0 and k > 0:
            gx, gy = x + rng.normal(0, sig_g), y + rng.normal(0, sig_g)
            if jump and jump[0] <= t < jump[1]:
                gx += jump[2]
            recs.append(Gnss(t, gx, gy, sig_g))
            recs.append(Heading(t, wrap_angle(th + rng.normal(0, sig_h)), sig_h))
        # exact constant-turn integration
        th2 = th + w * dt
        x += v / w * (math.sin(th2) - math.sin(th))
        y -= v / w * (math.cos(th2) - math.cos(th))
        th = th2
    return NavLog.from_unsorted(recs, meta={"name": "drive"})


def pos_err(res, log) -> np.ndarray:
    ref = log.truth()
    idx = np.searchsorted(ref.t, res.trajectory.t)
    return np.hypot(*(res.trajectory.poses[:, :2] - ref.poses[idx, :2]).T)


def test_gnss_only_variance_matches_closed_form():
    # No motion (v = w = 0, no process noise): n fixes of variance s^2 on a prior p0 -> 1/(1/p0 + n/s^2)
    f = PoseEkf(np.zeros(3), np.diag([4.0, 4.0, 0.1]), gate=None)
    for _ in range(7):
        f.predict_odometry(0.0, 0.0, 1.0, 0.0, 0.0)
        f.update_position((0.3, -0.2), 2.0)
    expect = 1.0 / (1.0 / 4.0 + 7 / 4.0)
    assert f.P[0, 0] == pytest.approx(expect, rel=1e-12)
    assert f.P[1, 1] == pytest.approx(expect, rel=1e-12)
    # the mean is the precision-weighted average of the prior (0) and the fixes
    assert f.x[0] == pytest.approx(0.3 * (7 / 4.0) * expect, rel=1e-12)


def test_one_step_agrees_with_filterpy():
    from filterpy.kalman import ExtendedKalmanFilter

    x0 = np.array([1.0, 2.0, 0.4])
    P0 = np.array([[0.5, 0.1, 0.01], [0.1, 0.7, -0.02], [0.01, -0.02, 0.03]])
    v, w, dt, sv, sw = 3.0, 0.2, 0.5, 0.3, 0.05
    f = PoseEkf(x0, P0, gate=None)
    f.predict_odometry(v, w, dt, sv, sw)
    f.update_position((2.5, 3.0), 0.8)
    f.update_heading(0.55, 0.1)

    ekf = ExtendedKalmanFilter(dim_x=3, dim_z=2)
    ekf.x, ekf.P = x0.copy(), P0.copy()
    c, s = math.cos(x0[2]), math.sin(x0[2])
    ekf.F = np.array([[1, 0, -s * dt * v], [0, 1, c * dt * v], [0, 0, 1]])
    Wm = np.array([[c * dt, 0], [s * dt, 0], [0, dt]])
    ekf.Q = Wm @ np.diag([sv**2, sw**2]) @ Wm.T
    ekf.predict()  # F x is not the motion model: set the mean ourselves
    ekf.x = x0 + np.array([v * dt * c, v * dt * s, w * dt])
    H = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    ekf.update(np.array([2.5, 3.0]), lambda x: H, lambda x: H @ x, R=np.eye(2) * 0.64)
    Hh = np.array([[0, 0, 1.0]])
    ekf.update(np.array([0.55]), lambda x: Hh, lambda x: Hh @ x, R=np.array([[0.01]]))
    np.testing.assert_allclose(f.x, ekf.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f.P, ekf.P, rtol=1e-8, atol=1e-12)


def test_tracks_a_turning_drive_and_reports_every_estimate():
    log = drive(1)
    seen = []
    res = estimators.run("ekf", log, on_estimate=lambda t, p, c: seen.append((t, p.copy(), c.copy())))
    assert len(seen) == len(res.trajectory)
    e = pos_err(res, log)
    assert np.sqrt(np.mean(e**2)) < 1.5          # GNSS sigma 1 m, odometry good
    # the reported covariance is consistent: normalised position error not absurd
    P = res.trajectory.cov
    assert np.all(np.linalg.eigvalsh(P) > 0)
    assert res.info["rejected"] < 0.02 * res.info["accepted"]


def test_gnss_jump_is_rejected_and_the_estimate_survives():
    log = drive(2, jump=(50.0, 60.0, 80.0))
    gated = run_ekf(log)
    blind = run_ekf(log, gate=None)
    assert gated.info["rejected"] >= 10
    assert pos_err(gated, log).max() < 5.0
    assert pos_err(blind, log).max() > 20.0       # without the gate the jump drags the estimate


def test_permanent_shift_is_believed_after_reinit_after_s():
    # the GNSS "jump" never ends: rejected while it is younger than reinit_after_s, then believed
    # (after 150 s of tracking: a shift that outnumbers the fixes behind the estimate is believed sooner)
    log = drive(3, T=320.0, jump=(150.0, 1e9, 60.0))
    res = run_ekf(log, reinit_after_s=100.0)
    assert res.info["reinit"] >= 1
    ref = log.truth()
    idx = np.searchsorted(ref.t, res.trajectory.t)
    dx = res.trajectory.poses[:, 0] - ref.poses[idx, 0]
    t = res.trajectory.t
    assert np.abs(dx[t < 245.0]).max() < 5.0          # not followed for 95 s
    assert abs(dx[-1] - 60.0) < 5.0                   # then followed


def test_heading_wraps_across_pi():
    # start heading just below +pi, turning left: yaw crosses +pi -> -pi during the run
    log = drive(4, T=60.0, yaw0=math.pi - 0.3, w=0.02)
    res = run_ekf(log)
    ref = log.truth()
    idx = np.searchsorted(ref.t, res.trajectory.t)
    dyaw = wrap_angle(res.trajectory.poses[:, 2] - ref.poses[idx, 2])
    assert np.max(np.abs(dyaw)) < math.radians(5.0)
    assert np.all(np.abs(res.trajectory.poses[:, 2]) <= math.pi)
    assert res.info["rejected"] < 5


def test_speed_state_estimates_speed():
    log = drive(5, T=60.0)
    res = run_ekf(log, speed=True)
    assert np.sqrt(np.mean(pos_err(res, log) ** 2)) < 1.5


@pytest.mark.skipif(not icp_available(), reason="graphnav.scan.weighted_icp not in this build (branch icp)")
def test_icp_motion_on_marina(marina_log):
    res = run_ekf(marina_log.sliced(None, marina_log.t0 + 30.0), motion="icp")
    assert len(res.icp_ms) > 0 and np.all(np.isfinite(res.trajectory.poses))
