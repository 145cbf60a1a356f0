"""Degenerate scan matches (single wall, corridor), the motion guess, the odometry increment, and
icp-dr bridging (issue #3, docs/weighted-icp.md "Degeneracy and initial guesses")."""

from __future__ import annotations

import numpy as np
import pytest
from _scan_sim import corridor, even_points, noisy_scan, observe, points, room

from graphnav.estimators.icp_odometry import run_icp_dr
from graphnav.geometry import increment, se2_compose
from graphnav.log import NavLog, Odometry, PosePrior, Scan, Truth, odometry_samples
from graphnav.scan import degeneracy
from graphnav.scan.motion_guess import MotionGuess
from graphnav.scan.weighted_icp import GUESS_SIGMA, VARIANTS, IcpConfig, MatchResult, match_points


def _wall_pair(variant: str, seed: int = 4):
    """A single straight 200 m wall 3 m to the side (y = -3), scanned by a 0.5 deg LiDAR (40 m
    range): x (along the wall) unobservable."""
    rng = np.random.default_rng(seed)
    wall = np.array([[-100.0, -3.0, 100.0, -3.0]])
    true = np.array([0.8, 0.05, 0.01])
    tgt = points(*noisy_scan(wall, (0.0, 0.0, 0.0), rng, n_beams=720, sigma_r_rel=0.002))
    src = points(*noisy_scan(wall, true, rng, n_beams=720, sigma_r_rel=0.002))
    return src, tgt, true


@pytest.mark.parametrize("variant", VARIANTS)
def test_single_wall_flagged_weak_along_wall_and_inflated(variant):
    src, tgt, true = _wall_pair(variant)
    guess = np.array([0.75, 0.0, 0.0])  # e.g. the odometry increment, 5 cm short along the wall
    cfg = IcpConfig(variant=variant)
    res = match_points(src, tgt, cfg, init=guess)
    q = res.quality
    assert not res.ok and q["degenerate"] and q["inflated"] and "degenerate" in q["reason"]
    w = np.asarray(q["weak_direction"])
    assert abs(w[0]) > 0.99 * np.linalg.norm(w)  # the weak direction is along the wall (x)
    # along the wall the estimate is the guess's; across it (y) and in yaw the wall's
    assert res.pose[0] == pytest.approx(guess[0], abs=0.02)
    assert res.pose[1] == pytest.approx(true[1], abs=0.03)
    # along the wall the pose is the guess's and so is the variance: a guess without a covariance has
    # the constant-velocity model's stated sigma (GUESS_SIGMA, 1 m), far above the across-wall one
    assert res.cov[0, 0] == pytest.approx(GUESS_SIGMA[0] ** 2, rel=0.05)
    assert res.cov[0, 0] > 100 * res.cov[1, 1]
    # with the guess's own covariance (e.g. the odometry's), that one
    odo = np.diag([0.05**2, 0.02**2, np.radians(0.5) ** 2])
    res2 = match_points(src, tgt, cfg, init=guess, init_cov=odo)
    assert res2.quality["degenerate"] and res2.pose[0] == pytest.approx(guess[0], abs=0.02)
    assert res2.cov[0, 0] == pytest.approx(0.05**2, rel=0.05)


def test_without_a_guess_the_estimate_is_kept_and_only_the_covariance_inflated():
    src, tgt, _ = _wall_pair("HDL")
    cfg = IcpConfig(variant="HDL")
    res = match_points(src, tgt, cfg)  # init None: nothing to take along the wall
    raw = match_points(src, tgt, IcpConfig(variant="HDL", max_condition=1e12, max_sigma=1e12))
    assert not res.ok and res.quality["degenerate"] and raw.ok
    assert np.allclose(res.pose, raw.pose)
    g = GUESS_SIGMA[0] ** 2  # nothing known along the wall but the constant-velocity model's sigma
    assert np.allclose(res.cov - raw.cov, g * np.outer([1, 0, 0], [1, 0, 0]), atol=0.02 * g)


