"""Sensor mounts (graphnav.graph.mounts, docs/mounts.md) on known answers: a boat turning on a circle with
its GNSS antenna 3 m forward of the body origin (with the lever arm the error is at the fixes' noise
level, without it it is the arm), a LiDAR mounted off the origin (its sensor-frame matches conjugated
to the body's motion), an IMU off the origin (the centripetal term removed), the options' checks."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

import factors as F
from graphnav.config import OptionError
from graphnav.graph.builder import GraphBuilder
from graphnav.graph.log_runs import run
from graphnav.graph.mounts import Mount, merged, parse_mounts
from graphnav.graph.scan_factors import conjugate
from graphnav.graph.smoother_config import SmootherConfig
from graphnav.log import Gnss, Heading, Imu, NavLog, Odometry, Scan, Truth

R_CIRCLE, SPEED = 20.0, 2.0
OMEGA = SPEED / R_CIRCLE  # 0.1 rad/s


def circle_pose(t: float) -> tuple[float, float, float]:
    """The body on a circle of 20 m at 2 m/s, turning left, starting at the origin heading east."""
    yaw = OMEGA * t
    return R_CIRCLE * math.sin(yaw), R_CIRCLE - R_CIRCLE * math.cos(yaw), yaw


def circle_log(arm: tuple[float, float] = (3.0, 0.0), duration: float = 40.0, sigma: float = 0.05,
               meta: dict | None = None, seed: int = 0, arm2: tuple[float, float] | None = None) -> NavLog:
    """Odometry at 10 Hz, the antenna's fixes (noise ``sigma``) and a compass at 1 Hz, truth at 1 Hz;
    with ``arm2`` a second receiver (source "B", the first "A") at 1 Hz half a second later."""
    rng = np.random.default_rng(seed)
    recs = []
    for i in range(int(duration * 10) + 1):
        t = 0.1 * i
        x, y, yaw = circle_pose(t)
        recs.append(Odometry(t, SPEED + rng.normal(0, 0.01), OMEGA + rng.normal(0, 0.001), 0.01, 0.001))
        if i % 10 == 0:
            ax, ay = F.antenna_position(gtsam.Pose2(x, y, yaw), arm)
            recs.append(Gnss(t, ax + rng.normal(0, sigma), ay + rng.normal(0, sigma), sigma,
                             source="A" if arm2 is not None else ""))
            recs.append(Heading(t, yaw + rng.normal(0, 0.005), 0.005))
            recs.append(Truth(t, x, y, yaw))
        if arm2 is not None and i % 10 == 5:
            bx, by = F.antenna_position(gtsam.Pose2(x, y, yaw), arm2)
            recs.append(Gnss(t, bx + rng.normal(0, sigma), by + rng.normal(0, sigma), sigma, source="B"))
    return NavLog(recs, [], {"name": "circle", **(meta or {})})


def position_errors(log: NavLog, **options) -> np.ndarray:
    est = run(log, "isam2", compass_bias=False, **options).trajectory
    truth = log.truth()
    idx = [int(np.argmin(abs(est.t - t))) for t in truth.t]
    return np.hypot(est.poses[idx, 0] - truth.poses[:, 0], est.poses[idx, 1] - truth.poses[:, 1])


def test_gnss_lever_arm_on_a_circle_planar():
    log = circle_log()
    without = position_errors(log)
    # the error is the arm (a little less: fixes 3 m off the modelled body are found noisier than stated,
    # graph.measurements.GnssScale, and the odometry's circle pulls the track part of the way)
    assert 2.4 < np.median(without) < 3.1
    with_arm = position_errors(log, mounts={"gnss": {"x": 3.0}})
    assert np.median(with_arm) < 0.05 and with_arm.max() < 0.15  # noise level (sigma 0.05 m per axis)


def test_gnss_lever_arm_from_the_log_meta_and_on_the_pose3_graph():
    """The mount stated in the log's meta applies as the option does; on the Pose3 graph through
    GPSFactorArm (its height is not used: roll and pitch are not observed)."""
    log = circle_log(arm=(3.0, -1.0), meta={"mounts": {"gnss": {"x": 3.0, "y": -1.0, "z": 2.0}}})
    assert np.median(position_errors(log)) < 0.05
    assert np.median(position_errors(log, motion="vessel")) < 0.07
    # the option wins over the meta, per sensor: without the arm the fixes disagree with the odometry's
    # circle by up to hypot(3, 1) m (how far the track follows them depends on how much noisier than
    # stated the closing step finds them: graph.solution, gnss_inflated)
    assert np.median(position_errors(log, mounts={"gnss": {}})) > 0.5


def test_two_receivers_each_at_its_antenna():
    """Two GNSS sources on one bus, antennas 3 m forward and 2 m aft + 1 m to port: per-source mounts
    (gnss@A, gnss@B) bring both to the noise level and every fix is used; one mount for both leaves
    the second receiver's fixes 5 m off: the gate and the batch's residual test throw them out."""
    log = circle_log(arm=(3.0, 0.0), arm2=(-2.0, 1.0))
    n_b = sum(1 for r in log.of("gnss") if r.source == "B")

    def solve(mounts):
        r = run(log, "isam2", compass_bias=False, mounts=mounts)
        return r, r.info.get("gnss_rejected", 0) + r.info.get("gnss_dropped_after_lm", 0)

    both, left_out = solve({"gnss@A": {"x": 3.0}, "gnss@B": {"x": -2.0, "y": 1.0}})
    assert left_out == 0
    truth = log.truth()
    idx = [int(np.argmin(abs(both.trajectory.t - t))) for t in truth.t]
    err = np.hypot(*(both.trajectory.poses[idx, :2] - truth.poses[:, :2]).T)
    assert np.median(err) < 0.05
    _, left_out = solve({"gnss": {"x": 3.0}})
    assert left_out >= 0.9 * n_b


def test_antenna_factor_jacobian_is_numerical_derivative():
    f = F.gnss_factor(F.X(0), 1.0, 2.0, 0.5, robust=None, arm=(3.0, -1.2))
    pose = gtsam.Pose2(0.4, -0.3, 0.7)
    v = gtsam.Values()
    v.insert(F.X(0), pose)
    J = f.linearize(v).jacobian()[0] * 0.5  # whitened by 1/sigma
    num = np.zeros((2, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = 1e-6
        vp, vm = gtsam.Values(), gtsam.Values()
        vp.insert(F.X(0), pose.retract(d))
        vm.insert(F.X(0), pose.retract(-d))
        num[:, j] = (f.unwhitenedError(vp) - f.unwhitenedError(vm)) / 2e-6
    np.testing.assert_allclose(J, num, atol=1e-6)
    # zero arm: the native factor
    assert isinstance(F.gnss_factor(F.X(0), 1.0, 2.0, 0.5, arm=(0.0, 0.0)), gtsam.NonlinearFactor)
    assert type(F.gnss_factor(F.X(0), 1.0, 2.0, 0.5, robust=None)).__name__ == "PoseTranslationPrior2D"


def test_lidar_extrinsic_conjugates_the_match():
    """A matcher that returns the sensor's true relative motion: with the extrinsic the smoothed track
    is the truth (to the match's noise), without it the track drifts off the circle."""
    mount = (1.5, 0.5, 0.2)
    E = gtsam.Pose2(*mount)
    times = np.arange(0.0, 20.01, 0.5)
    recs = []
    for t in times:
        recs.append(Scan(float(t), np.full(8, 5.0), np.linspace(-3.0, 3.0, 8)))
        recs.append(Truth(float(t), *circle_pose(float(t))))
    log = NavLog(recs, [], {"name": "lidar-circle"})

    def matcher(cur, prev, init, init_cov=None, in_graph=False):
        body = gtsam.Pose2(*circle_pose(prev.t)).between(gtsam.Pose2(*circle_pose(cur.t)))
        sensor = E.inverse().compose(body).compose(E)
        return True, np.array([sensor.x(), sensor.y(), sensor.theta()]), np.diag([1e-4, 1e-4, 1e-6])

    def final_error(**options):
        est = run(log, "batch", matcher=matcher, loops=False, icp_gate=None, **options).trajectory
        x, y, _ = circle_pose(20.0)
        return math.hypot(est.poses[-1, 0] - x, est.poses[-1, 1] - y)

    assert final_error(mounts={"lidar": {"x": mount[0], "y": mount[1], "yaw": mount[2]}}) < 0.01
    assert final_error() > 1.0
    # conjugation there and back is the identity; the covariance follows the adjoint
    p, c = conjugate(np.array([1.0, 0.2, 0.1]), np.diag([0.01, 0.02, 0.003]), E)
    q, c2 = conjugate(p, c, E.inverse())
    np.testing.assert_allclose(q, [1.0, 0.2, 0.1], atol=1e-12)
    np.testing.assert_allclose(c2, np.diag([0.01, 0.02, 0.003]), atol=1e-12)


def test_imu_mount_removes_the_centripetal_acceleration():
    """An IMU 3 m forward on a hull turning in place at 0.5 rad/s reads -omega^2 3 m/s^2: with the mount
    the preintegrated velocity stays zero, without it the IMU seems to accelerate aft."""
    w, r = 0.5, 3.0

    def velocity(mounts):
        b = GraphBuilder(SmootherConfig(motion="imu", mounts=mounts), imu=True)
        for i in range(201):
            b.motion.imu.add(Imu(0.01 * i, -w * w * r, 0.0, w))
        pim = b.motion.imu.preintegrate(gtsam.imuBias.ConstantBias(), 0.0, 2.0)
        return np.asarray(pim.predict(gtsam.NavState(), gtsam.imuBias.ConstantBias()).velocity())

    assert np.linalg.norm(velocity({"imu": {"x": r}})) < 0.01  # (the planar mid-step rotation: 4 mm/s)
    assert np.linalg.norm(velocity({})) > 1.0


@pytest.mark.parametrize("mounts,where", [
    ({"radar": {"x": 1}}, "mounts.radar"),
    ({"gnss@": {"x": 1}}, "mounts.gnss@"),
    ({"gnss@52": {"x": float("inf")}}, "mounts.gnss@52.x"),
    ({"gnss": {"forward": 1}}, "mounts.gnss.forward"),
    ({"gnss": {"x": float("nan")}}, "mounts.gnss.x"),
    ({"gnss": {"x": 1e9}}, "mounts.gnss.x"),
    ({"lidar": {"yaw": 100.0}}, "mounts.lidar.yaw"),
    ({"imu": [1, 2, 3]}, "mounts.imu"),
    ("gnss", "mounts"),
])
def test_bad_mounts_name_the_field(mounts, where):
    with pytest.raises(OptionError) as exc:
        SmootherConfig(mounts=mounts)
    assert exc.value.where == where


def test_mounts_merge_meta_and_option():
    m = merged({"gnss": {"x": 1.0}, "lidar": {"y": 2.0}}, {"gnss": {"x": 3.0}})
    assert m == {"gnss": Mount(x=3.0), "lidar": Mount(y=2.0)}
    assert parse_mounts(None) == {} and Mount().is_identity
    with pytest.raises(OptionError, match="log meta mounts.gnss.z"):
        merged({"gnss": {"z": "high"}}, {})
