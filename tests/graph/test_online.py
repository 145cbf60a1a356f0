"""The minimal online graph adapter: known answers on noise-free data, outages, late records."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _harbour import harbour_trial

import factors as F
from graphnav.estimators.dead_reckoning import unicycle_step
from graphnav.evaluation.metrics import ate
from graphnav.graph.graph_online import GraphOnline
from graphnav.log import Gnss, Heading, NavLog, Odometry
from graphnav.online.runner import make_online, run_online


@pytest.mark.parametrize("v,w,dt", [(2.0, 0.0, 0.1), (2.0, 0.3, 1.0), (-1.0, -0.05, 2.0), (0.0, 0.2, 0.5)])
def test_motion_model_increment_matches_dead_reckoning(v, w, dt):
    """The online graph's motion model (factors.odometry_increment, eq. 3 integrated exactly)."""
    pose = np.array([1.0, -2.0, 0.7])
    ref = unicycle_step(pose, v, w, dt)
    d, _ = F.odometry_increment(v, w, dt, 0.0, 0.0)
    inc = [d.x(), d.y(), d.theta()]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    got = pose + [c * inc[0] - s * inc[1], s * inc[0] + c * inc[1], inc[2]]
    np.testing.assert_allclose(got[:2], ref[:2], atol=1e-9)
    assert math.remainder(got[2] - ref[2], 2 * math.pi) == pytest.approx(0, abs=1e-12)


def test_noise_free_log_is_tracked_exactly():
    log = harbour_trial(duration=10.0, sigma_gnss=1e-3, sigma_heading_deg=1e-3, seed=0, odo_sigma=(0.0, 0.0))
    # noise-free speed and rate, with sigmas that leave room for the 10 Hz sampling of the controls
    exact = [r if r.kind != "odometry" else Odometry(r.t, r.v, r.w, 0.01, 0.001) for r in log.records]
    tr = run_online(NavLog(exact, meta=log.meta), GraphOnline())
    assert len(tr.t) == len(log.of("gnss"))
    assert ate(tr, log.truth())["max"] < 0.01


@pytest.mark.parametrize("name", ["fixed-lag", "isam2"])
def test_noisy_log_beats_gnss_noise(name):
    log = harbour_trial(duration=20.0, sigma_gnss=1.5, seed=3)
    tr = run_online(log, make_online(name))
    assert ate(tr, log.truth())["rmse"] < 0.75  # GNSS alone: 1.5 m per axis = 2.1 m 2-D RMSE


def test_outage_longer_than_the_lag_and_late_records():
    log = harbour_trial(duration=30.0, seed=4)
    gap = log.without(lambda r: r.kind in ("gnss", "heading") and 1.7e9 + 10 <= r.t <= 1.7e9 + 20)
    est = GraphOnline(lag=3.0)
    tr = run_online(gap, est)
    assert tr.t[-1] == pytest.approx(log.t1)
    # during the outage no estimate is produced without absolute input: odometry only feeds the next
    assert not np.any((tr.t > 1.7e9 + 10.5) & (tr.t < 1.7e9 + 20))
    assert ate(tr, log.truth())["rmse"] < 1.0
    assert est.add(Gnss(1.7e9, 0.0, 0.0, 1.0)) is None and est.counts["late"] == 1


def test_heading_drives_output_in_gnss_outage():
    est = GraphOnline(outage_s=1.0)
    assert est.add(Heading(0.0, 0.5, 0.01)) is None  # before the first fix: remembered
    e = est.add(Gnss(0.0, 10.0, 20.0, 0.5))
    assert e is not None and e.pose[2] == pytest.approx(0.5, abs=1e-3)
    assert est.add(Odometry(0.0, 1.0, 0.0)) is None
    assert est.add(Heading(0.5, 0.5, 0.01)) is None  # GNSS is recent
    e = est.add(Heading(2.0, 0.5, 0.01))  # 2 s without GNSS: heading yields an estimate
    assert e is not None and e.t == 2.0
    expect = [10.0 + 2.0 * math.cos(0.5), 20.0 + 2.0 * math.sin(0.5)]  # 1 m/s for 2 s along yaw 0.5
    np.testing.assert_allclose(e.pose[:2], expect, atol=0.05)


def test_rebase_keeps_the_estimate():
    log = harbour_trial(duration=20.0, seed=6)
    a, b = GraphOnline(), GraphOnline(rebase_every=30)
    ta, tb = run_online(log, a), run_online(log, b)
    assert b.counts["rebases"] >= 5 and "rebases" not in a.counts
    assert abs(ate(tb, log.truth())["rmse"] - ate(ta, log.truth())["rmse"]) < 0.1
    assert np.max(np.hypot(*(ta.poses[:, :2] - tb.poses[:, :2]).T)) < 0.5


def test_scan_factors_carry_a_gnss_outage_without_odometry():
    """No odometry, GNSS lost for 30 s: scan-to-scan registration must carry the track. The window
    is the route's run between the piers (350-400 s): along the open south quay (the first minutes)
    plain GICP with fixed sigmas slides along the wall and carries only half the distance."""
    full = harbour_trial(duration=400.0, scans=True, seed=2)
    t0 = full.t0 + 350.0
    log = full.sliced(t0, None)
    lg = log.without(lambda r: r.kind == "odometry" or (r.kind == "gnss" and 15 <= r.t - t0 <= 45))
    errs = {}
    for use in (False, True):
        est = GraphOnline(use_scans=use)
        tr = run_online(lg, est)
        m = (tr.t > t0 + 15) & (tr.t < t0 + 45)
        ref = log.truth().poses[np.searchsorted(log.truth().t, tr.t[m] - 1e-6)]
        errs[use] = float(np.max(np.hypot(*(tr.poses[m, :2] - ref[:, :2]).T)))
    assert est.counts["icp"] >= 40
    # scans between fixes join the graph from their nodes' guesses (none skipped for want of a solve)
    assert est.counts["icp"] + est.counts.get("icp_rejected", 0) >= est.counts["scan"] - 2
    assert est.counts.get("icp_skipped", 0) == 0
    assert errs[True] < 10.0 and errs[False] > 3 * errs[True], errs
