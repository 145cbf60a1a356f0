"""Weighted ICP on synthetic scans with exact truth (graphnav.scan.weighted_icp)."""

from __future__ import annotations

import json
from pathlib import Path

import gtsam
import numpy as np
import pytest
from _scan_sim import corridor, even_points, noisy_scan, observe, points, raycast, room, to_frame
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.geometry import se2_between, se2_compose
from graphnav.log import NavLog, Scan, Truth
from graphnav.scan.movement import movement_from_increments
from graphnav.scan.weighted_icp import (
    VARIANTS,
    IcpConfig,
    MatchResult,
    match_points,
    match_scans,
    weighted_align,
    weighted_svd_align,
)

TIGHT = {"tol": 1e-12, "tol_step": 1e-10, "max_iter": 100}


def gtsam_error(est, true) -> np.ndarray:
    """xi with true = est ∘ Exp(xi) (GTSAM's Pose2 tangent space)."""
    return np.asarray(gtsam.Pose2.Logmap(gtsam.Pose2(*est).between(gtsam.Pose2(*true))))


# ----------------------------------------------------------------------------- solver pieces


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), th=st.floats(-3.0, 3.0))
def test_closed_form_alignment_equals_weighted_svd(seed, th):
    """The kernel's 2D closed form (graphnav.scan._icp_fast.weighted_align) equals the SVD of eq. 15-20."""
    rng = np.random.default_rng(seed)
    p = rng.normal(0, 5, (30, 2))
    c, s = np.cos(th), np.sin(th)
    q = p @ np.array([[c, -s], [s, c]]).T + rng.normal(0, 1, 2) + rng.normal(0, 0.1, (30, 2))
    w = rng.uniform(0.1, 2.0, 30)
    r_svd, t_svd = weighted_svd_align(p, q, w)
    th_cf, t_cf = weighted_align(p, q, w)
    assert np.arctan2(r_svd[1, 0], r_svd[0, 0]) == pytest.approx(th_cf, abs=1e-9)
    assert np.allclose(t_svd, t_cf, atol=1e-9)


def test_k_equals_open3d_point_to_point():
    """K is classic point-to-point ICP: from the same guess, with every pair kept and tight tolerances, it
    converges to open3d's point-to-point solution (an independent implementation: Kabsch on k-d tree pairs)."""
    o3d = pytest.importorskip("open3d")
    reg = o3d.pipelines.registration
    rng = np.random.default_rng(5)
    world = even_points(room(), 0.2)
    true = np.array([0.35, -0.15, np.radians(2.5)])
    tgt = observe(world, (0.0, 0.0, 0.0), rng, 0.004, 0.003)
    src = observe(world, true, rng, 0.004, 0.003)
    init = true + [0.05, -0.04, 0.01]
    ours = match_points(src, tgt, IcpConfig(variant="K", **TIGHT), init=init)

    def cloud(p):
        c = o3d.geometry.PointCloud()
        c.points = o3d.utility.Vector3dVector(np.column_stack([p, np.zeros(len(p))]))
        return c

    m = np.eye(4)
    m[:2, :2] = [[np.cos(init[2]), -np.sin(init[2])], [np.sin(init[2]), np.cos(init[2])]]
    m[:2, 3] = init[:2]
    crit = reg.ICPConvergenceCriteria(relative_fitness=1e-15, relative_rmse=1e-15, max_iteration=200)
    r = reg.registration_icp(cloud(src), cloud(tgt), 1e3, m, reg.TransformationEstimationPointToPoint(), crit)
    t = np.asarray(r.transformation)
    theirs = np.array([t[0, 3], t[1, 3], np.arctan2(t[1, 0], t[0, 0])])
    assert np.abs(ours.pose - theirs).max() < 1e-8, (ours.pose, theirs)
    assert np.abs(ours.pose - true).max() < 0.02


def test_config_rejects_unknown_variant():
    with pytest.raises(ValueError, match="variant"):
        IcpConfig(variant="X")


