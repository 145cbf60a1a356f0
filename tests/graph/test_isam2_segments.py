"""iSAM2 in segments (``isam2_segment``): a fresh iSAM2 every N keyframes, started from the joint
marginal of the variables still in use, gives the newest state a whole-log iSAM2 gives; a factor on a
variable of an earlier segment stays out of the online problem and in the kept graph; the smoothed
result solves the whole graph as before."""

from __future__ import annotations

import gtsam
import numpy as np
from _harbour import harbour_trial

from graphnav import estimators
from graphnav.graph.loop_places import Deferred, _vec
from graphnav.graph.solution import joint_prior, marginal_priors, place_poses
from graphnav.graph.solver import Solver, isam_params
from graphnav.graph.space import NavSpace, PlanarSpace


def X(i: int) -> int:
    return gtsam.symbol("x", i)


L0 = gtsam.symbol("l", 0)
ODO = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.02]))
FIX = gtsam.noiseModel.Isotropic.Sigma(2, 3.0)
SIGHT = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.02, 0.3]))


def _step(k: int, rng: np.random.Generator) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """Keyframe ``k`` of a circle (radius ~16 m) with odometry, a fix every 5th keyframe and a sighting
    of one beacon (unknown at first: the SLAM case, where the pose and the beacon correlate)."""
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    truth = gtsam.Pose2(16 * np.sin(0.06 * k), 16 * (1 - np.cos(0.06 * k)), 0.06 * k)
    if k == 0:
        g.add(gtsam.PriorFactorPose2(X(0), truth, gtsam.noiseModel.Diagonal.Sigmas(np.array([1.0, 1.0, 0.1]))))
        g.add(gtsam.PriorFactorPoint2(L0, np.array([5.0, 10.0]), gtsam.noiseModel.Isotropic.Sigma(2, 20.0)))
        v.insert(L0, np.array([5.0, 10.0]))
    else:
        step = gtsam.Pose2(16 * np.sin(0.06), 16 * (1 - np.cos(0.06)), 0.06)
        g.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), step.compose(gtsam.Pose2(*rng.normal(0, [0.05, 0.05, 0.02]))),
                                       ODO))
    if k % 5 == 0:
        g.add(gtsam.PriorFactorPose2(X(k), truth, gtsam.noiseModel.Diagonal.Sigmas(np.array([3.0, 3.0, 1e3]))))
    d = np.array([5.0, 10.0]) - truth.translation()
    bearing = gtsam.Rot2.fromAngle(np.arctan2(d[1], d[0]) - truth.theta() + rng.normal(0, 0.02))
    g.add(gtsam.BearingRangeFactor2D(X(k), L0, bearing, float(np.hypot(*d)) + rng.normal(0, 0.3), SIGHT))
    v.insert(X(k), truth.compose(gtsam.Pose2(0.3, -0.2, 0.02)))
    return g, v


def _run(rebase_at: int | None, priors=joint_prior, n: int = 60) -> Solver:
    rng = np.random.default_rng(4)
    sol = Solver("isam2", isam_params(0.01), keep_graph=True)
    for k in range(n):
        sol.update(*_step(k, rng))
        sol.estimate(X(k), "Pose2")
        if k == rebase_at:
            sol.rebase(*priors(sol, PlanarSpace(), [X(k), L0], 0.0))
    sol.relinearize(3)
    return sol


def test_a_segment_started_from_the_joint_marginal_gives_the_whole_log_estimate():
    whole, joint, apart = _run(None), _run(30), _run(30, marginal_priors)
    last = [s.estimate(X(59), "Pose2") for s in (whole, joint, apart)]
    err_joint = np.hypot(*(last[1].translation() - last[0].translation()))
    err_apart = np.hypot(*(last[2].translation() - last[0].translation()))
    assert err_joint < 0.02 and err_joint < 0.2 * err_apart
    np.testing.assert_allclose(joint.marginal(X(59)), whole.marginal(X(59)), rtol=0.1, atol=0.01)
    # every variable keeps an estimate; the earlier segment's as it left it
    cur = joint.current()
    assert all(cur.exists(X(k)) for k in range(60)) and cur.exists(L0)
    assert joint.done.exists(X(10)) and not joint.s.valueExists(X(10))
    np.testing.assert_allclose(joint.estimate(X(10), "Pose2").translation(), joint.done.atPose2(X(10)).translation())


def test_a_factor_on_an_earlier_segment_goes_to_the_kept_graph_only():
    sol = _run(30)
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.BetweenFactorPose2(X(5), X(59), gtsam.Pose2(1.0, 0.0, 0.0), ODO))  # a loop back to segment 1
    g.add(gtsam.PriorFactorPose2(X(59), sol.estimate(X(59), "Pose2"), ODO))
    size = sol.graph.size()
    sol.update(g, gtsam.Values())
    assert sol.new_indices[0] == -1 and sol.new_indices[1] >= 0
    assert sol.graph.size() == size + 2


