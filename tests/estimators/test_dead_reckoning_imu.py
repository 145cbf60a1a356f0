"""Dead reckoning on a log without odometry: the IMU's planar strapdown integration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.log import Imu, NavLog, PosePrior, Truth


def _turn_log(v: float = 1.5, w: float = math.radians(4.0), hz: float = 100.0, seconds: float = 60.0,
              known_velocity: bool = True) -> tuple[NavLog, np.ndarray]:
    """A constant turn of speed ``v`` and rate ``w`` from (10, 20) heading 30 deg: exact IMU means
    (ax 0, ay = v w, wz = w) and the closed-form end pose."""
    th0 = math.radians(30.0)
    n = int(round(seconds * hz))
    recs: list = [PosePrior(0.0, 10.0, 20.0, th0, 0.1, 0.01), Truth(0.0, 10.0, 20.0, th0)]
    recs += [Imu((k + 1) / hz, 0.0, v * w, w) for k in range(n)]
    th1 = th0 + w * seconds
    r = v / w
    end = np.array([10.0 + r * (math.sin(th1) - math.sin(th0)), 20.0 - r * (math.cos(th1) - math.cos(th0)), th1])
    meta = {"initial_velocity": [v * math.cos(th0), v * math.sin(th0)]} if known_velocity else {}
    return NavLog(recs, meta=meta), end


def test_imu_dead_reckoning_follows_a_constant_turn():
    log, end = _turn_log()
    assert estimators.get("dead-reckoning").unmet(log) is None
    r = estimators.run("dead-reckoning", log)
    assert r.info["motion"] == "imu" and r.info["anchor"] == "pose_prior"
    assert len(r.trajectory.t) == 6001 and r.trajectory.t[-1] == pytest.approx(60.0)
    last = r.trajectory.poses[-1]
    assert np.hypot(*(last[:2] - end[:2])) < 0.02  # 90 m of arc, 240 deg of turn
    assert last[2] == pytest.approx((end[2] + math.pi) % (2 * math.pi) - math.pi, abs=1e-9)


def test_imu_dead_reckoning_without_initial_velocity_starts_at_rest():
    log, _ = _turn_log(known_velocity=False, seconds=5.0)
    r = estimators.run("dead-reckoning", log)
    assert r.info["initial_velocity"] == "zero"
    moved = np.hypot(*(r.trajectory.poses[-1, :2] - [10.0, 20.0]))
    a = 1.5 * math.radians(4.0)  # only the centripetal acceleration moves it: at most a t^2 / 2
    assert 0.9 * 0.5 * a * 25.0 < moved <= 0.5 * a * 25.0


def test_odometry_still_wins_and_an_empty_log_is_unmet():
    log, _ = _turn_log(seconds=1.0)
    assert estimators.get("dead-reckoning").unmet(NavLog([Truth(0.0, 0.0, 0.0, 0.0)])) is not None
    from graphnav.log import Odometry

    both = NavLog(sorted(list(log.records) + [Odometry(0.0, 1.0, 0.0), Odometry(1.0, 1.0, 0.0)], key=lambda r: r.t),
                  meta=log.meta)
    r = estimators.run("dead-reckoning", both)
    assert "motion" not in r.info and len(r.trajectory.t) == 2
