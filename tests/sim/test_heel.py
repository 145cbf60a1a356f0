"""graphnav.sim.heel: a planar log's IMU made 6-axis on a heeled, rolling hull, checked by GTSAM's own
preintegration from the true state (a closed loop with the graph's IMU model)."""

from __future__ import annotations

import math
from pathlib import Path

import gtsam
import numpy as np
import pytest

from graphnav.graph.imu_chain import ImuChain, ImuConfig
from graphnav.io.dispatch import load_log
from graphnav.log import Scan
from graphnav.sim.harbour3d import rot_zyx
from graphnav.sim.heel import heeled, roll_pitch_at, tilted_scan

HARBOUR = Path(__file__).resolve().parents[2] / "data" / "harbour.npz"


@pytest.fixture(scope="module")
def logs():
    if not HARBOUR.exists():
        pytest.skip("data/harbour.npz is absent")
    base = load_log(HARBOUR).sliced(0.0, 120.0)
    return base, heeled(base, math.radians(10.0), math.radians(5.0), seed=3, attitude_hz=10.0)


def _prediction_errors(log, tilt):
    tr = log.truth()
    chain = ImuChain(ImuConfig(), log.meta.get("imu"))
    for r in log.of("imu"):
        chain.add(r)
    yaw = np.unwrap(tr.poses[:, 2])
    out = []
    for t0 in np.arange(10.0, 100.0, 9.0):
        x, y = (np.interp(t0, tr.t, tr.poses[:, i]) for i in (0, 1))
        v = [(np.interp(t0 + 0.05, tr.t, tr.poses[:, i]) - np.interp(t0 - 0.05, tr.t, tr.poses[:, i])) / 0.1
             for i in (0, 1)]
        roll, pitch = tilt(t0)
        pose = gtsam.Pose3(gtsam.Rot3.Ypr(float(np.interp(t0, tr.t, yaw)), pitch, roll), np.array([x, y, 0.0]))
        pim = chain.preintegrate(gtsam.imuBias.ConstantBias(), t0, t0 + 2.0)
        s = pim.predict(gtsam.NavState(pose, np.array([*v, 0.0])), gtsam.imuBias.ConstantBias())
        x1, y1 = (np.interp(t0 + 2.0, tr.t, tr.poses[:, i]) for i in (0, 1))
        out.append(math.hypot(s.pose().translation()[0] - x1, s.pose().translation()[1] - y1))
    return np.array(out)


def test_heeled_records_carry_gravity_and_the_hull_motion(logs):
    base, heel = logs
    imu = heel.of("imu")
    assert all(r.six_axis for r in imu) and len(imu) == len(base.of("imu"))
    assert np.mean([r.az for r in imu]) == pytest.approx(9.80665 * math.cos(math.radians(10.0)), abs=0.05)
    assert len(heel.of("attitude")) == pytest.approx(1200, abs=2)

    def true_tilt(t):
        r, p = roll_pitch_at(heel, np.array([t]))
        return float(r[0]), float(p[0])

    e_true = _prediction_errors(heel, true_tilt)
    e_level = _prediction_errors(heel, lambda t: (0.0, 0.0))
    e_planar = _prediction_errors(base, lambda t: (0.0, 0.0))
    assert np.median(e_true) < 0.05 and np.max(e_true) < 0.1  # consistent with the planar records' ...
    assert np.median(e_planar) < 0.05  # ... own 2 s prediction
    assert np.median(e_level) > 1.0  # the heel is in the records: taken as level, gravity leaks (~1.7 m/s^2)


def test_bearings_are_azimuths_in_the_hull_plane(logs):
    base, heel = logs
    b0, b1 = base.of("beacon"), heel.of("beacon")
    d = np.array([(b.bearing - a.bearing + math.pi) % (2 * math.pi) - math.pi for a, b in zip(b0, b1, strict=True)])
    ahead = np.array([abs(math.sin(a.bearing)) < 0.05 or abs(math.cos(a.bearing)) < 0.05 for a in b0])
    assert np.max(np.abs(d[ahead])) < math.radians(0.3)  # ahead, astern and abeam the heel does not move them
    assert np.max(np.abs(d)) > math.radians(0.2)  # elsewhere it does (tan-like, ~0.4 deg at 10 deg heel)