# ----------------------------------------------------------------------------- known answers


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_exact_recovery_without_noise(variant, seed):
    rng = np.random.default_rng(seed)
    world = even_points(room(), 0.15)
    true = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4), np.radians(rng.uniform(-6, 6))])
    p0 = np.array([rng.uniform(-2, 2), rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi)])
    tgt = to_frame(world, p0)
    src = to_frame(world, se2_compose(p0, true))
    # from a constant-velocity-like guess (every variant) and from zero (K, H, HDL; the range
    # weighting of HM/HD narrows the basin: docs/weighted-icp.md)
    inits = [true + [0.03, -0.02, np.radians(0.3)]] + ([None] if variant in ("K", "H", "HDL") else [])
    for init in inits:
        res = match_points(src, tgt, IcpConfig(variant=variant, **TIGHT), init=init)
        assert res.ok, res.quality
        assert np.abs(res.pose[:2] - true[:2]).max() < 1e-6
        assert abs(res.pose[2] - true[2]) < 1e-6


@pytest.mark.parametrize("opts", [{"matching": "delaunay"}, {"equalize": True}])
def test_paper_options_recover_the_motion(opts):
    world = even_points(room(), 0.15)
    true = np.array([0.4, -0.2, np.radians(3.0)])
    tgt = to_frame(world, (0, 0, 0))
    src = to_frame(world, true)
    src = np.vstack([src, src[:40] + 0.01])  # unequal counts for the equalisation
    res = match_points(src, tgt, IcpConfig(variant="HD", **opts), init=true + [0.03, -0.02, 0.005])
    assert np.abs(res.pose - true).max() < 0.01


def test_match_scans_drops_missing_returns_and_uses_sensor_frames():
    segs = room()
    ang = np.arange(720) * 2 * np.pi / 720
    true = np.array([0.5, 0.1, np.radians(2.0)])
    r0 = raycast(segs, (0.0, 0.0, 0.0), ang)
    r1 = raycast(segs, true, ang)
    r1[::7] = np.nan
    r1[3::11] = 0.0
    res = match_scans(Scan(1.0, r1, ang), Scan(0.0, r0, ang), IcpConfig(variant="HDL"))
    assert res.ok
    assert res.quality["points_source"] == int(np.sum(np.isfinite(r1) & (r1 > 0)))
    assert np.abs(res.pose[:2] - true[:2]).max() < 0.01
    assert abs(res.pose[2] - true[2]) < np.radians(0.1)


# ----------------------------------------------------------------------------- covariance


@pytest.mark.parametrize("beams", [180, 360])
def test_hdl_covariance_on_ray_cast_scans_is_not_overconfident(beams):
    """HDL on ray-cast scans of the room (1 and 0.5 deg beams, random beam offsets, range noise): the
    covariance (LiDAR noise + sampling, graphnav.scan.covariance) covers the error, error in GTSAM's
    convention. The room's walls are perfect lines, so the sampling term is generous here: mean NEES
    0.1-0.4 (the simulated harbour, with piles and hulls, is consistent: test_harbour_nees)."""
    rng = np.random.default_rng(11)
    nees = []
    for _ in range(60):
        true = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), np.radians(rng.uniform(-5, 5))])
        p0 = np.array([rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi)])
        tgt = points(*noisy_scan(room(), p0, rng, n_beams=beams))
        src = points(*noisy_scan(room(), se2_compose(p0, true), rng, n_beams=beams))
        res = match_points(src, tgt, IcpConfig(variant="HDL"), init=true + [0.05, -0.05, 0.01])
        assert res.ok, res.quality["reason"]
        xi = gtsam_error(res.pose, true)
        nees.append(xi @ np.linalg.solve(res.cov, xi))
    assert 0.02 < np.mean(nees) < 3.0, np.mean(nees)


def test_harbour_nees(legacy_harbour):
    """On the simulated harbour (exact truth; quays, piles, hulls, 1 deg beams to 40 m) the HDL
    covariance is consistent: mean NEES of the unflagged increments in [0.5, 3] (3 dof: 3 is exact)."""
    from graphnav.scan.icp_pairs import reference_increments, run_pairs

    log = legacy_harbour  # its 5 Hz scans with the odometry as the guess
    scans = log.of("scan")[:600]
    log = NavLog([r for r in log.records if r.t <= scans[-1].t], log.beacons_known, log.meta)
    pr = run_pairs(log, IcpConfig(variant="HDL"), init="odometry", guess_cov=False)  # the matcher's own flags
    ref = reference_increments(log, pr.t0, pr.t1)
    nees = [gtsam_error(r.pose, f) @ np.linalg.solve(r.cov, gtsam_error(r.pose, f))
            for r, f in zip(pr.results, ref, strict=True) if r.ok]
    assert len(nees) > 200
    assert 0.5 < np.mean(nees) < 3.0, np.mean(nees)


