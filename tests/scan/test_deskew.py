"""De-skewing a 2D LiDAR sweep (graphnav.scan.deskew) against closed forms, and its hooks: the weighted-ICP
points, the graph's matcher, the harbour simulator's sweep and the ROS bag's time_increment."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.log import Scan
from graphnav.scan.deskew import (
    beam_times,
    deskew,
    deskew_mask_points,
    deskew_polar,
    se2_exp,
    se2_log,
    skew,
    sweep_of,
    twist_of,
)
from tests._scan_sim import raycast, room

SWEEP = 0.1  # [s] a 10 Hz spinning LiDAR
N = 360


def _swept(segs: np.ndarray, twist, angles: np.ndarray, sweep: float = SWEEP) -> np.ndarray:
    """Exact ranges of a sweeping sensor starting at the origin: beam i from the pose Exp(t_i xi)."""
    tau = beam_times(angles.size, sweep)
    x, y, th = se2_exp(twist, tau)
    return np.array([raycast(segs, (x[i], y[i], th[i]), angles[i:i + 1], 100.0)[0] for i in range(angles.size)])


def _xy(r: np.ndarray, a: np.ndarray) -> np.ndarray:
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


def test_beam_times_follow_laserscan_convention():
    t = beam_times(4, 0.1)  # the stamp is the first beam; time_increment = sweep / N
    assert t == pytest.approx([0.0, 0.025, 0.05, 0.075])
    assert beam_times(0, 0.1).size == 0


def test_exp_and_log_match_gtsam():
    xi = np.array([1.5, -0.3, math.radians(25.0)])
    for tau in (0.0, 1e-7, 0.3, 2.0):
        x, y, th = se2_exp(xi, np.array([tau]))
        ref = gtsam.Pose2.Expmap(xi * tau)
        assert [x[0], y[0], th[0]] == pytest.approx([ref.x(), ref.y(), ref.theta()], abs=1e-12)
    rel = gtsam.Pose2(2.0, 0.5, 1.0)
    assert se2_log([rel.x(), rel.y(), rel.theta()]) == pytest.approx(gtsam.Pose2.Logmap(rel), abs=1e-12)
    assert twist_of([1.0, 0.0, 0.0], 0.5) == pytest.approx([2.0, 0.0, 0.0])


def test_straight_wall_swept_while_rotating_is_straight_again():
    wall = np.array([[5.0, -30.0, 5.0, 30.0]])  # x = 5 in the stamp's frame
    a = np.radians(np.linspace(-60.0, 60.0, 121))
    twist = np.array([0.0, 0.0, math.radians(30.0)])  # turning on the spot, 3 deg over the sweep
    r = _swept(wall, twist, a)
    raw = _xy(r, a)
    assert np.ptp(raw[:, 0]) > 0.05  # the sweep bends the wall (several cm at 5 m)
    fixed = deskew(raw, beam_times(a.size, SWEEP), twist)
    assert fixed[:, 0] == pytest.approx(np.full(a.size, 5.0), abs=1e-9)


def test_sweep_while_translating_and_turning():
    wall = np.array([[10.0, -40.0, 10.0, 40.0], [-40.0, 3.0, 40.0, 3.0]])  # ahead (x = 10) and abeam (y = 3)
    a = np.radians(np.arange(N) * 1.0 - 180.0)
    for twist in ([4.0, 0.0, 0.0], [3.0, 0.5, math.radians(-20.0)]):
        r = _swept(wall, np.array(twist), a)
        ok = np.isfinite(r)
        fixed = deskew(_xy(r, a)[ok], beam_times(N, SWEEP)[ok], twist)
        on_wall = np.minimum(np.abs(fixed[:, 0] - 10.0), np.abs(fixed[:, 1] - 3.0))
        assert on_wall.max() < 1e-9
        raw_err = np.minimum(np.abs(_xy(r, a)[ok][:, 0] - 10.0), np.abs(_xy(r, a)[ok][:, 1] - 3.0))
        assert raw_err.max() > 0.05  # ... and were off before


def test_zero_twist_is_the_identity():
    p = np.random.default_rng(1).normal(size=(50, 2)) * 10
    tau = beam_times(50, SWEEP)
    assert np.array_equal(deskew(p, tau, [0.0, 0.0, 0.0]), p)
    r, a = np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])
    r2, a2 = deskew_polar(r, a, SWEEP, [0.0, 0.0, 0.0])
    assert r2 == pytest.approx(r, abs=1e-12) and a2 == pytest.approx(a, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(vx=st.floats(-10, 10), vy=st.floats(-3, 3), wz=st.floats(-2, 2), sweep=st.floats(-0.2, 0.2),
       seed=st.integers(0, 2**31 - 1))
def test_deskew_inverts_skew(vx, vy, wz, sweep, seed):
    p = np.random.default_rng(seed).uniform(-50, 50, size=(40, 2))
    tau = beam_times(40, sweep)
    back = deskew(skew(p, tau, [vx, vy, wz]), tau, [vx, vy, wz])
    assert np.abs(back - p).max() < 1e-9


def test_mask_and_scan_points_deskew_only_the_kept_beams():
    from graphnav.scan.weighted_icp import IcpConfig, scan_points

    a = np.radians(np.arange(N) - 180.0)
    r = np.full(N, 8.0)
    r[::7] = np.nan
    scan = Scan(0.0, r, a)
    twist = np.array([2.0, 0.0, 0.3])
    cfg = IcpConfig()
    plain = scan_points(scan, cfg)
    got = scan_points(scan, cfg, sweep_s=SWEEP, twist=twist)
    keep = np.isfinite(r)
    assert np.array_equal(got, deskew(plain, beam_times(N, SWEEP)[keep], twist))
    assert np.array_equal(deskew_mask_points(plain, keep, SWEEP, twist), got)
    assert np.array_equal(scan_points(scan, cfg, sweep_s=0.0, twist=twist), plain)  # no sweep: unchanged


def test_sweep_of_reads_the_meta():
    class L:
        def __init__(self, meta):
            self.meta = meta

    assert sweep_of(L({})) == 0.0
    assert sweep_of(L({"lidar": {"hz": 10.0}})) == 0.0
    assert sweep_of(L({"lidar": {"sweep_s": 0.1}})) == 0.1
    assert sweep_of(L({"lidar": {"sweep_s": "x"}})) == 0.0


def test_graph_matcher_deskews_with_the_guess_twist():
    """Two swept scans of a room while turning fast: with the sweep the match lands on the true motion;
    without it the smeared scans pull it off."""
    from graphnav.graph.scan_factors import default_matcher

    segs = room()
    a = np.radians(np.arange(N) * 1.0 - 180.0)
    twist = np.array([1.5, 0.0, math.radians(30.0)])
    dt = 0.5
    x0 = np.array([-4.0, -2.0, 0.2])
    rel = np.array(gtsam.Pose2.Expmap(twist * dt).translation().tolist() + [twist[2] * dt])

    def swept_from(pose):
        tau = beam_times(N, SWEEP)
        x, y, th = se2_exp(twist, tau)
        out = np.empty(N)
        for i in range(N):
            g = gtsam.Pose2(*pose).compose(gtsam.Pose2(x[i], y[i], th[i]))
            out[i] = raycast(segs, (g.x(), g.y(), g.theta()), a[i:i + 1], 40.0)[0]
        return out

    g1 = gtsam.Pose2(*x0).compose(gtsam.Pose2(*rel))
    prev = Scan(10.0, swept_from(x0), a)
    cur = Scan(10.0 + dt, swept_from([g1.x(), g1.y(), g1.theta()]), a)
    errs = {}
    for sweep in (0.0, SWEEP):
        match = default_matcher({}, sweep)
        ok, pose, _ = match(cur, prev, rel, None, False)
        assert ok
        errs[sweep] = np.abs(np.asarray(gtsam.Pose2.Logmap(gtsam.Pose2(*rel).between(gtsam.Pose2(*pose)))))
    assert errs[SWEEP].max() < 1e-5  # exact scans: exact up to the ICP's convergence
    assert errs[0.0].max() > 1e-3  # smeared: millimetres and ~0.1 deg off


def test_harbour_sweep_option():
    from graphnav.sim.harbour import HarbourConfig, simulate_harbour

    plain = simulate_harbour(0, HarbourConfig(), duration=20.0)
    swept = simulate_harbour(0, HarbourConfig(lidar_sweep=SWEEP), duration=20.0)
    assert "sweep_s" not in plain.meta["lidar"] and swept.meta["lidar"]["sweep_s"] == SWEEP
    s0, s1 = plain.of("scan"), swept.of("scan")
    assert len(s1) >= len(s0) - 1
    for a, b in zip(s0[:50], s1[:50], strict=False):
        assert a.t == b.t
        both = np.isfinite(a.ranges[0]) and np.isfinite(b.ranges[0])
        assert not both or a.ranges[0] == b.ranges[0]  # beam 0 is taken at the stamp: the same draw, the same pose
    diff = np.nanmax(np.abs(np.concatenate([a.ranges - b.ranges for a, b in zip(s0[:50], s1[:50], strict=False)])))
    assert diff > 0.01  # later beams see the harbour from where the vessel is by then
    assert [r for r in plain.records if r.kind != "scan"] == [r for r in swept.records if r.kind != "scan"]


def test_rosbag_carries_the_sweep(tmp_path):
    pytest.importorskip("rosbags")
    from graphnav.io.rosbag import read_bag, write_bag
    from graphnav.log import NavLog

    a = np.radians(np.arange(N) - 180.0)
    scans = [Scan(float(t), np.full(N, 5.0), a, 40.0) for t in (0.0, 0.1, 0.2)]
    for sweep, want in ((0.0, None), (SWEEP, SWEEP)):
        log = NavLog.from_unsorted(scans, (), {"lidar": {"sweep_s": sweep}} if sweep else {})
        out = tmp_path / f"s{sweep}.bag"
        write_bag(log, out)
        back = read_bag(out)
        if want is None:
            assert "lidar" not in back.meta
        else:
            assert back.meta["lidar"]["sweep_s"] == pytest.approx(want, rel=1e-6)
