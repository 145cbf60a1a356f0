"""The record-by-record navigator (graphnav.Navigator): the public API, the online estimate on
known answers, outages, late records, scans through a GNSS outage, and Navigator == run_isam2."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _harbour import harbour_trial

import factors as F
import graphnav
from graphnav.estimators.dead_reckoning import unicycle_step
from graphnav.evaluation.metrics import ate
from graphnav.graph.log_runs import run_isam2
from graphnav.graph.navigator import Navigator
from graphnav.log import Gnss, Heading, NavLog, Odometry
from graphnav.online.runner import make_online, run_online
from graphnav.sim.square import square_loop


def test_public_api_from_the_top_level(tmp_path):
    log = square_loop(0, side=20.0, laps=1)
    path = tmp_path / "sq.npz"
    graphnav.save_log(log, path)
    log = graphnav.load_log(path)
    nav = graphnav.Navigator(config=None)
    ests = [e for e in (nav.add(r) for r in log) if e is not None]
    assert ests and all(isinstance(e, graphnav.Estimate) for e in ests)
    e = ests[-1]
    assert e.pose.__class__.__name__ == "Pose2" and e.cov.shape == (3, 3)
    np.testing.assert_allclose([e.pose.x(), e.pose.y(), e.pose.theta()], e.vec)
    assert np.all(np.linalg.eigvalsh(e.cov) > 0)
    traj = nav.smoothed()
    assert isinstance(traj, graphnav.Trajectory) and traj.cov is not None and len(traj) >= len(ests)
    assert ate(traj, log.truth(), max_dt=0.02)["rmse"] < 0.6


@pytest.mark.parametrize("v,w,dt", [(2.0, 0.0, 0.1), (2.0, 0.3, 1.0), (-1.0, -0.05, 2.0), (0.0, 0.2, 0.5)])
def test_motion_model_increment_matches_dead_reckoning(v, w, dt):
    """The graph's odometry motion model (factors.odometry_increment, eq. 3 integrated exactly)."""
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
    tr = run_online(NavLog(exact, meta=log.meta), make_online("fixed-lag"))
    assert len(tr.t) == 20  # one estimate per keyframe: a 0.5 s grid over the 10 s
    assert ate(tr, log.truth())["max"] < 0.01


@pytest.mark.parametrize("name", ["fixed-lag", "isam2"])
def test_noisy_log_beats_gnss_noise(name):
    log = harbour_trial(duration=20.0, sigma_gnss=1.5, seed=3)
    tr = run_online(log, make_online(name))
    assert ate(tr, log.truth())["rmse"] < 0.75  # GNSS alone: 1.5 m per axis = 2.1 m 2-D RMSE


def test_outage_longer_than_the_lag_and_late():
    log = harbour_trial(duration=30.0, seed=4)
    gap = log.without(lambda r: r.kind in ("gnss", "heading") and 1.7e9 + 10 <= r.t <= 1.7e9 + 20)
    est = make_online("fixed-lag", lag=3.0)
    tr = run_online(gap, est)
    assert tr.t[-1] == pytest.approx(log.t1, abs=0.5)  # the last keyframe of the 0.5 s grid
    # through the outage the estimates go on (odometry carries the keyframes)
    assert np.sum((tr.t > 1.7e9 + 10.5) & (tr.t < 1.7e9 + 20)) >= 18
    assert ate(tr, log.truth())["rmse"] < 1.0
    assert est.add(Gnss(1.7e9, 0.0, 0.0, 1.0)) is None and est.info()["late"] == 1


def test_heading_before_the_first_fix_and_odometry_through_an_outage():
    nav = Navigator()
    assert nav.add(Heading(0.0, 0.5, 0.01)) is None  # held until the anchor is chosen
    assert nav.add(Gnss(0.0, 10.0, 20.0, 0.5)) is None
    assert nav.add(Odometry(0.0, 1.0, 0.0, 0.01, 0.001)) is None
    e = nav.add(Heading(0.5, 0.5, 0.01))  # time moved on: keyframe 0 (t = 0) is solved
    assert e is not None and e.t == 0.0 and e.vec[2] == pytest.approx(0.5, abs=1e-3)
    assert nav.info()["anchor"] == "first GNSS+compass"
    out = [nav.add(Heading(t, 0.5, 0.01)) for t in (1.0, 1.5, 2.0, 2.5)]
    e = next(x for x in out if x is not None and x.t == 2.0)  # 2 s without GNSS: odometry carries on
    expect = [10.0 + 2.0 * math.cos(0.5), 20.0 + 2.0 * math.sin(0.5)]  # 1 m/s for 2 s along yaw 0.5
    np.testing.assert_allclose(e.vec[:2], expect, atol=0.05)
    assert e.sog == pytest.approx(1.0)


def test_scan_factors_carry_a_gnss_outage_without_odometry():
    """No odometry, GNSS lost for 30 s: scan-to-scan registration must carry the track (window:
    the route's run between the piers, 350-400 s)."""
    full = harbour_trial(duration=400.0, scans=True, seed=2)
    t0 = full.t0 + 350.0
    log = full.sliced(t0, None)
    lg = log.without(lambda r: r.kind == "odometry" or (r.kind == "gnss" and 15 <= r.t - t0 <= 45))
    errs = {}
    for name, opts in (("random walk", {"use_icp": False, "motion_model": "random-walk"}),
                       ("gnss velocity", {"use_icp": False}), ("icp", {})):
        # loops off: this compares the motion models alone (with loops the GNSS-velocity case is 2.0 m)
        est = make_online("fixed-lag", loops=False, **opts)
        tr = run_online(lg, est)
        m = (tr.t > t0 + 15) & (tr.t < t0 + 45)
        ref = log.truth().interpolate(tr.t[m])
        errs[name] = float(np.max(np.hypot(*(tr.poses[m, :2] - ref[:, :2]).T)))
    info = est.info()
    assert info["icp_pairs"] >= 40 and info["icp_failed"] <= 2
    # measured 5.4 m with the scans, 6.7 m on the GNSS velocity alone, 32.6 m with nothing known
    assert errs["icp"] < 10.0 and errs["random walk"] > 3 * errs["icp"], errs
    assert errs["icp"] < errs["gnss velocity"] < errs["random walk"], errs


