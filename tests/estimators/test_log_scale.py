"""The filters' speed-log scale state ``k`` (the speed through water along the bow is ``k`` x the log's reading;
prior N(1, 0.1^2), a slow random walk; the graph's scale state): a log that reads 0.93 x the true speed through
water is recovered as k = 1/0.93, and the track through a GNSS gap is better than with ``log_scale=false``;
the EKF's Jacobian against finite differences; ``log_scale=false`` is the filter as before."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_ekf_vessel import crabbing_boat
from test_imu_filters import CURRENT, turn_log

from graphnav import estimators
from graphnav.estimators.ekf import run_ekf
from graphnav.estimators.ins_ekf import InsEkf
from graphnav.estimators.ukf import UnscentedNav
from graphnav.log import Gnss, GnssVelocity, NavLog, WaterSpeed

READS = 0.93  # the log reads 7 % low: k = 1/0.93 = 1.0753
GAP = (120.0, 180.0)  # GNSS position and velocity withheld: dead reckoning on the IMU / vessel model and the log


def _log(log: NavLog, factor: float, gap: tuple[float, float] | None) -> NavLog:
    """``log`` with every water-speed reading x ``factor`` and no GNSS position or velocity in ``gap``."""
    recs = [WaterSpeed(r.t, factor * r.v, r.sigma_v) if isinstance(r, WaterSpeed) else r for r in log.records]
    if gap is not None:
        recs = [r for r in recs if not (isinstance(r, (Gnss, GnssVelocity)) and gap[0] < r.t <= gap[1])]
    return NavLog.from_unsorted(recs, meta=log.meta)


def _gap_rmse(res, log: NavLog, gap: tuple[float, float]) -> float:
    tr = res.trajectory
    m = (tr.t > gap[0]) & (tr.t <= gap[1])
    e = tr.poses[m, :2] - log.truth().interpolate(tr.t[m])[:, :2]
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


@pytest.fixture(scope="module")
def under_reading():
    """The IMU filters' turning boat (3 deg/s, 20 Hz biased IMU, GNSS, compass, GNSS velocity, log) in a
    (0.3, -0.2) m/s current, 240 s, its log reading 0.93 x, GNSS out over 120-180 s."""
    return _log(turn_log(seed=2, seconds=240.0, current=CURRENT, velocity=True, water=True), READS, GAP)


@pytest.mark.parametrize("name", ["ekf", "ukf", "ukf-bias", "fuzzy-ukf", "fuzzy-ukf-bias"])
def test_each_filter_finds_the_logs_scale_and_tracks_the_gap_better(under_reading, name):
    """k within 0.015 (2.5 of its sigma) of 1/0.93, the current within 0.05 m/s, and through the 60 s GNSS gap
    the track at most 0.6 x its error with the log taken at face value (measured: 0.48-0.54 m against
    2.3-3.1 m with ``log_scale=false``, seed 2)."""
    log = under_reading
    on = estimators.run(name, log)
    off = estimators.run(name, log, log_scale=False)
    assert on.info["log_scale_state"] is True and off.info["log_scale_state"] is False
    assert "log_scale_final" not in off.info
    k, sk = on.info["log_scale_final"], on.info["log_scale_sigma"]
    assert abs(k - 1.0 / READS) < 0.015, (k, sk)
    assert 0.003 < sk < 0.015
    np.testing.assert_allclose(on.info["current_final"], CURRENT, atol=0.05)
    e_on, e_off = _gap_rmse(on, log, GAP), _gap_rmse(off, log, GAP)
    assert e_on < 0.6 * e_off, (e_on, e_off)


def test_a_calibrated_log_keeps_k_at_1():
    """The same boat with a true log: k stays within 0.01 of 1 (the EKF, the UKF)."""
    log = _log(turn_log(seed=2, seconds=240.0, current=CURRENT, velocity=True, water=True), 1.0, None)
    for name in ("ekf", "ukf"):
        k = estimators.run(name, log).info["log_scale_final"]
        assert abs(k - 1.0) < 0.01, (name, k)


def test_the_vessel_motion_finds_the_scale():
    """No IMU (the EKF's vessel motion, the psaros33 case): the crabbing boat with a log reading 0.93 x, GNSS out
    over 250-310 s: k within 0.015 of 1/0.93, the current's x (across the turn's start) within 0.05 m/s where
    the log at face value puts it 0.13 off, and the gap's track under half its error without the state."""
    gap = (250.0, 310.0)
    log = _log(crabbing_boat(seed=0), READS, gap)
    on, off = run_ekf(log), run_ekf(log, log_scale=False)
    assert on.info["motion"] == "vessel" and on.info["log_scale_state"]
    assert abs(on.info["log_scale_final"] - 1.0 / READS) < 0.015, on.info["log_scale_final"]
    assert abs(on.info["current_final"][0] - 0.3) < 0.05 < abs(off.info["current_final"][0] - 0.3)
    assert _gap_rmse(on, log, gap) < 0.5 * _gap_rmse(off, log, gap)


