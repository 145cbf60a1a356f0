"""NDT (graphnav.scan.ndt): Magnusson's 3D P2D-NDT and Biber's 2D NDT against closed forms, finite
differences, GTSAM's Pose3 tangent, the points' own Gaussians, and known transforms; the kernels compiled and as
plain Python."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gtsam
import numpy as np
import pytest
from _cloud_sim import apply, pair, rigid, scene
from _scan_sim import noisy_scan, points, room
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from graphnav.scan import ndt
from graphnav.scan.register3d import pose_error

# ----------------------------------------------------------------------------- constants, rotations


@pytest.mark.parametrize(("res", "ratio"), [(1.0, 0.55), (0.5, 0.3), (2.0, 0.9)])
def test_score_constants_fit_the_mixture_at_0_and_1(res, ratio):
    """Eq. 6.8: d1 exp(-d2 x^2 / 2) + d3 equals -log(c1 exp(-x^2 / 2) + c2) at x = 0 and x = 1."""
    d1, d2 = ndt.score_constants(res, ratio)
    c1, c2 = 10 * (1 - ratio), ratio / res ** 3
    d3 = -np.log(c2)
    for x in (0.0, 1.0):
        assert d1 * np.exp(-d2 * x * x / 2) + d3 == pytest.approx(-np.log(c1 * np.exp(-x * x / 2) + c2), rel=1e-12)
    assert d1 < 0 < d2


def test_score_constants_reject_a_bad_outlier_ratio():
    with pytest.raises(ValueError, match="outlier_ratio"):
        ndt.score_constants(1.0, 1.0)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_euler_rotation_and_its_derivatives(phi):
    """R = R_x R_y R_z (scipy's intrinsic 'XYZ'); dR and d2R equal central differences."""
    phi = np.array(phi)
    R, dR, d2R = ndt.euler_derivatives(phi)
    assert np.allclose(R, Rotation.from_euler("XYZ", phi).as_matrix(), atol=1e-12)
    h = 1e-5
    pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    for k in range(3):
        e = np.eye(3)[k] * h
        Rp, dRp, _ = ndt.euler_derivatives(phi + e)
        Rm, dRm, _ = ndt.euler_derivatives(phi - e)
        assert np.allclose((Rp - Rm) / (2 * h), dR[k], atol=1e-8)
        for pi, (a, b) in enumerate(pairs):
            if b == k:
                assert np.allclose((dRp[a] - dRm[a]) / (2 * h), d2R[pi], atol=1e-8)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_euler_to_tangent_is_gtsam_pose3_local_coordinates(seed):
    """G maps dp to delta with T(p + dp) T0 = T(p) T0 Exp(delta): checked with gtsam.Pose3.Logmap."""
    rng = np.random.default_rng(seed)
    p = np.r_[rng.normal(0, 2, 3), rng.uniform(-0.5, 0.5, 3)]
    T0 = rigid(rng.normal(0, 3, 3), rng.uniform(-60, 60, 3))
    G = ndt.euler_to_tangent(p, T0)
    T = gtsam.Pose3(ndt.pose_matrix(p) @ T0)
    for k in range(6):
        dp = np.eye(6)[k] * 1e-6
        Tp = gtsam.Pose3(ndt.pose_matrix(p + dp) @ T0)
        Tm = gtsam.Pose3(ndt.pose_matrix(p - dp) @ T0)
        num = (gtsam.Pose3.Logmap(T.between(Tp)) - gtsam.Pose3.Logmap(T.between(Tm))) / 2e-6
        assert np.allclose(num, G[:, k], atol=1e-6)


# ----------------------------------------------------------------------------- voxel maps


def test_voxel_gaussians_are_the_points_mean_and_regularised_covariance():
    rng = np.random.default_rng(1)
    flat = np.column_stack([rng.uniform(0.05, 0.95, (50, 2)), rng.uniform(0.5, 0.5005, 50)])  # voxel (0,0,0)
    few = rng.uniform(3.1, 3.9, (5, 3))                                                         # 5 < 6: dropped
    vm = ndt.build_voxels3(np.vstack([flat, few]), 1.0, min_points=6, eig_ratio=0.01)
    assert len(vm) == 1 and vm.counts[0] == 50
    assert np.allclose(vm.means[0], flat.mean(0))
    w, V = np.linalg.eigh(np.cov(flat.T))
    assert w[0] < 0.01 * w[-1]  # the regularisation of eq. 6.11 is exercised
    w = np.maximum(w, 0.01 * w[-1])
    assert np.allclose(vm.icovs[0], V @ np.diag(1 / w) @ V.T, rtol=1e-9)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([0.3, 1.0, 2.5]))