def test_navigator_equals_run_isam2_record_by_record():
    log = square_loop(3, side=30.0, laps=1, compass_bias=math.radians(3.0))
    ref = run_isam2(log, covariances=False)
    nav = Navigator(covariances=False)
    got = [e for e in (nav.add(r) for r in log) if e is not None]
    last = nav.flush()
    if last is not None:
        got.append(last)
    np.testing.assert_array_equal([e.t for e in got], ref.online.t)
    np.testing.assert_allclose(np.array([e.vec for e in got]), ref.online.poses, atol=1e-9)
    np.testing.assert_allclose(np.array([e.cov for e in got]), ref.online.cov, atol=1e-12)
    np.testing.assert_allclose(nav.smoothed().poses, ref.trajectory.poses, atol=1e-9)


def test_rebase_keeps_the_estimate():
    """Live mode (no history) re-anchors the fixed-lag smoother every rebase_every keyframes (flat
    memory): the estimate stays the same to within the noise."""
    from _harbour import harbour_trial as trial

    log = trial(duration=20.0, seed=6)
    a = make_online("fixed-lag")
    b = make_online("fixed-lag", rebase_every=10)
    ta, tb = run_online(log, a), run_online(log, b)
    assert b.info()["rebases"] >= 3 and "rebases" not in a.info()
    assert abs(ate(tb, log.truth())["rmse"] - ate(ta, log.truth())["rmse"]) < 0.1
    assert np.max(np.hypot(*(ta.poses[:, :2] - tb.poses[:, :2]).T)) < 0.5


def test_navigator_gives_graphnav_runs_online_ate_on_the_embedded_harbour():
    """Issue #17: the record-by-record API (README: ``Navigator.for_log`` + ``add``) on the embedded
    harbour log (a USV's sensors: IMU, scans, GNSS + Doppler, compass, speed log, beacons: the IMU graph)
    gives the online ATE of ``graphnav run LOG -e isam2`` (the estimator registry's ``isam2``) within
    5 %; here a 60 s slice (the whole log: docs/compare.md)."""
    from pathlib import Path

    from graphnav import estimators
    from graphnav.io import load_log

    path = Path(__file__).resolve().parents[2] / "data" / "harbour.npz"
    if not path.exists():
        pytest.skip("data/harbour.npz not generated")
    log = load_log(path).sliced(None, 60.0)
    assert log.counts()["imu"] > 0 and log.counts()["scan"] > 0
    nav = graphnav.Navigator.for_log(log)
    for rec in log:
        nav.add(rec)
    nav.flush()
    ref = estimators.run("isam2", log)
    truth = log.truth()
    a = ate(nav.online(), truth, max_dt=0.02)["rmse"]
    b = ate(ref.online, truth, max_dt=0.02)["rmse"]
    assert a == pytest.approx(b, rel=0.05)
    assert ate(nav.smoothed(), truth, max_dt=0.02)["rmse"] == pytest.approx(
        ate(ref.trajectory, truth, max_dt=0.02)["rmse"], rel=0.05)


def test_fixed_lag_without_history_returns_its_window():
    """Live mode (history=False) keeps neither the online track nor the poses that left the fixed-lag
    window: the result is the window (it failed with "x0 does not exist" before)."""
    from graphnav.sim.solent import simulate_solent

    log = simulate_solent(scenario=1, seed=0, max_steps=80)
    nav = Navigator.for_log(log, solver="fixed-lag", lag=10.0, history=False, covariances=False)
    for r in log:
        nav.add(r)
    res = nav.result()
    t = res.trajectory.t
    assert len(res.online) == 0 and 5 <= len(t) <= 25
    assert t[-1] >= log.t1 - 1.0 and t[0] >= log.t1 - 10.0 - 2.0


def test_live_isam2_keeps_no_graph_and_estimates_as_with_history():
    """Live mode (history=False) with iSAM2: the solver keeps no copy of the graph (the closing step's, which
    live mode never runs: it grew ~47 MB an hour at 10 Hz), and every online estimate is the one a run with the
    history gives."""
    from graphnav.sim.solent import simulate_solent

    log = simulate_solent(scenario=1, seed=0, max_steps=80)
    out: dict[bool, list] = {True: [], False: []}
    for history in (True, False):
        nav = Navigator.for_log(log, solver="isam2", history=history, isam2_segment_gnss=20,
                                on_estimate=lambda t, p, c, h=history: out[h].append((t, *p)))
        for r in log:
            nav.add(r)
        assert (nav.solver.graph.size() > 0) == history and nav.solver.keep == history
    assert len(out[True]) >= 30
    np.testing.assert_array_equal(np.array(out[False]), np.array(out[True]))
    nav = Navigator.for_log(log, solver="isam2", history=False, isam2_segment_gnss=20)
    for r in log:
        nav.add(r)
    t = nav.result().trajectory.t  # live mode's result: the keyframes of the current segment
    assert 1 <= len(t) <= 21 and t[-1] >= log.t1 - 1.0