def test_covariance_convention_is_gtsam_tangent_not_target_additive():
    """In a long channel (strongly anisotropic) turned 90 deg between scans the two conventions
    differ a lot: ``cov`` fits the GTSAM error, ``cov_target`` the additive target-frame error.
    (HDL: the point-to-line covariance sees the channel's weak axis; point-to-point's does not.)"""
    rng = np.random.default_rng(3)
    segs = np.vstack([corridor(40.0, 2.0), [[-20, -2, -20, 2], [20, -2, 20, 2]]])
    world = even_points(segs, 0.25)
    s_rel, s_a = 0.004258, np.radians(0.2)
    cfg = IcpConfig(variant="HDL", sigma_r_rel=s_rel, sigma_alpha=s_a, max_condition=1e6, max_sigma=1e6)
    n_gtsam, n_wrong, n_target = [], [], []
    for _ in range(60):
        true = np.array([0.3 + rng.normal(0, 0.05), rng.normal(0, 0.05), np.pi / 2 + rng.normal(0, 0.01)])
        p0 = np.array([rng.uniform(-5, 5), rng.uniform(-0.5, 0.5), 0.0])
        tgt = observe(world, p0, rng, s_rel, s_a)
        src = observe(world, se2_compose(p0, true), rng, s_rel, s_a)
        res = match_points(src, tgt, cfg, init=true)
        xi = gtsam_error(res.pose, true)
        add = true - res.pose
        n_gtsam.append(xi @ np.linalg.solve(res.cov, xi))
        n_wrong.append(add @ np.linalg.solve(res.cov, add))
        n_target.append(add @ np.linalg.solve(res.cov_target, add))
    # the sampling term makes the covariance generous on these perfect walls (NEES < 3); what matters
    # is that the right convention fits and the wrong one is off by far more
    assert np.mean(n_gtsam) < 5.0 and 0.5 < np.mean(n_target) / np.mean(n_gtsam) < 2.0
    assert np.mean(n_wrong) > 5 * np.mean(n_gtsam)


def test_covariance_matches_gtsam_between_factor_hessian():
    """A BetweenFactorPose2 with the match's covariance has exactly that information (sanity
    check that (x, y, theta) ordering and scaling agree with GTSAM)."""
    rng = np.random.default_rng(2)
    world = even_points(room(), 0.3)
    true = np.array([0.4, 0.1, 0.05])
    res = match_points(observe(world, true, rng, 0.004, 0.003), observe(world, (0, 0, 0), rng, 0.004, 0.003),
                       IcpConfig(variant="HD"))
    f = gtsam.BetweenFactorPose2(1, 2, gtsam.Pose2(*res.pose), gtsam.noiseModel.Gaussian.Covariance(res.cov))
    v = gtsam.Values()
    v.insert(1, gtsam.Pose2(0, 0, 0))
    v.insert(2, gtsam.Pose2(*res.pose))
    lin = f.linearize(v)
    info = lin.augmentedInformation()[3:6, 3:6]
    assert np.allclose(info, np.linalg.inv(res.cov), rtol=1e-6)


# ----------------------------------------------------------------------------- robustness


def _outlier_case(rng):
    world = even_points(room(), 0.2)
    true = np.array([0.5, -0.2, np.radians(4.0)])
    tgt = observe(world, (0.0, 0.0, 0.0), rng, 0.002, 0.001)
    src = observe(world, true, rng, 0.002, 0.001)
    n_out = int(0.25 * len(src))  # 20 % of the final cloud
    junk = np.column_stack([rng.uniform(2.0, 9.0, n_out), rng.uniform(-5.0, 5.0, n_out)])  # clutter, one side
    return np.vstack([src, junk]), tgt, true


@pytest.mark.parametrize("variant", ["K", "H", "HM", "HD", "HDL"])
def test_twenty_percent_outliers_handled_by_huber_variants_not_k(variant):
    rng = np.random.default_rng(7)
    src, tgt, true = _outlier_case(rng)
    res = match_points(src, tgt, IcpConfig(variant=variant), init=np.zeros(3))
    err_t = np.hypot(*(res.pose[:2] - true[:2]))
    err_r = abs(res.pose[2] - true[2])
    if variant == "K":
        assert err_t > 0.05 or err_r > np.radians(0.5)
    else:
        assert err_t < 0.02 and err_r < np.radians(0.2), (err_t, np.degrees(err_r))


