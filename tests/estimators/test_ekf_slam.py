"""EKF-SLAM (beacon paper eq. 3-27): agreement with the batched search, consistency, 10,000-step PD."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from graphnav import estimators
from graphnav.beacons.layout import Choices, Fairway, propagate
from graphnav.estimators.ekf_slam import SENSOR_DEFAULTS, EkfSlam, _NisScale, run_ekf_slam
from graphnav.geometry import wrap_angle
from graphnav.log import KnownBeacon, NavLog
from graphnav.sim.fairway import parse_beacons, simulate_fairway


def test_estimator_on_simulated_log_equals_batched_filter():
    # the log-driven estimator in the paper's mode and the batched layout filter see the same noise draw
    lay = np.array([[650.0, 370.0], [300.0, 50.0]])
    log = simulate_fairway(lay, seed=7)
    res = estimators.run("ekf-slam", log, paper=True)
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
    clean = run_ekf_slam(log)                    # the gate (0.999) is on by default
    gated = run_ekf_slam(bad)
    blind = run_ekf_slam(bad, gate=None)
    assert gated.info["rejected"] >= 1
    assert np.abs(gated.trajectory.poses[-1, :2] - clean.trajectory.poses[-1, :2]).max() < 0.5
    assert np.abs(blind.trajectory.poses[-1, :2] - clean.trajectory.poses[-1, :2]).max() > 2.0


# --- the real-log mode: gate, textbook first sighting, slots at first sighting, adaptive scale ---

def _filter_with_history(seed: int = 0) -> EkfSlam:
    """A filter with a correlated, non-trivial P: two predicts and one mapped beacon."""
    f = EkfSlam(np.array([1.0, -2.0, 0.4]), 1, pose_cov0=np.diag([0.04, 0.09, 0.01]), init="inverse")
    f.predict(2.0, 0.1, 1.0, 0.2, 0.05)
    f.update(0, 12.0, 0.3, 0.3, math.radians(2.0))
    f.predict(2.0, -0.05, 1.0, 0.2, 0.05)
    f.add_beacon()
    return f


def test_first_sighting_covariance_equals_the_closed_form_with_finite_difference_jacobians():
    f = _filter_with_history()
    x0, P0 = f.x.copy(), f.P.copy()
    z, sr, sb = np.array([7.5, -0.8]), 0.4, math.radians(3.0)

    def g(x: np.ndarray, zz: np.ndarray) -> np.ndarray:
        a = x[2] + zz[1]
        return np.array([x[0] + zz[0] * math.cos(a), x[1] + zz[0] * math.sin(a)])

    h = 1e-6
    gx = np.column_stack([(g(x0[:3] + h * e, z) - g(x0[:3] - h * e, z)) / (2 * h) for e in np.eye(3)])
    gz = np.column_stack([(g(x0[:3], z + h * e) - g(x0[:3], z - h * e)) / (2 * h) for e in np.eye(2)])
    assert f.update(1, z[0], z[1], sr, sb) is True           # first sighting: spent on the slot
    b = slice(5, 7)
    np.testing.assert_allclose(f.x[b], g(x0[:3], z), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(f.x[:5], x0[:5])           # nothing else moves
    Pbb = gx @ P0[:3, :3] @ gx.T + gz @ np.diag([sr**2, sb**2]) @ gz.T
    np.testing.assert_allclose(f.P[b, b], Pbb, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(f.P[b, :5], gx @ P0[:3, :5], rtol=1e-7, atol=1e-12)
    np.testing.assert_array_equal(f.P[:5, :5], P0[:5, :5])
    np.testing.assert_array_equal(f.P, f.P.T)


def test_first_sighting_covariance_matches_monte_carlo():
    f = _filter_with_history()
    x0, P0 = f.x.copy(), f.P.copy()
    z, sr, sb = np.array([7.5, -0.8]), 0.4, math.radians(3.0)
    f.update(1, z[0], z[1], sr, sb)
    rng = np.random.default_rng(1)
    n = 200_000
    xs = rng.multivariate_normal(x0[:5], P0[:5, :5], n)      # pose and the mapped beacon
    zr = z[0] + rng.normal(0, sr, n)
    a = xs[:, 2] + z[1] + rng.normal(0, sb, n)
    bxy = np.column_stack([xs[:, 0] + zr * np.cos(a), xs[:, 1] + zr * np.sin(a)])
    emp = np.cov(np.column_stack([xs, bxy]).T)
    scale = np.sqrt(np.outer(np.diag(f.P[:7, :7]), np.diag(f.P[:7, :7])))
    # first-order closed form vs sampled: within a few % of the scale (the map is mildly non-linear)
    assert np.max(np.abs(emp[5:, :] - f.P[5:7, :7]) / scale[5:, :]) < 0.03


def test_slot_added_at_first_sighting_equals_a_slot_from_the_start():
    rng = np.random.default_rng(3)
    a = EkfSlam(np.zeros(3), 2, init="inverse")
    b = EkfSlam(np.zeros(3), 0, init="inverse")
    beacons = {0: (30.0, 10.0), 1: (-5.0, 40.0)}
    pose = np.zeros(3)
    for k in range(60):
        for f in (a, b):
            f.predict(1.0, 0.02, 0.5, 0.1, 0.01)
        pose = pose + [0.5 * math.cos(pose[2]), 0.5 * math.sin(pose[2]), 0.01]
        j = k % 2
        if k < 10 and j == 1:
            continue                                          # beacon 1 first seen at k = 11
        d = np.array(beacons[j]) - pose[:2]
        zr, zb = float(np.hypot(*d) + rng.normal(0, 0.3)), float(math.atan2(d[1], d[0]) - pose[2])
        if j >= len(b.seen):
            assert b.add_beacon() == j
        a.update(j, zr, zb, 0.3, 0.01, gate=0.999)
        b.update(j, zr, zb, 0.3, 0.01, gate=0.999)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.P, a.P, rtol=0, atol=1e-12)


def test_gate_uses_the_mahalanobis_distance_and_leaves_the_state_alone():
    f = _filter_with_history()
    x, P = f.x.copy(), f.P.copy()
    b = 3
    d = f.x[b:b + 2] - f.x[:2]
    r, brg = float(np.hypot(*d)), float(wrap_angle(math.atan2(d[1], d[0]) - f.x[2]))
    assert f.update(0, r + 50.0, brg, 0.3, math.radians(2.0), gate=0.999) is False   # a 50 m false echo
    np.testing.assert_array_equal(f.x, x)
    np.testing.assert_array_equal(f.P, P)
    # the test statistic is nu^T S^-1 nu with S = H P H^T + Q: at the threshold's edge it flips
    H = np.zeros((2, f.n))
    H[0, [0, 1, b, b + 1]] = [-d[0] / r, -d[1] / r, d[0] / r, d[1] / r]
    H[1, [0, 1, 2, b, b + 1]] = [d[1] / r**2, -d[0] / r**2, -1.0, -d[1] / r**2, d[0] / r**2]
    S = H @ P @ H.T + np.diag([0.3**2, math.radians(2.0) ** 2])
    k = math.sqrt(chi2.ppf(0.999, 2) / np.linalg.inv(S)[0, 0])  # range offset with NIS = threshold
    assert f.update(0, r + 0.99 * k, brg, 0.3, math.radians(2.0), gate=0.999) is True
    f2 = _filter_with_history()
    assert f2.update(0, r + 1.01 * k, brg, 0.3, math.radians(2.0), gate=0.999) is False


@pytest.mark.parametrize("z_range", [-3.0, 0.0, math.nan, math.inf])
def test_a_range_that_is_not_positive_and_finite_is_rejected(z_range):
    f = _filter_with_history()
    x, P = f.x.copy(), f.P.copy()
    assert f.update(0, z_range, 0.1, 0.3, 0.01) is False
    assert f.update(1, z_range, 0.1, 0.3, 0.01) is False    # nor does it initialise a new slot
    assert not f.seen[1]
    np.testing.assert_array_equal(f.x, x)
    np.testing.assert_array_equal(f.P, P)


def test_estimator_counts_invalid_ranges_and_ignores_them():
    from dataclasses import replace

    log = simulate_fairway(np.array([[500.0, 300.0]]), seed=4)
    recs = list(log.records)
    idx = [k for k, r in enumerate(recs) if r.kind == "beacon"]
    for k in idx[5:200:20]:
        recs[k] = replace(recs[k], range=-recs[k].range)
    bad = run_ekf_slam(NavLog(recs, [], log.meta))
    assert bad.info["invalid"] == len(idx[5:200:20])
    assert np.all(np.isfinite(bad.trajectory.poses))


def _square_with_beacons(seed: int, outlier_rate: float = 0.0):
    """Two laps of the square loop, four uncharted beacons; a fraction of the sightings replaced by
    gross outliers (range off by 5-30 m or bearing off by 30-180 deg), first sightings included."""
    from dataclasses import replace

    from graphnav.sim.square import square_loop

    beacons = {"A": (-10.0, -10.0), "B": (50.0, -8.0), "C": (48.0, 52.0), "D": (-8.0, 45.0)}
    log = square_loop(seed, laps=2, gnss=False, compass=False, beacons=beacons, charted=False,
                      sigma_bearing=math.radians(1.0))
    if outlier_rate == 0.0:
        return log
    rng = np.random.default_rng(100 + seed)
    recs = list(log.records)
    for k, r in enumerate(recs):
        if r.kind == "beacon" and rng.random() < outlier_rate:
            if rng.random() < 0.5:
                recs[k] = replace(r, range=r.range + float(rng.choice([-1, 1]) * rng.uniform(5.0, 30.0)))
                recs[k] = replace(recs[k], range=abs(recs[k].range))
            else:
                recs[k] = replace(r, bearing=float(wrap_angle(r.bearing + rng.choice([-1, 1]) *
                                                               rng.uniform(math.radians(30), math.pi))))
    return NavLog(recs, [], log.meta)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_five_percent_gross_outliers_keep_the_ate_near_the_outlier_free_run(seed):
    from graphnav.evaluation.metrics import ate

    clean_log, bad_log = _square_with_beacons(seed), _square_with_beacons(seed, 0.05)
    truth = clean_log.truth()
    clean = ate(run_ekf_slam(clean_log).trajectory, truth)["rmse"]
    gated = run_ekf_slam(bad_log)
    bad = ate(gated.trajectory, truth)["rmse"]
    assert gated.info["rejected"] >= 0.03 * bad_log.counts()["beacon"]
    assert bad <= 1.25 * clean + 0.05
    try:                                                       # without the gate the outliers do hurt
        with np.errstate(all="ignore"):                        # (a diverging filter overflows on its way)
            blind = ate(run_ekf_slam(bad_log, gate=None).trajectory, truth)["rmse"]
    except ValueError as e:                                    # or the filter diverges, and says so
        assert "diverged" in str(e)
    else:
        assert blind > 3.0 * clean


def test_motion_noise_default_is_a_density_so_the_odometry_rate_does_not_change_it():
    from graphnav.log import BeaconObs, Odometry

    def heading_var(hz: float) -> float:
        n = int(60 * hz)
        recs = [Odometry(k / hz, 1.0, 0.05) for k in range(n + 1)] + [BeaconObs(60.0, "A", 10.0, 0.0)]
        res = run_ekf_slam(NavLog.from_unsorted(recs, [], {}), adaptive=False)
        return float(res.trajectory.cov[-2, 2, 2])             # before the sighting at 60 s

    sw = SENSOR_DEFAULTS["sigma_rot"]
    for hz in (2.0, 10.0, 100.0):
        assert heading_var(hz) == pytest.approx(sw**2 * 1.0 * 60.0, rel=0.02)


def test_nis_scale_follows_the_innovations():
    rng = np.random.default_rng(0)
    s = _NisScale(200, chi2.ppf(0.999, 2))
    for v in rng.chisquare(2, 200):
        s.add(float(v))
    assert s.scale < 1.3                                       # consistent innovations: (almost) no scaling
    for v in 4.0 * rng.chisquare(2, 200):
        s.add(float(v))
    assert 3.0 < s.scale < 5.0                                 # four times the variance: ~4
    for v in rng.chisquare(2, 200):
        s.add(float(v))
    assert s.scale < 1.3                                       # and back


def test_a_beacon_first_seen_through_a_gross_outlier_is_initialised_again():
    from dataclasses import replace

    log = _square_with_beacons(0)
    recs = list(log.records)
    k = next(i for i, r in enumerate(recs) if r.kind == "beacon" and r.id == "A")
    recs[k] = replace(recs[k], range=recs[k].range + 25.0)
    res = run_ekf_slam(NavLog(recs, [], log.meta))
    assert res.info["reinitialised"] >= 1
    assert np.hypot(*(np.array(res.info["beacons"]["A"]) - [-10.0, -10.0])) < 1.0
    stuck = run_ekf_slam(NavLog(recs, [], log.meta), reinit_after=None)
    assert np.hypot(*(np.array(stuck.info["beacons"]["A"]) - [-10.0, -10.0])) > 10.0


def test_first_estimates_jacobian_gains_no_spurious_heading_information():
    """Map-relative sightings of unknown beacons cannot tell the global heading (Huang, Mourikis &
    Roumeliotis 2008): with first-estimates Jacobians the heading variance never falls below its
    prior; the standard EKF, linearised at changing estimates, falls well below it."""
    def min_heading_var(fej: bool) -> float:
        rng = np.random.default_rng(0)
        beac = np.array([[20.0, 5.0], [-10.0, 25.0], [5.0, -20.0]])
        f = EkfSlam(np.zeros(3), len(beac), pose_cov0=np.diag([1.0, 1.0, 0.1**2]), init="inverse", fej=fej)
        pose, least = np.zeros(3), np.inf
        for _ in range(400):
            v, w, dt = 1.0, 0.05, 0.5
            pose = pose + [v * dt * math.cos(pose[2]), v * dt * math.sin(pose[2]), w * dt]
            f.predict(v + rng.normal(0, 0.05), w + rng.normal(0, 0.01), dt, 0.05, 0.01)
            for j, b in enumerate(beac):
                d = b - pose[:2]
                f.update(j, float(np.hypot(*d) + rng.normal(0, 0.2)),
                         float(wrap_angle(math.atan2(d[1], d[0]) - pose[2] + rng.normal(0, 0.02))), 0.2, 0.02)
            least = min(least, f.P[2, 2])
        return least

    assert min_heading_var(True) >= 0.1**2 * (1 - 1e-9)
    assert min_heading_var(False) < 0.1 * 0.1**2