def test_voxel_map_holds_every_voxels_gaussian(seed, res):
    """Every voxel with >= min_points points, and no other, holds their mean and regularised inverse
    covariance (grouped here by numpy from the points' floor(x / res)); the hash table finds every key and
    no absent one."""
    rng = np.random.default_rng(seed)
    pts = scene(rng, 3000)
    pts[:5] = np.nan                              # non-finite points are skipped
    pts[5] = [1e9, 0, 0]                          # outside the key range: skipped
    vm = ndt.build_voxels3(pts, res, min_points=6, eig_ratio=0.01)
    ok = pts[6:]
    cells, inv, cnt = np.unique(np.floor(ok / res).astype(np.int64), axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    full = np.flatnonzero(cnt >= 6)
    assert len(vm) == len(full) and sorted(vm.counts.tolist()) == sorted(cnt[full].tolist())
    by_mean = {tuple(np.round(m, 9)): (m, ic) for m, ic in zip(vm.means, vm.icovs, strict=True)}
    for c in full:
        x = ok[inv == c]
        w, V = np.linalg.eigh(np.cov(x.T))
        m, ic = by_mean[tuple(np.round(x.mean(0), 9))]
        assert np.allclose(m, x.mean(0), atol=1e-12)
        ref = V @ np.diag(1 / np.maximum(w, 0.01 * w[-1])) @ V.T
        assert np.allclose(ic, ref, rtol=1e-7, atol=1e-7 * np.abs(ic).max())
    fast = ndt._fast()
    assert all(fast.hash_find(k, vm.tkeys, vm.tvals) == i for i, k in enumerate(vm.keys))
    probe = rng.integers(0, 1 << 62, 200)
    present = set(vm.keys.tolist())
    assert all(fast.hash_find(k, vm.tkeys, vm.tvals) == -1 for k in probe if int(k) not in present)


def test_voxel_map_memory_follows_the_points_not_the_bounding_box():
    """Two clusters 100 km apart: two voxels and a hash table of 8 slots, no dense grid."""
    rng = np.random.default_rng(2)
    pts = np.vstack([rng.normal(0.5, 0.1, (20, 3)), rng.normal(1e5 + 0.5, 0.1, (20, 3))])
    vm = ndt.build_voxels3(pts, 1.0)
    assert len(vm) == 2 and vm.tkeys.size == 8


# ----------------------------------------------------------------------------- derivatives


def _away_from_faces(x: np.ndarray, p: np.ndarray, res: float, margin: float = 2e-3) -> np.ndarray:
    """Points whose moved position is not within ``margin`` of a voxel face (the score jumps there)."""
    xp = apply(ndt.pose_matrix(p), x) / res
    frac = xp - np.floor(xp)
    return x[np.all((frac > margin) & (frac < 1 - margin), axis=1)]


@pytest.mark.parametrize("neighbors", [1, 7, 27])
def test_3d_gradient_and_hessian_equal_finite_differences(neighbors):
    rng = np.random.default_rng(3)
    tgt = scene(rng, 4000)
    vm = ndt.build_voxels3(tgt, 1.0)
    d1, d2 = ndt.score_constants(1.0, 0.55)
    off = ndt.neighbor_offsets(neighbors)
    p = np.array([0.12, -0.2, 0.05, 0.02, -0.015, 0.04])
    x = _away_from_faces(scene(rng, 800), p, 1.0)
    ev = ndt.derivatives3(x, p, vm, d1, d2, off)
    assert ev.hits > 300
    h = 1e-6
    g_num, H_num = np.zeros(6), np.zeros((6, 6))
    for k in range(6):
        e = np.eye(6)[k] * h
        a, b = ndt.derivatives3(x, p + e, vm, d1, d2, off), ndt.derivatives3(x, p - e, vm, d1, d2, off)
        g_num[k] = (a.f - b.f) / (2 * h)
        H_num[:, k] = (a.g - b.g) / (2 * h)
    assert np.allclose(g_num, ev.g, rtol=1e-5, atol=1e-5 * np.abs(ev.g).max())
    assert np.allclose(H_num, ev.H, rtol=1e-4, atol=1e-5 * np.abs(ev.H).max())
    assert np.allclose(ev.H, ev.H.T)
    assert np.linalg.eigvalsh(ev.G).min() > -1e-9 * np.abs(ev.G).max()  # Gauss-Newton part: PSD
    no_h = ndt.derivatives3(x, p, vm, d1, d2, off, hess=False)
    assert no_h.f == ev.f and np.array_equal(no_h.g, ev.g) and not no_h.H.any()


def _scan_pair(rng, pose, n_beams=720):
    """Two noisy 2D scans of the test room: from the origin (target) and from ``pose`` (source)."""
    segs = room()
    r0, a0 = noisy_scan(segs, (0.0, 0.0, 0.0), rng, n_beams)
    r1, a1 = noisy_scan(segs, pose, rng, n_beams)
    return points(r1, a1), points(r0, a0)


@pytest.mark.parametrize("grids", [1, 4])
def test_2d_gradient_and_hessian_equal_finite_differences(grids):
    rng = np.random.default_rng(4)
    src, tgt = _scan_pair(rng, (0.3, -0.2, 0.05))
    vm = ndt.build_voxels2(tgt, 1.0, grids=grids)
    p = np.array([0.25, -0.15, 0.04])
    c, s = np.cos(p[2]), np.sin(p[2])
    moved = src @ np.array([[c, -s], [s, c]]).T + p[:2]
    ok = np.ones(len(src), bool)
    for sh in vm.shifts:  # away from every grid's cell faces
        frac = (moved - sh) / vm.resolution % 1.0
        ok &= np.all((frac > 2e-3) & (frac < 1 - 2e-3), axis=1)
    x = src[ok]
    ev = ndt.derivatives2(x, p, vm)
    h = 1e-6
    g_num, H_num = np.zeros(3), np.zeros((3, 3))
    for k in range(3):
        e = np.eye(3)[k] * h
        a, b = ndt.derivatives2(x, p + e, vm), ndt.derivatives2(x, p - e, vm)
        g_num[k] = (a.f - b.f) / (2 * h)
        H_num[:, k] = (a.g - b.g) / (2 * h)
    assert np.allclose(g_num, ev.g, rtol=1e-5, atol=1e-6 * np.abs(ev.g).max())
    assert np.allclose(H_num, ev.H, rtol=1e-4, atol=1e-5 * np.abs(ev.H).max())


# ----------------------------------------------------------------------------- registration


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 10_000), st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_3d_ndt_recovers_transforms_within_the_basin(seed, t, rpy_deg):
    """Random rigid transforms (|t| <= 0.5 m: half a voxel; |angles| <= 3 deg: 0.8 m at the far
    walls) recover to 3 cm, 0.3 deg. The translation is drawn per axis and brought inside the half-voxel
    ball: the cube's corners (|t| up to 0.87 m) leave the basin (39 of 240 corner cases of 0.5 m on every
    axis failed, 0 of 468 at 0.5 m in 26 directions). (With 5 deg on every axis at once, 1 in 30 corners
    did not.)"""
    rng = np.random.default_rng(seed)
    t = np.asarray(t, float)
    t = t * min(1.0, 0.5 / max(float(np.linalg.norm(t)), 1e-12))
    T = rigid(list(t), rpy_deg)
    src, tgt = pair(rng, T, 5000)
    r = ndt.ndt3d(src, tgt)
    dt, dr = pose_error(r.T, T)
    assert dt < 0.03 and dr < 0.3, (dt, dr, r.iterations)
    assert r.converged and r.hits > 0.7 * len(src)  # the rest fall in voxels of < 6 points