def test_a_heeled_six_axis_log_is_held_at_the_surface_and_its_heel(logs):
    """isam2 on 120 s of the heeled harbour: the keyframes' height stays at the sea surface (surface_sigma) and
    the first roll comes from gravity (anchor.sigma_tilt_deg), not level."""
    import factors as F
    from graphnav.graph.navigator import Navigator

    _, heel = logs
    nav = Navigator.for_log(heel)
    for r in heel:
        nav.add(r)
    nav.flush()
    nav.result()
    t = np.array(nav.builder.kf_t)
    poses = [nav._final.atPose3(F.X(k)) for k in range(len(t))]
    roll, _ = roll_pitch_at(heel, t)
    assert max(abs(p.translation()[2]) for p in poses) < 1.0
    d_roll = np.degrees([p.rotation().roll() for p in poses]) - np.degrees(roll)
    assert abs(np.mean(d_roll)) < 0.5 and np.degrees(poses[0].rotation().roll()) > 5.0  # heeled ~10 deg from the start


def test_tilted_scan_known_answers():
    """Level: unchanged. Rolled by phi: straight ahead the beam stays level (a wall 10 m ahead at 10 m);
    abeam it climbs (a wall 10 m abeam at 10 / cos phi, still abeam); a return pushed beyond the
    stated maximum becomes missing; a missing return stays missing."""
    ang = np.array([-math.pi / 2, 0.0, 0.3, math.pi / 2])
    scan = Scan(1.0, np.array([10.0, 10.0, math.inf, 10.0]), ang, 10.5)
    same = tilted_scan(scan, 0.0, 0.0)
    np.testing.assert_allclose(same.ranges[[0, 1, 3]], [10.0, 10.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(same.angles, ang, atol=1e-12)
    phi = math.radians(15.0)
    t = tilted_scan(Scan(1.0, np.array([10.0, 10.0, math.inf, 10.0]), ang, 20.0), phi, 0.0)
    np.testing.assert_allclose(t.ranges[[0, 1, 3]], [10.0 / math.cos(phi), 10.0, 10.0 / math.cos(phi)], rtol=1e-12)
    np.testing.assert_allclose(t.angles[[0, 1, 3]], [-math.pi / 2, 0.0, math.pi / 2], atol=1e-12)
    assert not np.isfinite(t.ranges[2])
    cut = tilted_scan(scan, math.radians(30.0), 0.0)  # 10 / cos 30 = 11.5 > 10.5: missing now
    assert cut.valid().tolist() == [False, True, False, False]
    th = math.radians(10.0)  # pitched: ahead the beam climbs, abeam it stays level
    p = tilted_scan(Scan(1.0, np.array([10.0, 10.0, math.inf, 10.0]), ang, 20.0), 0.0, th)
    np.testing.assert_allclose(p.ranges[[0, 1, 3]], [10.0, 10.0 / math.cos(th), 10.0], rtol=1e-12)


def test_heeled_scans_are_the_hull_plane_slices(logs):
    """Every scan of a heeled log is its level scan lifted into the hull's plane at its time's roll and
    pitch: the returns' horizontal points are the level ones (the walls did not move)."""
    level, tilt = logs[0], logs[1]
    ls, ts = level.of("scan"), tilt.of("scan")
    assert len(ls) == len(ts) > 10
    roll, pitch = roll_pitch_at(tilt, np.array([s.t for s in ts]))
    assert np.ptp(roll) > math.radians(1.0)
    for s0, s1, ph, th in list(zip(ls, ts, roll, pitch, strict=True))[:: max(1, len(ls) // 20)]:
        v0, v1 = s0.valid(), s1.valid()
        p1 = np.stack([s1.ranges[v1] * np.cos(s1.angles[v1]), s1.ranges[v1] * np.sin(s1.angles[v1]),
                       np.zeros(v1.sum())], axis=1) @ rot_zyx(0.0, th, ph).T  # body -> levelled
        p0 = np.stack([s0.ranges[v0] * np.cos(s0.angles[v0]), s0.ranges[v0] * np.sin(s0.angles[v0])], axis=1)
        d = np.min(np.hypot(p1[:, None, 0] - p0[None, :, 0], p1[:, None, 1] - p0[None, :, 1]), axis=1)
        assert np.max(d) < 1e-9
