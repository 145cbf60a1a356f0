"""The IMU factor graph (graphnav.graph.imu_motion, factors.imu) on synthetic logs with exact truth."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

import factors as F
from graphnav import estimators
from graphnav.evaluation.metrics import ate, heading_error
from graphnav.graph.imu_motion import (
    ImuGraphConfig,
    run_batch,
    run_fixed_lag,
    run_isam2,
    wants_imu_graph,
    world_cov_planar,
)
from graphnav.log import Gnss, Heading, Imu, NavLog, PosePrior, Truth
from graphnav.sim.solent import simulate_solent

FAST = {"covariances": False}


def turn_log(v: float = 2.0, w_deg: float = 2.0, n: int = 120, *, bias=(0.0, 0.0, 0.0), gnss_sigma: float = 0.5,
             gnss_noise: float = 0.0, compass_noise_deg: float = 0.0, seed: int = 0,
             jump: tuple[int, int, float] | None = None, imu_rate: int = 1) -> NavLog:
    """Constant speed ``v`` and yaw rate ``w`` from (0, 0, yaw 0) (``w = 0``: a straight line), GNSS
    and compass at 1 Hz, IMU at ``imu_rate`` Hz: the exact body-frame acceleration (0, v w) and
    rate w, plus ``bias``."""
    w = math.radians(w_deg)
    rng = np.random.default_rng(seed)
    t = np.arange(n + 1, dtype=float)
    yaw = w * t
    if w:
        x, y = v / w * np.sin(yaw), v / w * (1.0 - np.cos(yaw))
    else:
        x, y = v * t, np.zeros_like(t)
    recs: list = [PosePrior(0.0, 0.0, 0.0, 0.0, 0.1, math.radians(0.5))]
    for k in range(n + 1):
        gx, gy = x[k] + rng.normal(0, gnss_noise), y[k] + rng.normal(0, gnss_noise)
        if jump is not None and jump[0] <= k < jump[1]:
            gx += jump[2]
        recs += [Truth(t[k], x[k], y[k], float((yaw[k] + math.pi) % (2 * math.pi) - math.pi)),
                 Gnss(t[k], gx, gy, gnss_sigma),
                 Heading(t[k], float(yaw[k] + rng.normal(0, math.radians(compass_noise_deg))), math.radians(0.5))]
        for j in range(imu_rate if k else 0):
            recs.append(Imu(t[k] - j / imu_rate, bias[0], v * w + bias[1], w + bias[2]))
    return NavLog.from_unsorted(recs, meta={"initial_velocity": [v, 0.0]})


def test_preintegration_matches_closed_form_kinematics():
    p = F.planar_imu_params(0.004, 1e-3)
    # straight line, constant forward acceleration: p = v0 T + a T^2 / 2, v = v0 + a T (exact)
    pim = F.preintegrate(p, gtsam.imuBias.ConstantBias(), [(0.3, 0.0, 0.0, 1.0)] * 4, substeps=1)
    s = pim.predict(gtsam.NavState(F.planar_pose(1.0, 2.0, math.pi / 2), np.array([0.0, 1.0, 0.0])),
                    gtsam.imuBias.ConstantBias())
    np.testing.assert_allclose(s.pose().translation(), [1.0, 2.0 + 4.0 + 0.5 * 0.3 * 16, 0.0], atol=1e-12)
    np.testing.assert_allclose(s.velocity(), [0.0, 1.0 + 0.3 * 4, 0.0], atol=1e-12)
    # constant turn: centripetal body acceleration v w, the arc of radius v / w
    v, w, T = 2.0, math.radians(3.0), 30.0
    pim = F.preintegrate(p, gtsam.imuBias.ConstantBias(), [(0.0, v * w, w, 1.0)] * int(T), substeps=4)
    s = pim.predict(gtsam.NavState(F.planar_pose(0.0, 0.0, 0.0), np.array([v, 0.0, 0.0])),
                    gtsam.imuBias.ConstantBias())
    xyz = F.pose_xy_yaw(s.pose())
    arc = [v / w * math.sin(w * T), v / w * (1 - math.cos(w * T)), w * T]
    np.testing.assert_allclose(xyz, arc, atol=1e-3)  # second order in the substep
    np.testing.assert_allclose(s.velocity()[:2], [v * math.cos(w * T), v * math.sin(w * T)], atol=3e-5)
    # a bias in the preintegration is removed: biased samples + that bias == unbiased samples
    b = F.bias_vector(0.02, -0.01, math.radians(0.3))
    pb = F.preintegrate(p, b, [(0.02, v * w - 0.01, w + math.radians(0.3), 1.0)] * int(T), substeps=4)
    sb = pb.predict(gtsam.NavState(F.planar_pose(0.0, 0.0, 0.0), np.array([v, 0.0, 0.0])), b)
    np.testing.assert_allclose(F.pose_xy_yaw(sb.pose()), xyz, atol=1e-9)


def test_gnss_compass_and_bias_factor_errors_by_hand():
    vals = gtsam.Values()
    vals.insert(F.X(0), F.planar_pose(3.0, 4.0, 0.3))
    g = F.gnss3_factor(F.X(0), 1.0, 1.0, 2.0, robust=None)
    np.testing.assert_allclose(g.unwhitenedError(vals), [2.0, 3.0, 0.0], atol=1e-12)
    assert g.error(vals) == pytest.approx(0.5 * 13.0 / 4.0)
    c = F.compass3_factor(F.X(0), 0.25, math.radians(1.0), robust=None)
    np.testing.assert_allclose(c.unwhitenedError(vals), [0.0, 0.0, 0.05], atol=1e-12)
    assert c.error(vals) == pytest.approx(0.5 * (0.05 / math.radians(1.0)) ** 2)
    h = F.compass3_factor(F.X(0), 0.25, math.radians(1.0))  # Huber: linear beyond k = 1.345 sigma
    r = 0.05 / math.radians(1.0)
    assert h.error(vals) == pytest.approx(1.345 * (r - 1.345 / 2))
    vals.insert(F.IB(0), F.bias_vector())
    vals.insert(F.IB(1), F.bias_vector(0.002, 0.0, 0.0))
    bb = F.bias_between(0, 1, 1e-3, 1e-4, 4.0)  # sigma = rw sqrt(dt) = 2e-3
    assert bb.error(vals) == pytest.approx(0.5)


def test_world_cov_planar_rotates_the_body_translation_block():
    c6 = np.diag([1e-6, 1e-6, 0.01, 4.0, 1.0, 1e-6])
    c = world_cov_planar(F.planar_pose(0, 0, math.pi / 2), c6)
    np.testing.assert_allclose(np.diag(c), [1.0, 4.0, 0.01], atol=1e-12)  # body x (4 m^2) -> world y


@pytest.mark.parametrize("w_deg", [0.0, 2.0])
def test_noise_free_imu_recovers_truth(w_deg):
    log = turn_log(w_deg=w_deg, n=100)
    for run in (run_isam2, run_batch):
        r = run(log, substeps=20, **FAST)
        assert ate(r.trajectory, log.truth())["rmse"] < 0.01
        assert heading_error(r.trajectory, log.truth())["rmse"] < 0.01  # deg
        assert np.abs(r.info["bias_final"]).max() < 1e-4
    assert np.max(r.info["planar_residual"]) < 1e-6  # roll, pitch, z stay at 0 (batch)


def test_fast_imu_is_preintegrated_between_gnss_epochs():
    log = turn_log(w_deg=3.0, n=60, imu_rate=10)
    r = run_isam2(log, **FAST)
    assert r.info["keyframes"] == 61  # one per GNSS epoch, not per IMU sample
    assert ate(r.trajectory, log.truth())["rmse"] < 0.01


def test_biases_are_estimated():
    true = (0.02, -0.015, math.radians(0.3))
    log = turn_log(w_deg=1.5, n=240, bias=true, gnss_sigma=1.0, gnss_noise=1.0, compass_noise_deg=0.5, seed=3)
    opts = {"bias_sigma_acc": 0.05, "bias_sigma_gyro_deg": 1.0, **FAST}
    r = run_batch(log, **opts)
    b = np.array(r.info["bias_final"])
    assert abs(b[0] - true[0]) < 2e-3 and abs(b[1] - true[1]) < 2e-3
    assert abs(b[2] - true[2]) < math.radians(0.02)
    assert ate(r.trajectory, log.truth())["rmse"] < 0.5  # 1 m GNSS noise
    iz = run_isam2(log, **opts)
    np.testing.assert_allclose(iz.info["bias_final"], b, atol=5e-4)
    # without the bias states (a tight zero prior and no random walk) the track is much worse
    r0 = run_batch(log, bias_sigma_acc=1e-6, bias_sigma_gyro_deg=1e-5, bias_rw_acc=1e-9, bias_rw_gyro_deg=1e-9, **FAST)
    assert ate(r0.trajectory, log.truth())["rmse"] > 3 * ate(r.trajectory, log.truth())["rmse"]


def test_gnss_jump_is_survived_with_huber():
    jump = (60, 70, 30.0)  # 10 fixes 30 m off (15 sigma)
    base = turn_log(n=150, gnss_sigma=2.0, gnss_noise=2.0, seed=1)
    jumped = turn_log(n=150, gnss_sigma=2.0, gnss_noise=2.0, seed=1, jump=jump)
    ref = base.truth()
    e0 = ate(run_isam2(base, **FAST).trajectory, ref)["rmse"]
    e_h = ate(run_isam2(jumped, **FAST).trajectory, ref)["rmse"]
    e_l2 = ate(run_isam2(jumped, gnss_robust=None, **FAST).trajectory, ref)["rmse"]
    assert e0 < 1.0
    assert e_h < e0 + 1.0  # Huber: the jump costs less than a metre of RMSE
    assert e_l2 > 2 * e_h  # a plain Gaussian is pulled by the jump


@pytest.fixture(scope="module")
def solent():
    return simulate_solent(scenario=1, seed=0, max_steps=250)


def test_solent_isam2_beats_the_ukf_and_batch_agrees(solent):
    ref = solent.truth()
    assert wants_imu_graph(solent)
    iz = estimators.run("isam2", solent)
    assert iz.info["motion"] == "imu" and len(iz.trajectory) == len(ref)
    ukf = estimators.run("ukf", solent)
    e_i, e_u = ate(iz.trajectory, ref)["rmse"], ate(ukf.trajectory, ref)["rmse"]
    assert e_i < 0.7 * e_u
    assert e_i < ate(iz.online, ref)["rmse"] < 1.5 * e_u  # online: the filter's situation
    assert heading_error(iz.trajectory, ref)["rmse"] < heading_error(ukf.trajectory, ref)["rmse"]
    bt = estimators.run("batch", solent, **FAST)
    assert np.max(np.hypot(*(bt.trajectory.poses[:, :2] - iz.trajectory.poses[:, :2]).T)) < 0.3
    # the smoothed covariance is consistent with the errors (position NEES per pose ~ 2)
    err = iz.trajectory.poses[:, :2] - ref.interpolate(iz.trajectory.t)[:, :2]
    nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv(iz.trajectory.cov[:, :2, :2]), err)
    assert 0.3 < nees.mean() < 8.0


def test_motion_option_and_fixed_lag(solent):
    odo = estimators.run("isam2", solent, motion="odometry", **FAST)
    assert "motion" not in odo.info and odo.info["keyframes"] == 2 * len(solent.truth()) - 1  # 0.5 s grid
    with pytest.raises(ValueError, match="motion"):
        estimators.run("isam2", solent, motion="wheels")
    with pytest.raises(ValueError, match="unknown IMU-graph option"):
        estimators.run("batch", solent, scan_stride=2)
    fl = run_fixed_lag(solent, lag=15.0, **FAST)
    ref = solent.truth()
    assert fl.info["motion"] == "imu" and len(fl.trajectory) == len(ref)
    assert ate(fl.trajectory, ref)["rmse"] < ate(estimators.run("ukf", solent).trajectory, ref)["rmse"]


def test_auto_choice_needs_imu_and_gnss_and_no_scans():
    log = turn_log(n=5)
    assert wants_imu_graph(log)
    no_gnss = NavLog.from_unsorted([r for r in log.records if r.kind != "gnss"])
    assert not wants_imu_graph(no_gnss)
    assert ImuGraphConfig.from_options({"substeps": 2}).substeps == 2