_PLAIN_PYTHON = """
import json, sys
sys.modules["numba"] = None  # import numba -> ImportError: the kernels run as plain Python
sys.path[:0] = [{repo!r}]
import numpy as np
from graphnav.scan import ndt
assert ndt.resolve_backend("auto") == "python"
src, tgt = np.array({src}), np.array({tgt})
r = ndt.ndt2d(src, tgt, params=ndt.Ndt2Params(max_iter=8))
vm = ndt.build_voxels3(np.array({tgt3}), 1.0, min_points=4)
d1, d2 = ndt.score_constants(1.0, 0.55)
x = np.array({tgt3})[::3] + 0.05
ev = ndt.derivatives3(x, [0.05, 0.0, 0.02, 0.01, 0.0, 0.02], vm, d1, d2, ndt.neighbor_offsets(7))
print(json.dumps([r.pose.tolist(), r.iterations, ev.f, ev.g.tolist(), ev.H.tolist()]))
"""


def test_kernels_run_as_plain_python_without_numba():
    """Without numba the one implementation runs interpreted (graphnav.scan._jit) and gives the compiled
    results (to rounding of the math library)."""
    rng = np.random.default_rng(9)
    src, tgt = _scan_pair(rng, (0.2, 0.1, -0.03), n_beams=180)
    tgt3 = scene(rng, 300)
    repo = str(Path(__file__).resolve().parents[2])
    code = _PLAIN_PYTHON.format(repo=repo, src=src.tolist(), tgt=tgt.tolist(), tgt3=tgt3.tolist())
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    pose, iters, f, g, H = json.loads(out.stdout.strip().splitlines()[-1])
    r = ndt.ndt2d(src, tgt, params=ndt.Ndt2Params(max_iter=8))
    assert np.allclose(pose, r.pose, rtol=0, atol=1e-9) and iters == r.iterations
    vm = ndt.build_voxels3(tgt3, 1.0, min_points=4)
    d1, d2 = ndt.score_constants(1.0, 0.55)
    ev = ndt.derivatives3(tgt3[::3] + 0.05, [0.05, 0.0, 0.02, 0.01, 0.0, 0.02], vm, d1, d2, ndt.neighbor_offsets(7))
    assert f == pytest.approx(ev.f, rel=1e-12) and np.allclose(g, ev.g, rtol=1e-9, atol=1e-12)
    assert np.allclose(H, ev.H, rtol=1e-9, atol=1e-9 * np.abs(ev.H).max())