@pytest.mark.parametrize("variant", VARIANTS)
def test_corridor_is_flagged_degenerate(variant):
    rng = np.random.default_rng(4)
    world = even_points(corridor(200.0, 2.0), 0.2)
    src = observe(world, (1.2, 0.0, 0.0), rng, 0.002, 0.001)
    tgt = observe(world, (0.0, 0.0, 0.0), rng, 0.002, 0.001)
    res = match_points(src, tgt, IcpConfig(variant=variant), init=np.zeros(3))
    assert not res.ok
    assert res.quality["degenerate"]
    assert "degenerate" in res.quality["reason"]


def test_room_is_not_degenerate():
    rng = np.random.default_rng(4)
    world = even_points(room(), 0.2)
    res = match_points(observe(world, (0.4, 0.1, 0.03), rng, 0.002, 0.001),
                       observe(world, (0, 0, 0), rng, 0.002, 0.001), IcpConfig(variant="HD"))
    assert res.ok and not res.quality["degenerate"]
    assert 0.9 < res.quality["inlier_fraction"] <= 1.0


@pytest.mark.parametrize("n", [0, 5])
def test_nearly_empty_scan_is_flagged(n):
    rng = np.random.default_rng(0)
    tgt = even_points(room(), 0.2)
    res = match_points(rng.normal(0, 3, (n, 2)), tgt, IcpConfig(variant="HD"), init=[1.0, 0.0, 0.0])
    assert not res.ok
    assert "too few points" in res.quality["reason"]
    assert isinstance(res, MatchResult) and np.allclose(res.pose, [1.0, 0.0, 0.0])
    assert np.all(np.diag(res.cov) >= 1.0)


# ----------------------------------------------------------------------------- movement, estimator, CLI


def test_movement_parameters_eq23_25():
    inc = np.array([[1.0, 0.0, 0.1], [0.0, 2.0, -0.2], [0.6, 0.8, 0.0]])
    mv = movement_from_increments(inc, 0.5, hdg0=1.0)
    assert np.allclose(mv["sog"], [2.0, 4.0, 2.0])
    assert np.allclose(mv["rot"], [0.2, -0.4, 0.0])
    assert np.allclose(mv["hdg"], [1.1, 0.9, 0.9])
    assert np.allclose(mv["cog"], [1.0, 1.1 + np.pi / 2, 0.9 + np.arctan2(0.8, 0.6)])


def _synthetic_log(n=12, seed=0):
    rng = np.random.default_rng(seed)
    segs = room(30.0, 16.0)
    pose = np.array([-6.0, -2.0, 0.1])
    recs = []
    for k in range(n):
        r, a = noisy_scan(segs, pose, rng, n_beams=540, sigma_r_rel=0.002)
        recs.append(Scan(float(k), r, a))
        recs.append(Truth(float(k), *pose))
        pose = se2_compose(pose, [1.0, 0.0, np.radians(2.0)])
    return NavLog.from_unsorted(recs, [], {"name": "synthetic"})


def test_icp_dead_reckoning_estimator_follows_truth_online():
    from graphnav import estimators

    log = _synthetic_log()
    seen = []
    res = estimators.run("icp-dr", log, on_estimate=lambda t, p, c: seen.append((t, p, c)), variant="HDL")
    assert len(seen) == 12 and all(c is not None and c.shape == (3, 3) for _, _, c in seen)
    truth = log.truth()
    err = se2_between(res.trajectory.poses[-1], truth.poses[-1])
    assert np.hypot(*err[:2]) < 0.2 and abs(err[2]) < np.radians(1.0)
    # covariance grows along the chain
    assert np.trace(res.trajectory.cov[-1]) > np.trace(res.trajectory.cov[1]) > 0


def test_adjoint_matches_gtsam():
    from graphnav.geometry import se2_adjoint_inv

    inc = np.array([0.7, -0.3, 0.4])
    assert np.allclose(se2_adjoint_inv(inc), gtsam.Pose2(*inc).inverse().AdjointMap())


