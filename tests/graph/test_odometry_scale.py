"""The odometry's scale factors (graphnav.graph.odometry_scale): a known answer.

A robot whose odometry reports ``v / 1.08`` and ``w / 0.93`` (a wheel radius and a track that are
wrong) with its white noise stated, and GNSS fixes: the closing step (``-O odometry_scale=true``)
estimates ``s_v = 1.08``, ``s_w = 0.93`` within their standard deviations, and the smoothed track's
NEES is then that of chance; without the estimate the scale error, which no white noise describes,
makes it over-confident (NEES 54-66) and 5x less accurate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.evaluation.metrics import ate, nees_stats
from graphnav.geometry import increment
from graphnav.graph.odometry_scale import mean_increment
from graphnav.log import Gnss, NavLog, Odometry, PosePrior, Truth

SV, SW = 1.08, 0.93  # true / reported speed and turn rate
DT = 0.1  # [s] odometry
FIX_SIGMA = 0.5  # [m] stated and simulated


def _log(seed: int, duration: float = 240.0) -> NavLog:
    """A unicycle turning both ways at varying speed; odometry at 10 Hz with its white noise stated
    per sample (and the default lateral slip, ``odo_lateral``), fixes at 1 Hz."""
    rng = np.random.default_rng(seed)
    pose = np.array([0.0, 0.0, 0.2])
    recs: list = [PosePrior(0.0, *pose, 0.05, 0.01), Truth(0.0, *pose)]
    for i in range(int(round(duration / DT))):
        t, t_next = round(i * DT, 9), round((i + 1) * DT, 9)
        v = 0.8 + 0.4 * math.sin(0.05 * t)
        w = 0.25 * math.sin(0.07 * t) + 0.05
        dv, dw = 0.02 + 0.05 * v, math.radians(0.5) + 0.05 * abs(w)  # per sample, stated
        recs.append(Odometry(t, (v + rng.normal(0.0, dv)) / SV, (w + rng.normal(0.0, dw)) / SW, dv / SV, dw / SW))
        th = pose[2]
        lat = rng.normal(0.0, 0.05 * v * DT)  # slip: the default odo_lateral, per sample
        pose = pose + np.array([v * DT * math.cos(th + 0.5 * w * DT) - lat * math.sin(th),
                                v * DT * math.sin(th + 0.5 * w * DT) + lat * math.cos(th), w * DT])
        recs.append(Truth(t_next, *pose))
        if (i + 1) % 10 == 0:
            recs.append(Gnss(t_next, pose[0] + rng.normal(0.0, FIX_SIGMA), pose[1] + rng.normal(0.0, FIX_SIGMA),
                             FIX_SIGMA))
    return NavLog(recs, [], {"name": f"scaled-odometry-{seed}"})


def test_mean_increment_is_the_integrated_odometry():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.005, 0.02, 200))
    s = np.column_stack([t, rng.uniform(0, 1, 200), rng.uniform(-1, 1, 200), np.full(200, 0.1), np.full(200, 0.1)])
    for t0, t1 in [(t[0] - 0.1, t[50]), (t[3] + 1e-3, t[120] - 3e-3), (t[10], t[10] + 1e-3)]:
        assert mean_increment(s[:, :3], t0, t1) == pytest.approx(increment(s, t0, t1)[0], abs=1e-12)
    scaled = s.copy()
    scaled[:, 1] *= 1.1
    scaled[:, 2] *= 0.9
    want = increment(scaled, t[5], t[90])[0]
    assert mean_increment(s[:, :3], t[5], t[90], 1.1, 0.9) == pytest.approx(want, abs=1e-12)


def test_known_scales_are_estimated_and_the_nees_is_honest():
    """Over seeds: the scales within 3 of their reported sigmas of the truth (and within 1 %), the NEES (2 dof)
    of chance with them; without them the smoothed track is over-confident and less accurate."""
    on_nees, off_nees, on_ate, off_ate = [], [], [], []
    for seed in range(4):
        log = _log(seed)
        on = estimators.run("isam2", log, odometry_scale=True)
        rep = on.info["odometry_scale"]
        assert abs(rep["v"] - SV) < 3 * rep["sigma_v"] and abs(rep["v"] - SV) < 0.01 * SV, rep
        assert abs(rep["w"] - SW) < 3 * rep["sigma_w"] and abs(rep["w"] - SW) < 0.01 * SW, rep
        off = estimators.run("isam2", log)
        assert "odometry_scale" not in off.info  # off by default
        for res, nees, err in ((on, on_nees, on_ate), (off, off_nees, off_ate)):
            st = nees_stats(res.trajectory, log.truth())
            assert st is not None and st["n"] > 100
            nees.append(st["mean"])
            err.append(ate(res.trajectory, log.truth())["rmse"])
    assert 1.0 <= float(np.mean(on_nees)) <= 3.5, on_nees
    assert float(np.mean(off_nees)) > 5.0 * float(np.mean(on_nees)), (off_nees, on_nees)
    assert float(np.mean(on_ate)) < 0.5 * float(np.mean(off_ate)), (on_ate, off_ate)


def test_without_another_sensor_the_scales_stay_one():
    """Odometry and the anchor alone observe no scale: both are reported not estimated and stay 1."""
    log = NavLog([r for r in _log(0, duration=30.0).records if not isinstance(r, Gnss)], [], {"name": "odometry-only"})
    res = estimators.run("isam2", log, odometry_scale=True)
    rep = res.info["odometry_scale"]
    assert rep["v"] == 1.0 and rep["w"] == 1.0 and rep["steps"] == 0, rep
    off = estimators.run("isam2", log)
    assert np.allclose(res.trajectory.poses, off.trajectory.poses, atol=1e-6)