def test_3d_ndt_starts_from_init_and_reports_the_tangent_hessian():
    """From a far initial guess near the truth (a 3 m, 30 deg offset given as init) it converges, and
    cov = s^2 k H^-1 in the tangent of T (the documented Laplace form)."""
    rng = np.random.default_rng(7)
    T = rigid([3.0, -2.0, 0.2], [2.0, 1.0, 30.0])
    src, tgt = pair(rng, T, 5000)
    init = T @ rigid([0.3, 0.2, 0.0], [0.0, 0.0, 3.0])
    r = ndt.ndt3d(src, tgt, init=init)
    assert pose_error(r.T, T)[0] < 0.03
    w = np.linalg.eigvalsh(r.cov)
    assert np.all(w > 0) and np.allclose(r.cov, r.cov.T)
    assert np.allclose(np.linalg.inv(r.cov) @ r.cov, np.eye(6), atol=1e-6)


def test_3d_ndt_covariance_is_large_along_an_unobservable_direction():
    """A single floor plane: z, roll and pitch are constrained; x, y translation and yaw only through
    the voxel Gaussians' in-plane spread (NDT's pull towards voxel centres), 10x more loosely."""
    rng = np.random.default_rng(8)
    floor = np.column_stack([rng.uniform(-10, 10, 6000), rng.uniform(-10, 10, 6000), rng.normal(0.3, 0.01, 6000)])
    src = floor[:3000] - [0, 0, 0.05]
    r = ndt.ndt3d(src, floor[3000:])
    sd = np.sqrt(np.diag(r.cov))  # (omega_x, omega_y, omega_z, v_x, v_y, v_z)
    assert abs(r.T[2, 3] - 0.05) < 0.01
    assert sd[2] > 10 * max(sd[0], sd[1]) and min(sd[3], sd[4]) > 10 * sd[5]


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.floats(-0.2, 0.2), st.floats(-0.2, 0.2), st.floats(-0.05, 0.05))
def test_2d_ndt_recovers_transforms_within_the_basin(seed, x, y, yaw):
    """|x|, |y| <= 0.2 m and |yaw| <= 2.9 deg recover to 3 cm, 0.3 deg (150 of 150 random cases).
    Wider, the basin has holes: hypothesis found x = -0.372 m (seed 253), and seed 7553 with
    (-0.125, -0.223, -3.5 deg) stalls at the initial guess, reporting convergence (an open defect)."""
    rng = np.random.default_rng(seed)
    src, tgt = _scan_pair(rng, (x, y, yaw))
    r = ndt.ndt2d(src, tgt)
    assert np.hypot(r.pose[0] - x, r.pose[1] - y) < 0.03 and abs(r.pose[2] - yaw) < np.radians(0.3)
    assert r.converged and np.all(np.linalg.eigvalsh(r.cov) > 0)


def test_2d_ndt_covariance_is_in_the_body_frame():
    """GTSAM Pose2 tangent: the same scans registered with the target rotated by 90 deg give the
    same covariance (the body frame does not turn), the pose rotated."""
    rng = np.random.default_rng(9)
    src, tgt = _scan_pair(rng, (0.2, -0.1, 0.05))
    a = ndt.ndt2d(src, tgt)
    R = np.array([[0.0, -1.0], [1.0, 0.0]])
    b = ndt.ndt2d(src, tgt @ R.T, init=(*(R @ a.pose[:2]), a.pose[2] + np.pi / 2))
    assert np.allclose(b.pose[:2], R @ a.pose[:2], atol=5e-3)
    assert np.allclose(b.cov, a.cov, rtol=0.1, atol=1e-3 * np.abs(a.cov).max())