def test_cli_prints_one_json_object_with_the_issue_keys(tmp_path, capsys):
    from graphnav.cli import main
    from graphnav.io import save_log

    path = tmp_path / "syn.jsonl"
    save_log(_synthetic_log(8), path)
    rc = main(["icp", str(path), "--variant", "HD", "--init", "cv", "--out", str(tmp_path / "o"), "--json"])
    assert rc in (0, None)
    out = json.loads(capsys.readouterr().out)
    for key in ("variant", "pairs", "pairs_scored", "step_err_mean_m", "step_err_std_m", "step_err_max_abs_m",
                "step_err_rmse_m", "dtheta_err_mean_deg", "dtheta_err_std_deg", "dtheta_err_max_abs_deg",
                "dtheta_err_rmse_deg", "ms_per_pair_median"):
        assert key in out
    assert out["variant"] == "HD" and out["pairs"] == 7
    assert out["step_err_rmse_m"] < 0.05
    assert (tmp_path / "o" / "pairs.csv").exists()
    assert (tmp_path / "o" / "fig12_sog_diff.png").exists()
    assert (tmp_path / "o" / "fig15_dcog_hist.png").exists()


# ----------------------------------------------------------------------------- compiled backend


_PLAIN_PYTHON = """
import json, sys
sys.modules["numba"] = None  # import numba -> ImportError: the kernels run as plain Python
sys.path[:0] = [{repo!r}, {tests!r}]
import numpy as np
from _scan_sim import even_points, observe, room
from graphnav.errors import MissingExtra
from graphnav.scan.weighted_icp import IcpConfig, match_points
from graphnav.scan._jit import HAVE_NUMBA
assert not HAVE_NUMBA
src, tgt, cases = {case}
out = []
for kw in cases:
    r = match_points(np.array(src), np.array(tgt), IcpConfig(**kw), init=[0.45, -0.15, 0.03])
    out.append([r.pose.tolist(), r.cov.tolist(), r.quality["iterations"], r.ok])
try:
    match_points(np.array(src), np.array(tgt), IcpConfig(backend="numba"))
except MissingExtra:
    out.append("missing")
print(json.dumps(out))
"""


def test_kernels_run_as_plain_python_without_numba():
    """Without numba the one implementation runs interpreted (graphnav.scan._jit) and gives the compiled
    results (to rounding of the math library); ``backend="numba"`` then names the missing extra."""
    import subprocess
    import sys

    rng = np.random.default_rng(8)
    world = even_points(room(), 0.6)
    src = observe(world, (0.5, -0.2, 0.04), rng, 0.004, 0.003)
    tgt = observe(world, (0.0, 0.0, 0.0), rng, 0.004, 0.003)
    cases = [{"variant": "K"}, {"variant": "HD", "max_corr_dist": 0.3}, {"variant": "HDL"},
             {"variant": "HDL", "normals": "scan"}, {"variant": "HM", "matching": "delaunay"}]
    here = Path(__file__).resolve().parents[1]  # tests/
    code = _PLAIN_PYTHON.format(repo=str(here.parent), tests=str(here), case=(src.tolist(), tgt.tolist(), cases))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got[-1] == "missing"
    for kw, (pose, cov, iters, ok) in zip(cases, got[:-1], strict=True):
        ref = match_points(src, tgt, IcpConfig(**kw), init=[0.45, -0.15, 0.03])
        assert np.allclose(pose, ref.pose, rtol=0, atol=1e-9), (kw, pose, ref.pose)
        assert np.allclose(cov, ref.cov, rtol=1e-7, atol=0), kw
        assert iters == ref.quality["iterations"] and ok == ref.ok


def test_grid_neighbours_and_line_normals_are_exact():
    """The kernels' grid search finds scipy's k-d tree nearest point (also from any candidate, also far
    outside the target's box), and their k-nearest line normals are the PCA of the k-d tree's k nearest."""
    from scipy.spatial import cKDTree

    from graphnav.scan._icp_fast import build_grid, nearest, nearest_from
    from graphnav.scan.weighted_icp import line_normals

    rng = np.random.default_rng(8)
    tgt = rng.uniform(-20, 20, (300, 2))
    tx, ty = tgt[:, 0].copy(), tgt[:, 1].copy()
    q = rng.uniform(-40, 40, (200, 2))
    grid = build_grid(tx, ty, 0.5)
    d_ref, i_ref = cKDTree(tgt).query(q)
    got = np.array([nearest(x, y, tx, ty, grid) for x, y in q])
    assert np.array_equal(got[:, 1].astype(int), i_ref) and np.allclose(got[:, 0], d_ref, rtol=0, atol=1e-12)
    j0 = rng.integers(0, len(tgt), len(q))
    got = np.array([nearest_from(x, y, j, tx, ty, grid) for (x, y), j in zip(q, j0, strict=True)])
    assert np.array_equal(got[:, 1].astype(int), i_ref)
    n, flat = line_normals(tgt, 12)
    _, nb = cKDTree(tgt).query(tgt, k=12)
    for i in range(0, len(tgt), 7):
        lam, vec = np.linalg.eigh(np.cov(tgt[nb[i]].T))
        assert abs(n[i] @ vec[:, 0]) == pytest.approx(1.0, abs=1e-9)  # the minor axis
        assert flat[i] == pytest.approx((lam[1] - lam[0]) / (lam[1] + lam[0]), abs=1e-9)


