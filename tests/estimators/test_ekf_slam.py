"""EKF-SLAM (beacon paper eq. 3-27): agreement with the batched search, consistency, 10,000-step PD."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from graphnav import estimators
from graphnav.beacons.layout import Choices, Fairway, propagate
from graphnav.estimators.ekf_slam import EkfSlam, run_ekf_slam
from graphnav.geometry import wrap_angle
from graphnav.log import KnownBeacon, NavLog
from graphnav.sim.fairway import parse_beacons, simulate_fairway


def test_estimator_on_simulated_log_equals_batched_filter():
    # the log-driven estimator and the batched layout filter see the same noise draw
    lay = np.array([[650.0, 370.0], [300.0, 50.0]])
    log = simulate_fairway(lay, seed=7)
    res = estimators.run("ekf-slam", log)
    o = propagate(lay[None], Fairway(), Choices(linearize="estimate", seed=7), keep_state=True)
    assert len(res.trajectory) == Fairway().steps + 1
    np.testing.assert_allclose(np.sqrt(res.trajectory.cov[1:, 0, 0]), o["mx"][0], rtol=1e-7)
    np.testing.assert_allclose(np.sqrt(res.trajectory.cov[1:, 1, 1]), o["my"][0], rtol=1e-7)
    np.testing.assert_allclose(res.trajectory.poses[-1], o["x"][0, :3], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.info["beacons"]["B1"], o["x"][0, 3:5], rtol=1e-9)


def test_filter_is_consistent_over_seeds():
    # NEES of the final pose over independent draws follows chi2(3): the covariance means what it says
    lay = np.repeat([[[500.0, 300.0]]], 60, axis=0)
    track_end = Fairway().track()[-1]
    o = propagate(lay, Fairway(), Choices(linearize="estimate"), keep_state=True, seeds=np.arange(60))
    nees = []
    for x, P in zip(o["x"], o["P"], strict=True):
        e = x[:3] - track_end
        e[2] = wrap_angle(e[2])
        nees.append(e @ np.linalg.solve(P[:3, :3], e))
    lo, hi = chi2.ppf([0.005, 0.995], 3 * 60) / 60
    assert lo < np.mean(nees) < hi


def test_charted_beacons_are_used_and_help():
    lay = np.array([[400.0, 100.0]])
    log = simulate_fairway(lay, seed=1)
    charted = NavLog(log.records, [KnownBeacon("B1", 400.0, 100.0, 0.05)], log.meta)
    free = run_ekf_slam(log)
    known = run_ekf_slam(charted)
    assert known.info["beacons"]["B1"] == pytest.approx([400.0, 100.0], abs=0.5)
    assert np.mean(known.trajectory.cov[:, 1, 1]) < 0.5 * np.mean(free.trajectory.cov[:, 1, 1])


def test_first_sighting_initialises_beacon_from_observation():
    f = EkfSlam(np.array([10.0, 20.0, math.pi / 2]), 1)
    f.update(0, 5.0, -math.pi / 2, 0.1, 0.01)  # 5 m on the starboard beam of a north-heading vessel
    assert f.x[3:5] == pytest.approx([15.0, 20.0], abs=1e-6)
    assert f.P[3, 3] == pytest.approx(0.1**2, rel=1e-4)


def test_covariance_stays_symmetric_positive_semidefinite_for_10000_steps():
    """What the Joseph-form filter guarantees in floating point: P exactly symmetric, and no
    eigenvalue below -n*eps*max(eig) (PSD to round-off). P0's vessel block is zero, so P is only
    semidefinite in exact arithmetic at first (one predict has rank 2 in x, y, theta); once every
    beacon has been seen, P is positive definite with a margin far above round-off."""
    rng = np.random.default_rng(0)
    beacons = np.array([[60.0, 0.0], [-40.0, 50.0], [0.0, -80.0]])
    f = EkfSlam(np.array([0.0, 0.0, 0.0]), len(beacons))
    pose = np.array([0.0, 0.0, 0.0])
    sv, sw, sr, sb = 0.5, math.radians(0.1), 0.5, math.radians(0.5)
    dt, v, w = 0.5, 2.0, 0.02
    eps = np.finfo(float).eps
    worst_rel, min_eig_later = np.inf, np.inf
    for k in range(10_000):
        pose = pose + [v * dt * math.cos(pose[2]), v * dt * math.sin(pose[2]), w * dt]
        f.predict(v + rng.normal(0, sv), w + rng.normal(0, sw), dt, sv, sw)
        j = k % len(beacons)
        d = beacons[j] - pose[:2]
        f.update(j, float(np.hypot(*d) + rng.normal(0, sr)),
                 float(wrap_angle(math.atan2(d[1], d[0]) - pose[2] + rng.normal(0, sb))), sr, sb)
        if k % 500 == 0 or k < 5 or k == 9_999:
            assert np.array_equal(f.P, f.P.T)
            eig = np.linalg.eigvalsh(f.P)
            worst_rel = min(worst_rel, eig.min() / (f.n * eps * eig.max()))
            if k >= 500:
                min_eig_later = min(min_eig_later, eig.min())
    assert worst_rel >= -1.0
    assert min_eig_later > 1e-9
    assert np.all(np.isfinite(f.x))


def test_parse_beacons():
    np.testing.assert_array_equal(parse_beacons("1,2;3,4"), [[1, 2], [3, 4]])
    with pytest.raises(ValueError):
        parse_beacons("1,2,3")


def test_simulate_cli_round_trip(tmp_path):
    from graphnav.cli import main
    from graphnav.io import load_log

    out = tmp_path / "fw.jsonl"
    assert main(["simulate", "fairway", "--beacons", "650,370;300,50", "--seed", "3", "--out", str(out)]) == 0
    log = load_log(out)
    assert log.counts()["beacon"] == 2 * 200 and log.counts()["truth"] == 201
    assert estimators.runnable(log).count("ekf-slam") == 1


def test_gate_rejects_a_wild_beacon_return():
    from dataclasses import replace

    lay = np.array([[500.0, 300.0]])
    log = simulate_fairway(lay, seed=2)
    recs = list(log.records)
    i = [k for k, r in enumerate(recs) if r.kind == "beacon"][120]
    recs[i] = replace(recs[i], range=recs[i].range + 100.0)        # a 100 m false echo
    bad = NavLog(recs, [], log.meta)
    clean = run_ekf_slam(log, gate=0.999)
    gated = run_ekf_slam(bad, gate=0.999)
    blind = run_ekf_slam(bad)
    assert gated.info["rejected"] >= 1
    assert np.abs(gated.trajectory.poses[-1, :2] - clean.trajectory.poses[-1, :2]).max() < 0.5
    assert np.abs(blind.trajectory.poses[-1, :2] - clean.trajectory.poses[-1, :2]).max() > 2.0