def test_the_ekf_water_speed_jacobian_with_the_scale_is_exact():
    """The water-speed update with the scale state (the log reads ``(v - c) . e_yaw / k``, across the bow the
    leeway row unchanged): innovation and H against central finite differences, with the IMU bias states
    and the compass bias after the scale."""
    x0 = np.array([1.0, 2.0, 0.7, 1.5, -0.4, 1e-3, -2e-3, 1e-4, 0.2, 0.3, 1.08, 0.02])
    f = InsEkf(x0.copy(), np.eye(12), bias=True, current=True, log_scale=True, compass_bias=True,
               acc_density=0.0, gyro_density=0.0)
    assert (f.ic, f.il, f.ik) == (8, 10, 11)
    got = {}
    f._update = lambda sensor, nu, H, R, t=None, **kw: got.update(nu=nu, H=H, R=R) or True  # type: ignore

    def h(x):
        c, s = math.cos(x[2]), math.sin(x[2])
        u = x[3:5] - x[8:10]
        return np.array([(c * u[0] + s * u[1]) / x[10], -s * u[0] + c * u[1]])

    f.update_water_speed(1.2, 0.1, leeway=0.15)
    assert np.allclose(got["nu"], np.array([1.2, 0.0]) - h(x0))
    J = np.array([(h(x0 + d) - h(x0 - d)) / 2e-6 for d in np.eye(12) * 1e-6]).T
    assert np.allclose(got["H"], J, atol=1e-8)
    assert np.allclose(got["R"], np.diag([0.01, 0.0225]))  # the record's sigma, the leeway: as without k
    assert not got["H"][:, 11].any() and got["H"][0, 10] != 0.0


def test_the_ukf_water_speed_transform_divides_by_k():
    """The unscented water-speed update with the scale state: with a tiny covariance the predicted reading is
    ``(v - c) . e_theta / k`` and ``P_xz`` is ``P H^T`` with the EKF's Jacobian (to first order)."""
    x = np.array([0.0, 0.0, 1.5, -0.4, 0.7, 0.2, 0.3, 1.08])
    P = np.diag([1.0, 1.0, 1e-6, 2e-6, 1e-6, 3e-6, 1e-6, 4e-6])
    f = UnscentedNav(x, P, q_acc=0.0, q_gyro=0.0, current=True, log_scale=True)
    assert (f.ic, f.il, f.ik) == (5, 7, None)
    eps, pzz, pxz = f.water_speed_innovation(1.2)
    c, s = math.cos(0.7), math.sin(0.7)
    along = (1.5 - 0.2) * c + (-0.4 - 0.3) * s
    assert eps[0] == pytest.approx(1.2 - along / 1.08, abs=1e-5)  # (the transform's second-order term: ~1e-6)
    H = np.zeros(8)
    H[2], H[3], H[5], H[6] = c / 1.08, s / 1.08, -c / 1.08, -s / 1.08
    H[4] = (-(1.5 - 0.2) * s + (-0.4 - 0.3) * c) / 1.08
    H[7] = -along / 1.08 ** 2
    np.testing.assert_allclose(pxz[:, 0], P @ H, rtol=2e-3, atol=1e-12)
    assert pzz[0, 0] == pytest.approx(H @ P @ H, rel=2e-3)


#: the last pose and its covariance's trace before the scale state (main at ab5ec52, 2026-12-07): the IMU filters
#: on turn_log(seed=1, 60 s, current, GNSS velocity, log) and the vessel EKF on crabbing_boat(n=120)
BEFORE = {
    "ekf": ([-3.4756243026655227, 49.66387518548478, -2.799813136144341], 0.3792453766533909),
    "ukf": ([-3.4788603270798952, 49.66139114957726, -2.826180750223165], 0.3833361402968333),
    "fuzzy-ukf": ([-3.4519521792943992, 49.952502108066504, -2.825005707105413], 0.3625373251159949),
    "vessel": ([134.95117384340162, 142.3281087781608, 2.0996391299671986], 0.41179264375305646),
}


def test_without_the_state_the_filters_are_as_before():
    """``log_scale=false`` gives the figures of the filters before the state (``BEFORE``, to 1e-9), the state
    vector has no scale entry; without water speed there is no state, and ``log_scale=true`` without the
    current states is refused."""
    log = turn_log(seed=1, seconds=60.0, current=CURRENT, velocity=True, water=True)
    runs = {name: estimators.run(name, log, log_scale=False) for name in ("ekf", "ukf", "fuzzy-ukf")}
    runs["vessel"] = run_ekf(crabbing_boat(n=120), log_scale=False)
    for name, res in runs.items():
        pose, trace = BEFORE[name]
        np.testing.assert_allclose(res.trajectory.poses[-1], pose, rtol=0, atol=1e-9, err_msg=name)
        assert float(res.trajectory.cov[-1].trace()) == pytest.approx(trace, rel=1e-9), name
        assert res.info["log_scale_state"] is False
    assert len(runs["ukf"].info["state_final"]) == 5 + 3 + 2 + 1
    on = estimators.run("ukf", log)
    assert len(on.info["state_final"]) == 5 + 3 + 2 + 1 + 1 and on.info["state_final"][-2] == on.info["log_scale_final"]
    assert not np.allclose(on.trajectory.poses[-1], BEFORE["ukf"][0], rtol=0, atol=1e-9)
    dry = log.without(lambda r: r.kind == "water_speed")
    for name in ("ekf", "ukf"):
        assert estimators.run(name, dry).info["log_scale_state"] is False
        with pytest.raises(ValueError, match="current"):
            estimators.run(name, dry, log_scale=True)