def test_delaunay_walk_finds_scipys_triangle():
    """The paper's matching: the kernel's walk locates scipy's Delaunay triangle (or -1 outside the hull)."""
    from scipy.spatial import Delaunay

    from graphnav.scan._icp_fast import locate
    from graphnav.scan.weighted_icp import _triangulation

    rng = np.random.default_rng(2)
    tgt = rng.uniform(-10, 10, (200, 2))
    tri = _triangulation(tgt)
    q = rng.uniform(-14, 14, (300, 2))
    ref = Delaunay(tgt).find_simplex(q)
    got = [locate(x, y, tri, int(s0)) for (x, y), s0 in zip(q, rng.integers(0, len(tri[0]), len(q)), strict=True)]
    assert np.array_equal(got, ref)


@settings(max_examples=15, deadline=None)
@given(dx=st.floats(-0.8, 0.8), dy=st.floats(-0.5, 0.5), dth=st.floats(-0.1, 0.1), yaw0=st.floats(-3.1, 3.1))
def test_property_rigid_motion_is_recovered(dx, dy, dth, yaw0):
    """Any rigid motion of a noise-free room scan is recovered (K, from a guess 3 cm / 0.3 deg off)."""
    world = even_points(room(), 0.2)
    p0 = np.array([0.5, -0.3, yaw0])
    true = np.array([dx, dy, dth])
    tgt = to_frame(world, p0)
    src = to_frame(world, se2_compose(p0, true))
    res = match_points(src, tgt, IcpConfig(variant="K", **TIGHT), init=true + [0.03, -0.03, 0.005])
    assert np.abs(res.pose - true).max() < 1e-6


def test_reference_glitch_rule_known_answer():
    from graphnav.scan.icp_pairs import valid_reference_steps

    n = 40
    steps = np.column_stack([np.full(n, 1.25), np.zeros(n), np.zeros(n)])
    steps[10:20, 2] = np.radians(3.0)  # a turn: onset and end must stay valid
    steps[5, 0] = 0.07  # a short step
    steps[25, 2] = np.radians(-3.0)  # an isolated yaw spike
    steps[0] = np.nan  # no reference
    steps[34:, 0] = [1.0, 0.2, 1.2, 1.2, 0.8, 0.0]  # ragged end: 36-37 are fine but isolated
    ok = valid_reference_steps(steps)
    bad = set(np.flatnonzero(~ok))
    assert bad == {0, 5, 25, 34, 35, 36, 37, 38, 39}


def test_caller_sigmas_replace_the_lidar_model():
    """Per-point sigmas: equal ones make HM's weights uniform (= H); a huge sigma on the clutter
    mutes it even without the Huber kernel's help."""
    rng = np.random.default_rng(7)
    world = even_points(room(), 0.2)
    true = np.array([0.3, -0.1, 0.03])
    tgt = observe(world, (0.0, 0.0, 0.0), rng, 0.002, 0.001)
    src = observe(world, true, rng, 0.002, 0.001)
    hm = match_points(src, tgt, IcpConfig(variant="HM"), init=true, src_sigma=0.05, tgt_sigma=0.05)
    h = match_points(src, tgt, IcpConfig(variant="H"), init=true)
    assert np.allclose(hm.pose, h.pose, atol=1e-9)
    junk = np.column_stack([rng.uniform(2.0, 9.0, 150), rng.uniform(-5.0, 5.0, 150)])
    sig = np.r_[np.full(len(src), 0.01), np.full(150, 100.0)]
    res = match_points(np.vstack([src, junk]), tgt, IcpConfig(variant="HM", huber_c=1e9), init=np.zeros(3),
                       src_sigma=sig, tgt_sigma=0.01)
    assert np.abs(res.pose - true).max() < 0.01
    with pytest.raises(ValueError, match="src_sigma"):
        match_points(src, tgt, IcpConfig(), src_sigma=-1.0)