def test_after_a_rebase_factors_on_held_variables_all_go_online():
    sol = _run(30)
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose2(X(59), sol.estimate(X(59), "Pose2"), ODO))
    g.add(gtsam.BetweenFactorPose2(X(59), X(60), gtsam.Pose2(1.0, 0.0, 0.0), ODO))  # (X(60): new)
    v = gtsam.Values()
    v.insert(X(60), sol.estimate(X(59), "Pose2").compose(gtsam.Pose2(1.0, 0.0, 0.0)))
    held = sol.s.getFactorsUnsafe().size()
    sol.update(g, v)
    assert len(sol.new_indices) == 2 and min(sol.new_indices) >= held
    assert sol.s.valueExists(X(60))


def test_isam2_segments_keep_the_smoothed_result_and_the_online_track():
    """The embedded-style harbour trial (scans, GNSS, compass, IMU): in 12-keyframe segments the smoothed
    track is the whole-log one (the closing step solves the same graph) and the online one stays close."""
    log = harbour_trial(duration=30.0, seed=3)
    whole = estimators.run("isam2", log, isam2_segment=None)
    seg = estimators.run("isam2", log, isam2_segment=12)
    assert len(whole.trajectory) >= 60 and seg.info.get("rebases", 0) >= 4 and "rebases" not in whole.info
    np.testing.assert_allclose(seg.trajectory.poses, whole.trajectory.poses, atol=1e-4)
    gap = np.hypot(*(seg.online.poses[:, :2] - whole.online.poses[:, :2]).T)
    assert np.max(gap) < 0.1


def test_many_poses_read_in_one_call_are_the_estimates_one_by_one_bit_for_bit():
    """``place_poses`` (the loop closer's refresh of its places): the planar poses of many keys exactly as
    ``estimate`` answers them one at a time -- the segment's from one ``held_estimate``, the newest's from
    its marginal, the earlier segment's from the done values --; ``settled``: those of the earlier
    segment, whose estimates no longer change."""
    sol = _run(30, n=45)
    got = place_poses(sol, PlanarSpace(), list(range(45)))
    want = [_vec(sol.estimate(X(k), "Pose2")) for k in range(45)]
    assert all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))
    assert [sol.settled(X(k)) for k in range(45)] == [k < 30 for k in range(45)]
    assert not sol.settled(L0) and sol.read_apart(X(44)) and sol.read_apart(X(3)) and not sol.read_apart(X(40))


def test_pose3s_read_for_the_places_are_the_estimates_bit_for_bit():
    """The Pose3 graph's: the position now, the yaw when first looked at (``Deferred``), from the estimate
    as it was at the read (a later update moves the poses, not what was read)."""
    rng = np.random.default_rng(6)
    sol = Solver("isam2", isam_params(0.01), keep_graph=False)
    noise = gtsam.noiseModel.Isotropic.Sigma(6, 0.05)
    step = gtsam.Pose3(gtsam.Rot3.Ypr(0.1, 0.02, -0.01), np.array([1.0, 0.2, 0.05]))
    for k in range(30):
        g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
        truth = gtsam.Pose3()
        for _ in range(k):
            truth = truth.compose(step)
        if k == 0:
            g.add(gtsam.PriorFactorPose3(X(0), truth, noise))
        else:
            g.add(gtsam.BetweenFactorPose3(X(k - 1), X(k), step.compose(gtsam.Pose3.Expmap(rng.normal(0, 0.02, 6))),
                                           noise))
        if k % 4 == 0:
            g.add(gtsam.PriorFactorPose3(X(k), truth, gtsam.noiseModel.Isotropic.Sigma(6, 1.0)))
        v.insert(X(k), truth.compose(gtsam.Pose3.Expmap(rng.normal(0, 0.1, 6))))
        sol.update(g, v)
    space = NavSpace()
    got = place_poses(sol, space, list(range(30)))
    want = [_vec(space.pose2(sol.estimate(X(k), "Pose3"))) for k in range(30)]
    moved = gtsam.NonlinearFactorGraph()
    moved.add(gtsam.PriorFactorPose3(X(29), gtsam.Pose3(), noise))
    sol.update(moved, gtsam.Values())
    assert all(isinstance(g, Deferred) for g in got)
    for g, w in zip(got, want, strict=True):
        if isinstance(g, Deferred):
            assert np.array_equal(g.xy, w[:2])
            g = g.read()
        assert np.array_equal(g, w)


def test_gnss_fixes_shorten_the_segment_and_nothing_else_does():
    """``isam2_segment_gnss``: with GNSS fixes a segment is the smaller of the two lengths; without fixes it is
    ``isam2_segment``; ``isam2_segment`` None switches segments off everywhere."""
    log = harbour_trial(duration=30.0, seed=3)  # 60 keyframes
    whole = estimators.run("isam2", log, isam2_segment=None, isam2_segment_gnss=12)
    gnss = estimators.run("isam2", log, isam2_segment=30, isam2_segment_gnss=12)
    assert "rebases" not in whole.info and gnss.info["rebases"] == 4
    np.testing.assert_allclose(gnss.trajectory.poses, whole.trajectory.poses, atol=1e-4)
    no_fix = log.without(lambda r: r.kind == "gnss")
    assert estimators.run("isam2", no_fix, isam2_segment=30, isam2_segment_gnss=12).info["rebases"] == 1
