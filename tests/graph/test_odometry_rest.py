"""A robot at rest before its odometry begins (MRCLAM: 12-16 s before the first command).

The gap between the anchor and the first odometry sample was the random walk of "no motion known"
(2 m/s, 30 deg/s): with unknown beacons nothing absolute follows, so every later pose was reported
5-10 m and 79 deg uncertain in the anchor's frame (MRCLAM NEES 0.001-0.005). A log with odometry is
at rest until its first sample (:meth:`OdometryBuffer.rest_row`); the smoothed track's NEES is then
that of chance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.evaluation.metrics import nees_stats
from graphnav.graph.odometry_buffer import OdometryBuffer
from graphnav.graph.smoother_config import OdometryConfig
from graphnav.log import BeaconObs, NavLog, Odometry, PosePrior, Truth

REST = 10.0  # [s] at rest before the first odometry sample
DRIVE = 50.0  # [s] driving after it
SV, SW = 0.02, 0.02  # [m/s, rad/s] stated per-sample odometry sigmas
SR, SB = 0.05, math.radians(1.0)  # [m, rad] stated range and bearing sigmas
BEACONS = {"a": (4.0, 0.0), "b": (0.0, 5.0), "c": (-4.0, 1.0), "d": (1.0, -4.0)}  # unknown to the graph


def _log(seed: int) -> NavLog:
    """Anchor at t = 0, at rest for ``REST`` s (truth only), then a unicycle on a circle with noisy
    odometry at 10 Hz and range/bearing sightings of unknown beacons at 2 Hz."""
    rng = np.random.default_rng(seed)
    pose = np.array([1.0, -1.0, 0.3])
    prior = pose + rng.normal(0.0, 0.01, 3)  # the anchor: the first pose within its stated 0.01 m, 0.01 rad
    recs: list = [PosePrior(0.0, *prior, 0.01, 0.01), Truth(0.0, *pose)]
    dt = 0.1
    for i in range(1, int(round(REST / dt)) + 1):
        recs.append(Truth(i * dt, *pose))
    v, w = 0.3, 0.1
    t = REST
    for i in range(int(round(DRIVE / dt))):
        recs.append(Odometry(t, v + rng.normal(0.0, SV), w + rng.normal(0.0, SW), SV, SW))
        if i % 5 == 2:
            for bid, (bx, by) in BEACONS.items():
                dx, dy = bx - pose[0], by - pose[1]
                r = math.hypot(dx, dy)
                if r < 6.0:
                    b = math.atan2(dy, dx) - pose[2]
                    b = (b + math.pi) % (2 * math.pi) - math.pi
                    recs.append(BeaconObs(t, bid, r + rng.normal(0.0, SR), b + rng.normal(0.0, SB), SR, SB))
        th = pose[2]
        pose = pose + np.array([v * dt * math.cos(th + 0.5 * w * dt), v * dt * math.sin(th + 0.5 * w * dt), w * dt])
        t = REST + (i + 1) * dt
        recs.append(Truth(t, *pose))
    return NavLog(recs, [], {"name": f"rest-then-drive-{seed}"})


def test_buffer_at_rest_before_the_first_sample():
    cfg = OdometryConfig()
    sv, sw = cfg.sigma_v, math.radians(cfg.sigma_w_deg)
    buf = OdometryBuffer(cfg, expected=True)
    rel, cov = buf.between(0.0, 4.0)  # nothing yet, odometry expected: at rest, the densities over 4 s
    assert np.allclose([rel.x(), rel.y(), rel.theta()], 0.0)
    assert cov[0, 0] == pytest.approx(sv**2 * 4.0, rel=1e-4) and cov[2, 2] == pytest.approx(sw**2 * 4.0, rel=1e-4)
    assert OdometryBuffer(cfg).between(0.0, 4.0) is None  # not expected: the motion model decides
    buf.add(Odometry(10.0, 1.0, 0.0, 0.01, 0.001))
    rel, cov = buf.between(2.0, 6.0)  # wholly before the first sample
    assert np.allclose([rel.x(), rel.y(), rel.theta()], 0.0) and cov[0, 0] == pytest.approx(sv**2 * 4.0, rel=1e-4)
    rel, cov = buf.between(8.0, 12.0)  # straddling it: 2 s at rest, then 2 s at 1 m/s
    assert [rel.x(), rel.y(), rel.theta()] == pytest.approx([2.0, 0.0, 0.0], abs=1e-12)
    assert cov[0, 0] == pytest.approx(sv**2 * 2.0 + (0.01 * 2.0) ** 2, rel=1e-4)
    late = OdometryBuffer(cfg)  # the first sample decides when nothing was said before it
    late.add(Odometry(10.0, 1.0, 0.0, 0.01, 0.001))
    assert late.between(2.0, 6.0)[1][2, 2] == pytest.approx(sw**2 * 4.0, rel=1e-4)


def test_smoothed_nees_after_a_rest_is_chance():
    """Over Monte-Carlo seeds the smoothed track's position NEES (2 dof) is chance, and the covariance
    of a pose late in the run is that of the anchor, the rest and the odometry: decimetres, not metres."""
    # the rest's noise below the anchor's (the truth is still); no lateral slip (none simulated)
    opts = {"odo_sigma_v": 0.002, "odo_sigma_w_deg": 0.1, "odo_lateral": 0.0}
    means, sig = [], []
    for seed in range(24):
        log = _log(seed)
        res = estimators.run("isam2", log, **opts)
        tr = res.trajectory
        st = nees_stats(tr, log.truth())
        assert st is not None and st["n"] > 100
        means.append(st["mean"])
        sig.append(math.sqrt(tr.cov[-1][0, 0] + tr.cov[-1][1, 1]))
    assert 0.5 <= float(np.mean(means)) <= 3.0, means
    assert max(sig) < 0.5, sig
