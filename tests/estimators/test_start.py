"""Where the odometry baselines start (graphnav.estimators.start): the graph's anchor rule on the
log's records -- the pose prior, else the first GNSS fix and compass reading, ... -- never the truth
while the log holds an absolute record."""

from __future__ import annotations

import math

import numpy as np
from _logfactory import every_record_log

from graphnav import estimators
from graphnav.estimators.start import log_start
from graphnav.graph.anchor import choose_anchor
from graphnav.graph.smoother_config import SmootherConfig
from graphnav.io.drop import drop_kinds
from graphnav.log import Gnss, Heading, NavLog, Odometry, PosePrior, Truth


def _log(*recs) -> NavLog:  # noqa: ANN002
    return NavLog.from_unsorted(list(recs))


def test_the_prior_wins_at_its_own_time():
    s = log_start(_log(Truth(0.0, 5.0, 6.0, 0.7), Gnss(0.0, 1.0, 2.0, 3.0), Odometry(0.0, 1.0, 0.0),
                       PosePrior(0.5, 10.0, 20.0, -1.0, 0.3, 0.02), Heading(0.6, 0.2, 0.03)))
    assert s.name == "pose_prior" and s.t == 0.5 and not s.is_frame
    np.testing.assert_array_equal(s.pose, [10.0, 20.0, -1.0])
    np.testing.assert_array_equal(s.sigmas, [0.3, 0.3, 0.02])
    # as in the graph, a prior after a fix and a compass reading is not the anchor (it comes too late)
    late = log_start(_log(Gnss(0.0, 1.0, 2.0, 3.0), Heading(0.0, 0.2, 0.03),
                          PosePrior(0.5, 10.0, 20.0, -1.0, 0.3, 0.02)))
    assert late.name == "first GNSS+compass"


def test_gnss_and_compass_not_the_truth():
    g, h = Gnss(0.3, 1.0, 2.0, 3.0), Heading(0.6, 0.2, 0.03)
    s = log_start(_log(Truth(0.0, 5.0, 6.0, 0.7), g, h, Gnss(1.0, 9.0, 9.0, 3.0), Heading(1.0, 1.5, 0.03)))
    cfg = SmootherConfig()
    pose, sigmas, name = choose_anchor([g, h], {}, cfg.anchor, cfg.mounts)  # the graph's, from the same two
    assert s.name == name == "first GNSS+compass" and s.t == 0.3
    np.testing.assert_array_equal(s.pose, [1.0, 2.0, 0.2])
    np.testing.assert_array_equal(s.pose, pose)
    np.testing.assert_array_equal(s.sigmas, sigmas)


def test_a_late_compass_is_not_waited_for():
    """The graph holds records ``anchor_wait`` seconds (2 s) at most: a compass reading 5 s after the
    first fix comes too late, the yaw is 0 with the graph's wide sigma."""
    s = log_start(_log(Gnss(0.0, 1.0, 2.0, 3.0), Odometry(1.0, 1.0, 0.0), Odometry(3.0, 1.0, 0.0),
                       Heading(5.0, 0.2, 0.03)))
    assert s.name == "first GNSS" and s.pose[2] == 0.0 and s.sigmas[2] > math.radians(45.0)


def test_frames_when_nothing_is_absolute():
    s = log_start(_log(Odometry(0.0, 1.0, 0.0), Truth(0.2, 5.0, 6.0, 0.7)))
    assert s.name == "truth (first pose)" and s.is_frame and s.t == 0.2
    np.testing.assert_array_equal(s.pose, [5.0, 6.0, 0.7])
    s = log_start(_log(Odometry(0.0, 1.0, 0.0), Odometry(1.0, 1.0, 0.0)))
    assert s.name == "origin" and s.is_frame and s.t == -math.inf and not s.pose.any()


def test_icp_dr_starts_at_the_anchor_with_its_sigmas():
    log = drop_kinds(every_record_log(n=8), ["pose_prior"])
    res = estimators.run("icp-dr", log, init="cv")
    g, h = log.of("gnss")[0], log.of("heading")[0]
    s = log_start(log)
    assert res.info["anchor"] == "first GNSS+compass"
    np.testing.assert_allclose(res.trajectory.poses[0], [g.x, g.y, h.yaw])
    np.testing.assert_allclose(np.sqrt(np.diag(res.trajectory.cov[0])), s.sigmas)  # (world = body at the start)
    dr = estimators.run("dead-reckoning", log)
    np.testing.assert_allclose(dr.trajectory.poses[0], [g.x, g.y, h.yaw])