def test_corridor_flagged_and_weak_along_it():
    rng = np.random.default_rng(5)
    world = even_points(corridor(200.0, 2.0), 0.2)
    src = observe(world, (1.2, 0.0, 0.0), rng, 0.002, 0.001)
    tgt = observe(world, (0.0, 0.0, 0.0), rng, 0.002, 0.001)
    res = match_points(src, tgt, IcpConfig(variant="HDL"), init=np.array([1.0, 0.0, 0.0]))
    assert not res.ok and res.quality["degenerate"]
    assert abs(res.quality["weak_direction"][0]) > 0.99
    assert res.pose[0] == pytest.approx(1.0, abs=0.02)  # the guess, not a slide along the walls


def _room_pair() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The room scanned from the origin and from ``true`` (0.4 m, 0.1 m, 0.03 rad): ``true``, the points."""
    rng = np.random.default_rng(6)
    segs = room()
    true = np.array([0.4, 0.1, 0.03])
    r0, a0 = noisy_scan(segs, (0.0, 0.0, 0.0), rng)
    r1, a1 = noisy_scan(segs, true, rng)
    p0 = np.column_stack([r0 * np.cos(a0), r0 * np.sin(a0)])[np.isfinite(r0)]
    p1 = np.column_stack([r1 * np.cos(a1), r1 * np.sin(a1)])[np.isfinite(r1)]
    return true, p0, p1


@pytest.mark.parametrize("variant", ["HD", "HDL"])
def test_room_not_flagged_and_not_inflated(variant):
    true, p0, p1 = _room_pair()
    res = match_points(p1, p0, IcpConfig(variant=variant), init=np.zeros(3))
    assert res.ok and not res.quality["degenerate"] and not res.quality["inflated"]
    assert res.quality["sigma_weak"] < 0.5
    assert np.all(np.sqrt(np.diag(res.cov))[:2] < 0.2)
    assert np.allclose(res.pose, true, atol=0.02)


def _cov(info: np.ndarray, s2: float, radius: float) -> np.ndarray:
    """``s2 info^-1`` (scaled coordinates) as an unscaled tangent-space covariance."""
    t = np.diag([1.0, 1.0, 1.0 / radius])
    return t @ (s2 * np.linalg.inv(info)) @ t


def test_analyse_known_answer():
    """info = diag(100, 1, 10) in scaled coordinates (L = 2) with the covariance 0.01 info^-1:
    ascending eigenvalues (1, 10, 100) -> sigmas (0.1, 0.0316, 0.01) m; condition 100."""
    info = np.diag([100.0, 1.0, 10.0])
    d = degeneracy.analyse(info, 2.0, _cov(info, 0.01, 2.0), max_condition=50.0, max_sigma=0.05)
    assert d.condition == pytest.approx(100.0)
    assert np.allclose(d.sigmas, [0.1, np.sqrt(0.001), 0.01])
    assert list(d.weak) == [True, False, False]  # y: condition 100 > 50 and 0.1 m > 0.05 m
    assert np.allclose(np.abs(d.weakest), [0, 1, 0])
    p = d.projector()
    assert np.allclose(p, np.diag([0.0, 1.0, 0.0]))
    assert np.allclose(d.inflation(2.0), np.diag([0.0, 4.0, 0.0]))
    fixed = degeneracy.keep_constrained(np.array([1.0, 0.5, 0.0]), np.array([1.3, 0.0, 0.0]), d)
    assert np.allclose(fixed, [1.0, 0.0, 0.0], atol=1e-12)  # y from the guess, x and yaw kept
    info = np.diag([100.0, 50.0, 10.0])
    ok = degeneracy.analyse(info, 2.0, _cov(info, 0.01, 2.0), max_condition=50.0, max_sigma=0.05)
    assert not ok.degenerate
    # a guess that knows x (sigma 0.005 m < the match's 0.01 m) makes x weak; one that does not, nothing
    tight = degeneracy.analyse(info, 2.0, _cov(info, 0.01, 2.0), max_condition=50.0,
                               prior_cov=np.diag([0.005**2, 1.0, 1.0]))
    assert list(tight.weak) == [False, False, True] and np.allclose(np.abs(tight.vectors[:, 2]), [1, 0, 0])
    loose = degeneracy.analyse(info, 2.0, _cov(info, 0.01, 2.0), max_condition=50.0,
                               prior_cov=np.diag([0.02**2, 1.0, 1.0]))
    assert not loose.degenerate
    assert degeneracy.analyse(info, 2.0, np.full((3, 3), np.nan)).weak.all()  # no covariance: nothing known


# ----------------------------------------------------------------------------- motion guess


def _result(pose, ok: bool) -> MatchResult:
    return MatchResult(np.asarray(pose, dtype=float), np.eye(3), ok, {})


def test_motion_guess_never_feeds_a_flagged_match_forward():
    g = MotionGuess("cv")
    assert g.guess(0.0, 0.2) is None  # nothing yet: identity
    g.update(_result([0.3, 0.0, 0.01], True), 0.0, 0.2)
    assert np.allclose(g.guess(0.2, 0.4), [0.3, 0.0, 0.01])
    g.update(_result([9.0, 0.0, 0.5], False), 0.2, 0.4)  # a flagged runaway
    assert np.allclose(g.guess(0.4, 0.8), [0.6, 0.0, 0.02])  # last GOOD one, scaled to dt = 0.4
    assert g.source == "stale-cv"


def test_motion_guess_falls_back_to_odometry_after_a_flagged_match():
    odo = np.array([[t, 1.5, 0.0, 0.05, 0.005] for t in np.arange(0.0, 2.0, 0.1)])
    g = MotionGuess("cv", odo)
    g.update(_result([0.25, 0.0, 0.0], True), 0.0, 0.2)
    assert np.allclose(g.guess(0.2, 0.4), [0.25, 0.0, 0.0]) and g.source == "cv"
    g.update(_result([5.0, 0.0, 0.0], False), 0.2, 0.4)
    assert np.allclose(g.guess(0.4, 0.6), [0.3, 0.0, 0.0]) and g.source == "odometry"
    inc, cov, how = g.bridge(0.4, 0.6)
    assert how == "odometry" and np.allclose(inc, [0.3, 0.0, 0.0]) and np.all(np.diag(cov) > 0)
    assert np.allclose(MotionGuess("odometry", odo).guess(0.0, 1.0), [1.5, 0.0, 0.0])
    assert MotionGuess("zero", odo).guess(0.0, 1.0) is None
    with pytest.raises(ValueError):
        MotionGuess("bogus")


# ----------------------------------------------------------------------------- odometry increment


def test_odometry_increment_straight_line():
    odo = np.array([[t, 2.0, 0.0, 0.1, 0.01] for t in np.arange(0.0, 5.0, 0.1)])
    inc, cov = increment(odo, 1.05, 3.05)
    assert np.allclose(inc, [4.0, 0.0, 0.0], atol=1e-12)
    # speed error: sigma_x^2 = sum (sigma_v dt_i)^2 over the 21 held intervals (+ the 1e-4 floor)
    dts = np.diff(np.r_[1.05, np.arange(1.1, 3.05, 0.1), 3.05])
    assert cov[0, 0] == pytest.approx(np.sum((0.1 * dts) ** 2) + len(dts) * 1e-8, rel=1e-6)
    assert cov[1, 1] > 0 and cov[2, 2] == pytest.approx(np.sum((0.01 * dts) ** 2) + len(dts) * 1e-8, rel=1e-6)
    assert increment(odo, 3.0, 1.0) is None
    assert increment(odo[5:], 0.0, 0.2) is None  # no sample at or before t1


def test_odometry_increment_constant_turn_closed_form():
    v, w, t = 1.5, 0.2, 4.0
    odo = np.array([[s, v, w, 0.05, 0.005] for s in np.arange(0.0, 10.0, 0.1)])
    inc, _ = increment(odo, 2.0, 2.0 + t)
    assert np.allclose(inc, [v / w * np.sin(w * t), v / w * (1 - np.cos(w * t)), w * t], atol=1e-9)


def test_odometry_samples_from_log():
    log = NavLog.from_unsorted([Odometry(0.0, 1.0, 0.1, 0.05, float("nan")), Odometry(0.1, 1.1, 0.0, 0.05, 0.01)])
    s = odometry_samples(log, sigma_w=0.02)
    assert s.shape == (2, 5) and s[0, 4] == 0.02 and s[1, 4] == 0.01


# ----------------------------------------------------------------------------- icp-dr bridging


def _corridor_log(n: int = 40, dt: float = 0.5, v: float = 1.5, seed: int = 0) -> NavLog:
    """A vessel sailing along a 400 m corridor (x unobservable from the scans) with odometry."""
    rng = np.random.default_rng(seed)
    segs = corridor(400.0, 4.0)
    recs = [PosePrior(0.0, 0.0, 0.0, 0.0, 0.1, 0.01)]
    for k in range(n):
        t = k * dt
        pose = (v * t, 0.0, 0.0)
        r, a = noisy_scan(segs, pose, rng, n_beams=180)
        recs += [Scan(t, r, a), Truth(t, *pose), Odometry(t, v + rng.normal(0, 0.02), 0.0, 0.02, 0.002)]
    return NavLog.from_unsorted(recs)


def test_icp_dr_corridor_bounded_with_odometry_bridging():
    log = _corridor_log()
    res = run_icp_dr(log, variant="HDL", init="cv")
    info = res.info
    # the corridor is flagged: degenerate matches from an odometry guess are chained constrained (the
    # walls across, the odometry along), the others bridged by the odometry
    assert info["failed_matches"] + info["constrained"] >= 0.8 * info["matches"]
    assert info["bridged_odometry"] == info["failed_matches"] and info["bridged_cv"] == 0
    end = res.trajectory.poses[-1]
    truth = log.of("truth")[-1]
    assert abs(end[0] - truth.x) < 0.5 and abs(end[1] - truth.y) < 0.3  # 29 m sailed
    # the reported covariance grows along the corridor (odometry), not faster than ~1 m
    assert 0 < res.trajectory.cov[-1][0, 0] < 1.0


def test_icp_dr_without_odometry_bridges_with_cv_and_wide_covariance():
    log = _corridor_log(n=12)
    log = NavLog.from_unsorted([r for r in log.records if r.kind != "odometry"])
    res = run_icp_dr(log, variant="HDL", init="cv")
    assert res.info["bridged_cv"] == res.info["failed_matches"] > 0
    assert res.trajectory.cov[-1][0, 0] > 1.0  # honest: x is unknown without odometry


def test_keep_constrained_uses_pose_composition():
    """Replacing the weak component composes in the estimate's frame (rotated estimate)."""
    info = np.diag([1e-6, 100.0, 100.0])
    d = degeneracy.analyse(info, 1.0, _cov(info, 1e-4, 1.0), max_condition=200.0)
    pose = np.array([0.0, 0.0, np.pi / 2])
    guess = se2_compose(pose, [0.7, 0.0, 0.0])  # 0.7 m ahead along the body x axis
    assert np.allclose(degeneracy.keep_constrained(pose, guess, d), guess, atol=1e-12)


def test_own_estimate_survives_a_guess_that_knows_better():
    """A room constrains every direction; a guess 3 cm / 0.3 deg off with a covariance far tighter than the match's
    (an IMU over a short interval) makes the matcher return the guess along all of them (weak "where the guess knows
    better"), but the match's own estimate, its covariance and its geometry (no weak direction) stay available for a
    fusion by information (MatchResult.own)."""
    true, p0, p1 = _room_pair()
    guess = true + np.array([0.03, -0.03, np.radians(0.3)])
    tight = np.diag([1e-4, 1e-4, np.radians(0.01)]) ** 2
    res = match_points(p1, p0, IcpConfig(), init=guess, init_cov=tight)
    assert res.quality["inflated"] and res.quality["weak_dims"] == 3
    assert np.allclose(res.pose, guess, atol=1e-9)  # the guess, all of it
    pose, cov, weak = res.own()
    assert weak is None and np.all(np.isfinite(cov))
    assert np.allclose(pose, true, atol=0.02)  # the match's own answer
    alone = match_points(p1, p0, IcpConfig(), init=guess)
    np.testing.assert_allclose(pose, alone.pose, atol=1e-12)
    np.testing.assert_allclose(cov, alone.cov, atol=1e-15)
