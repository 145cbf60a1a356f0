"""The EKF's vessel motion (``motion="vessel"``): a boat's instruments without an IMU or odometer -- GNSS,
compass, GNSS velocity, speed through water -- in a constant-velocity filter with the graph's vessel
noise. Known answers on synthetic boats with exact truth, and the discretisation against Van Loan's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from graphnav import estimators
from graphnav.estimators.ekf import _unmet, auto_motion, run_ekf
from graphnav.estimators.ekf_online import EkfOnline
from graphnav.estimators.ins_ekf import InsEkf
from graphnav.evaluation.metrics import ate
from graphnav.log import ODOMETRY_FROM_ROT, Gnss, GnssVelocity, Heading, NavLog, Odometry, Truth, WaterSpeed


def crabbing_boat(n: int = 400, *, v: float = 2.0, w_deg: float = 1.0, current=(0.3, -0.25), gnss_sigma: float = 2.0,
                  seed: int = 0, water: bool = True) -> NavLog:
    """A boat at ``v`` through the water turning ``w`` in a constant ``current`` (course != heading):
    GNSS fixes (white, ``gnss_sigma``), compass (0.5 deg), GNSS velocity (0.05 m/s) and, with ``water``,
    speed through water (0.05 m/s), all at 1 Hz."""
    rng = np.random.default_rng(seed)
    w = math.radians(w_deg)
    recs: list = []
    for k in range(n + 1):
        t = float(k)
        yaw = w * t
        x = v / w * math.sin(yaw) + current[0] * t
        y = v / w * (1.0 - math.cos(yaw)) + current[1] * t
        vx, vy = v * math.cos(yaw) + current[0], v * math.sin(yaw) + current[1]
        recs += [Truth(t, x, y, math.remainder(yaw, 2 * math.pi)),
                 Gnss(t, x + rng.normal(0, gnss_sigma), y + rng.normal(0, gnss_sigma), gnss_sigma),
                 Heading(t, math.remainder(yaw + rng.normal(0, math.radians(0.5)), 2 * math.pi), math.radians(0.5)),
                 GnssVelocity(t, vx + rng.normal(0, 0.05), vy + rng.normal(0, 0.05), 0.05)]
        if water and k:
            recs.append(WaterSpeed(t + 0.5, v + rng.normal(0, 0.05), 0.05))
    return NavLog.from_unsorted(recs)


def test_vessel_prediction_is_the_exact_discretisation_of_white_noise_acceleration():
    """Q of :meth:`InsEkf.predict_vessel` against Van Loan's matrix exponential of the continuous model
    (position integrating velocity; acceleration, heading and position walk white)."""
    qa, qy, qp, T = 0.3, math.radians(5.0), 0.4, 1.7
    f = InsEkf(np.zeros(5), np.zeros((5, 5)), bias=False, current=False, acc_density=0.0, gyro_density=0.0)
    f.x[3:5] = [1.0, -2.0]
    f.predict_vessel(T, accel_density=qa, yaw_density=qy, position_walk=qp)
    A = np.zeros((5, 5))
    A[0, 3] = A[1, 4] = 1.0
    Qc = np.diag([qp**2, qp**2, qy**2, qa**2, qa**2])
    M = expm(np.block([[-A, Qc], [np.zeros((5, 5)), A.T]]) * T)
    Phi = M[5:, 5:].T
    Qd = Phi @ M[:5, 5:]
    assert np.allclose(f.P, Qd, atol=1e-12)
    assert np.allclose(f.x[:2], [T * 1.0, -2.0 * T])


def test_a_boat_crabbing_in_a_current_is_tracked_and_the_current_estimated():
    """No IMU, no odometer: ``auto`` is the vessel motion (as the graph's), the track beats its 2 m fixes
    several times over, the current comes out within 0.1 m/s, and the covariance is honest."""
    log = crabbing_boat()
    assert auto_motion(log) == "vessel" and _unmet(log) is None
    r = run_ekf(log)
    assert r.info["motion"] == "vessel" and r.info["current_states"] and not r.info["bias_states"]
    ref = log.truth()
    err = ate(r.trajectory, ref)["rmse"]
    assert err < 0.35 * 2.0 * math.sqrt(2), err  # the fixes' own error is 2.83 m
    cx, cy = r.info["current_final"]
    assert abs(cx - 0.3) < 0.1 and abs(cy + 0.25) < 0.1, (cx, cy)
    e = r.trajectory.poses[:, :2] - ref.interpolate(r.trajectory.t)[:, :2]
    nees = float(np.einsum("ni,nij,nj->n", e, np.linalg.inv(r.trajectory.cov[:, :2, :2]), e).mean())
    assert 0.5 < nees < 3.0, nees
    # the heading is the compass's, not the course (which differs by the crab angle)
    dyaw = r.trajectory.poses[:, 2] - ref.interpolate(r.trajectory.t)[:, 2]
    dyaw = np.remainder(dyaw + math.pi, 2 * math.pi) - math.pi
    assert np.sqrt(np.mean(dyaw[10:] ** 2)) < math.radians(1.0)


def test_gnss_alone_runs_the_vessel_model_and_rate_of_turn_is_no_odometer():
    log = crabbing_boat(n=60, water=False)
    fixes_only = log.without(lambda r: r.kind in ("heading", "gnss_velocity"))
    assert auto_motion(fixes_only) == "vessel" and _unmet(fixes_only) is None
    assert ate(run_ekf(fixes_only).trajectory, log.truth())["rmse"] < 2.0 * math.sqrt(2)
    # ROT + SOG records (NMEA ROT, N2K 127251) are no odometer: the vessel motion, SOG an update
    rot = NavLog.from_unsorted(list(log.records) + [Odometry(t + 0.2, 2.0, math.radians(1.0)) for t in range(60)],
                               meta={"odometry": ODOMETRY_FROM_ROT})
    assert auto_motion(rot) == "vessel"
    a = NavLog.from_unsorted(list(rot.records))  # the same records as a robot's odometer
    assert auto_motion(a) == "odometry"
    assert "odometry" in estimators.get("ekf").inputs(rot, {})
    nothing = NavLog.from_unsorted([Heading(float(t), 0.0, 0.01) for t in range(5)])
    assert "needs" in (_unmet(nothing) or "")


@pytest.mark.parametrize("emit", ["all"])
def test_online_vessel_ekf_is_the_batch_filter(emit):
    """The live adapter with ``motion="vessel"`` gives the batch filter's estimates at the same times,
    and reports SOG/COG from the velocity states."""
    log = crabbing_boat(n=80)
    b = run_ekf(log, motion="vessel", vessel_position_walk=0.0)
    on = EkfOnline(motion="vessel", emit=emit, current=True)
    est = [e for e in (on.add(r) for r in log.records if r.kind != "truth") if e is not None]
    assert len(est) > 60
    t = np.array([e.t for e in est])
    p = np.array([e.vec for e in est])
    i = np.searchsorted(b.trajectory.t, t)
    ok = (i < len(b.trajectory.t)) & (b.trajectory.t[np.minimum(i, len(b.trajectory.t) - 1)] == t)
    assert ok.sum() > 60
    late = t[ok] > 5.0  # after both have started from the first epoch
    assert np.abs(p[ok][late, :2] - b.trajectory.poses[i[ok]][late, :2]).max() < 0.2
    yaw = np.radians(1.0) * t[-20:]
    true_sog = np.hypot(2.0 * np.cos(yaw) + 0.3, 2.0 * np.sin(yaw) - 0.25)
    d = np.array([e.sog for e in est[-20:]]) - true_sog
    assert np.sqrt(np.mean(d**2)) < 0.1 and np.abs(d).max() < 0.3, d


def test_water_speed_with_leeway_is_the_graphs_model_and_its_jacobian_exact():
    """The 2D water-speed update (along the bow the log's sigma, across it the leeway): innovation and
    Jacobian against finite differences of ``h(x) = R(yaw)^T (v - c)``."""
    x0 = np.array([1.0, 2.0, 0.7, 1.5, -0.4, 0.2, 0.3])
    f = InsEkf(x0.copy(), np.eye(7), bias=False, current=True, acc_density=0.0, gyro_density=0.0)
    got = {}
    f._update = lambda sensor, nu, H, R, t=None, **kw: got.update(nu=nu, H=H, R=R) or True  # type: ignore

    def h(x):
        c, s = math.cos(x[2]), math.sin(x[2])
        u = x[3:5] - x[5:7]
        return np.array([c * u[0] + s * u[1], -s * u[0] + c * u[1]])

    f.update_water_speed(1.2, 0.1, leeway=0.15)
    assert np.allclose(got["nu"], np.array([1.2, 0.0]) - h(x0))
    J = np.array([(h(x0 + d) - h(x0 - d)) / 2e-6 for d in np.eye(7) * 1e-6]).T
    assert np.allclose(got["H"], J, atol=1e-8)
    assert np.allclose(got["R"], np.diag([0.01, 0.0225]))


def test_a_rate_of_turn_with_sog_gives_way_to_the_imu():
    """Solent (a SOG sensor and a ROT gyro beside a 1 Hz IMU, a 0.85 m/s current): ``auto`` takes the IMU,
    which beats the unicycle on the same log; a robot's odometer (no such mark) keeps the odometry."""
    from graphnav.sim.solent import SolentConfig, simulate_solent

    log = simulate_solent(SolentConfig(scenario=1, seed=0))
    assert log.meta["odometry"] == ODOMETRY_FROM_ROT and auto_motion(log) == "imu"
    ref = log.truth()
    e_auto = ate(run_ekf(log).trajectory, ref)["rmse"]
    e_uni = ate(run_ekf(log, motion="odometry").trajectory, ref)["rmse"]
    assert e_auto < 0.5 * e_uni, (e_auto, e_uni)
    robot = NavLog.from_unsorted(list(log.records), meta={k: v for k, v in log.meta.items() if k != "odometry"})
    assert auto_motion(robot) == "odometry"
