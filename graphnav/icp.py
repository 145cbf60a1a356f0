"""Weighted ICP scan matching (the weighted-ICP paper, section 2.1-2.2, eq. 11-22, Algorithm 1).

Variants (``IcpConfig.variant``):

* ``K``   classic point-to-point ICP, no weights;
* ``H``   Huber weights only, ``kHu = c * median pair distance`` (Algorithm 1, ``c = 2.0138``);
* ``HM``  Huber x mean-error weights ``w = (M_i^2 + M_j^2)^-1/2`` (eq. 11, 13);
* ``HD``  Huber x directional-error weights ``w = (sigma_beta_i^2 + sigma_beta_j^2)^-1/2`` (eq. 9, 11, 12),
  ``beta`` the direction from one point of the pair to the other;
* ``HDL`` (graphnav's improvement) the HD weights and Huber kernel on Censi's point-to-line
  metric: ``beta`` is the target's local normal, residual ``n . (R p + t - q)``.

Point-to-point variants are solved by the weighted SVD of eq. 15-20 (evaluated in its 2D closed
form, cross-checked against ``numpy.linalg.svd`` in the tests); HDL by a Gauss-Newton step per
iteration. Increments are accumulated as in eq. 21-22; iteration stops when the change of the
mean pair distance is below ``tol`` (Algorithm 1) or after ``max_iter``.

Frame convention: ``source`` is the current scan, ``target`` the previous one. The result
``pose = (dx, dy, dyaw)`` maps source points into the target frame, ``q = R(dyaw) p + (dx, dy)``:
it is the pose of the current scan in the previous scan's frame, i.e. the motion prev -> current,
the measurement of a ``gtsam.BetweenFactorPose2(prev, cur, Pose2(dx, dy, dyaw), noise)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .lidar import SIGMA_ALPHA, SIGMA_R_REL, polar_to_points

VARIANTS = ("K", "H", "HM", "HD", "HDL")
_BIG_COV = np.diag([1e4, 1e4, 10.0])  # returned with ok=False when there is nothing to match


@dataclass
class IcpConfig:
    """Settings of :func:`match_points` / :func:`match_scans` (SI units, radians)."""

    variant: str = "HDL"
    max_iter: int = 50
    tol: float = 1e-5  # stop when |change of mean pair distance| < tol [m] (Algorithm 1)
    huber_c: float = 2.0138  # kHu = huber_c * median pair distance (Algorithm 1)
    sigma_r_rel: float = SIGMA_R_REL  # sigma_r = sigma_r_rel * r (eq. 7)
    sigma_alpha: float = SIGMA_ALPHA  # angular 1-sigma [rad] (eq. 6)
    max_range: float | None = None  # range gate [m]
    min_range: float = 0.0
    max_corr_dist: float | None = None  # pairs farther apart get weight 0 (None: keep all, as the paper)
    matching: str = "kdtree"  # "kdtree" (cKDTree) or "delaunay" (the paper's nearest triangle apex)
    equalize: bool = False  # randomly thin the larger cloud to the smaller's size (the paper)
    seed: int = 0  # for equalize
    weight_power: float = 0.5  # w = G^-weight_power; 0.5 is eq. 11
    normal_k: int = 5  # neighbours of a target point for its line normal (HDL, degeneracy check)
    min_points: int = 20  # fewer valid points in either scan -> ok=False
    inlier_dist: float = 0.3  # a pair is an inlier when its final distance is below this [m]
    min_inlier_fraction: float = 0.3  # below -> ok=False
    max_condition: float = 1e3  # condition number of the (length-scaled) point-to-line information -> degenerate
    cov_scale: float = 1.0  # inflation of the covariance for unmodelled error (docs/weighted-icp.md)
    cov_floor: tuple[float, float, float] = (0.0, 0.0, 0.0)  # 1-sigma floor (x, y, yaw) added in quadrature
    workers: int = 1  # cKDTree query threads

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown ICP variant {self.variant!r}; known: {', '.join(VARIANTS)}")
        if self.matching not in ("kdtree", "delaunay"):
            raise ValueError(f"unknown matching {self.matching!r}; known: kdtree, delaunay")


@dataclass
class MatchResult:
    """Result of one scan match.

    ``pose`` (3,): ``(dx, dy, dyaw)``, the pose of the SOURCE (current) scan in the TARGET
    (previous) scan's frame = the relative motion prev -> current.

    ``cov`` (3, 3): covariance of ``pose`` in GTSAM's ``Pose2`` tangent-space convention, order
    ``(x, y, theta)``: the true relative pose is ``pose ∘ Exp(xi)``, ``xi ~ N(0, cov)``, with ``xi``
    expressed in the local frame of the estimated pose (right perturbation) — exactly the noise
    model of ``BetweenFactorPose2(prev, cur, Pose2(*pose), Gaussian.Covariance(cov))``.
    :attr:`cov_target` gives the same covariance for additive errors of ``(dx, dy, dyaw)`` in
    the target frame.

    ``ok`` is False for a degenerate or low-confidence match (see ``quality["reason"]``).
    """

    pose: NDArray[np.float64]
    cov: NDArray[np.float64]
    ok: bool
    quality: dict[str, Any] = field(default_factory=dict)

    @property
    def cov_target(self) -> NDArray[np.float64]:
        """Covariance of additive errors of ``(dx, dy, dyaw)`` in the target frame (first order)."""
        c, s = np.cos(self.pose[2]), np.sin(self.pose[2])
        a = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return a @ self.cov @ a.T


# ----------------------------------------------------------------------------- small numerics


def _rot(theta: float) -> NDArray[np.float64]:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def weighted_svd_align(
    p: NDArray[np.float64], q: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eq. 15-20 literally: ``R, T = argmin sum w ||R p + T - q||^2`` by the SVD of the weighted
    cross-covariance (reference implementation; the hot loop uses :func:`weighted_align`)."""
    sw = w.sum()
    mp = (w[:, None] * p).sum(0) / sw  # eq. 15
    mq = (w[:, None] * q).sum(0) / sw  # eq. 16
    c = (w[:, None, None] * (p[:, :, None] * q[:, None, :])).sum(0) / sw - np.outer(mp, mq)  # eq. 17
    u, _, vt = np.linalg.svd(c)  # eq. 18
    d = np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    r = vt.T @ d @ u.T  # eq. 19 (with the reflection guard)
    return r, mq - r @ mp  # eq. 20


def weighted_align(p: NDArray[np.float64], q: NDArray[np.float64], w: NDArray[np.float64]) -> tuple[float, NDArray]:
    """The 2D closed form of eq. 15-20: returns ``(theta, T)`` with ``R(theta) p + T ~ q``."""
    sw = w.sum()
    mp = w @ p / sw
    mq = w @ q / sw
    pc = p - mp
    qc = q - mq
    wp = pc * w[:, None]
    sxx = wp[:, 0] @ qc[:, 0]
    syy = wp[:, 1] @ qc[:, 1]
    sxy = wp[:, 0] @ qc[:, 1]
    syx = wp[:, 1] @ qc[:, 0]
    th = float(np.arctan2(sxy - syx, sxx + syy))
    c, s = np.cos(th), np.sin(th)
    return th, mq - np.array([c * mp[0] - s * mp[1], s * mp[0] + c * mp[1]])


def line_normals(pts: NDArray[np.float64], tree: cKDTree, k: int) -> tuple[NDArray, NDArray]:
    """Unit normals of the local line through each point's ``k`` nearest neighbours (PCA), and a
    flatness in [0, 1] (1 = a perfect line)."""
    k = int(min(k, len(pts)))
    _, nb = tree.query(pts, k=k)
    nbp = pts[nb]  # (N, k, 2)
    d = nbp - nbp.mean(1, keepdims=True)
    cxx = (d[..., 0] ** 2).mean(1)
    cyy = (d[..., 1] ** 2).mean(1)
    cxy = (d[..., 0] * d[..., 1]).mean(1)
    phi = 0.5 * np.arctan2(2 * cxy, cxx - cyy)  # direction of the line (major axis)
    n = np.column_stack([-np.sin(phi), np.cos(phi)])
    tr = cxx + cyy
    disc = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy**2, 0.0))
    lmin = 0.5 * tr - disc
    flat = np.where(tr > 0, 1.0 - 2.0 * lmin / np.maximum(tr, 1e-300), 0.0)
    return n, flat


class _Cloud:
    """Points of one scan with what the error model needs (range, unit radial vector)."""

    __slots__ = ("xy", "r", "u", "a2", "b2", "m2")

    def __init__(self, xy: NDArray, cfg: IcpConfig):
        self.xy = np.ascontiguousarray(xy, dtype=float)
        self.r = np.hypot(self.xy[:, 0], self.xy[:, 1])
        rs = np.where(self.r > 0, self.r, 1.0)
        self.u = self.xy / rs[:, None]
        self.a2 = (cfg.sigma_alpha * self.r) ** 2  # eq. 6, squared
        self.b2 = (cfg.sigma_r_rel * self.r) ** 2  # eq. 7, squared
        self.m2 = self.a2 + self.b2  # eq. 5, squared

    def take(self, idx: NDArray) -> None:
        for k in self.__slots__:
            setattr(self, k, getattr(self, k)[idx])

    def dir_var(self, idx: NDArray | slice, radial: NDArray, direction: NDArray) -> NDArray:
        """Eq. 9: error variance of points ``idx`` along unit ``direction`` (``radial`` rotated into
        the frame of ``direction``)."""
        a2, b2 = self.a2[idx], self.b2[idx]
        c = radial[:, 0] * direction[:, 0] + radial[:, 1] * direction[:, 1]
        return a2 - (a2 - b2) * c * c

    def cov(self, idx: NDArray | slice, rot: NDArray | None = None) -> NDArray:
        """Eq. 8 covariances (N, 2, 2) of points ``idx``, optionally rotated by ``rot``."""
        u = self.u[idx] if rot is None else self.u[idx] @ rot.T
        a2, b2 = self.a2[idx], self.b2[idx]
        # a^2 t t^T + b^2 u u^T with t the tangential unit vector (= alpha + 90 deg)
        uu = u[:, :, None] * u[:, None, :]
        eye = np.eye(2)[None]
        return a2[:, None, None] * (eye - uu) + b2[:, None, None] * uu


# ----------------------------------------------------------------------------- the matcher


def _pose_parts(init: ArrayLike | None) -> tuple[float, NDArray]:
    if init is None:
        return 0.0, np.zeros(2)
    x = np.asarray(init, dtype=float).ravel()
    if x.shape != (3,) or not np.all(np.isfinite(x)):
        raise ValueError(f"init must be a finite (dx, dy, dyaw), got {init!r}")
    return float(x[2]), x[:2].copy()


def _failed(reason: str, init: ArrayLike | None, n_src: int, n_tgt: int, t0: float) -> MatchResult:
    th, t = _pose_parts(init)
    q = {"points_used": 0, "points_source": n_src, "points_target": n_tgt, "inlier_fraction": 0.0,
         "residual": float("nan"), "condition_number": float("inf"), "iterations": 0, "degenerate": True,
         "converged": False, "reason": reason, "ms": (time.perf_counter() - t0) * 1e3}
    return MatchResult(np.array([t[0], t[1], th]), _BIG_COV.copy(), False, q)


def _match(tree: cKDTree, tri: Any, tgt: NDArray, p: NDArray, workers: int) -> tuple[NDArray, NDArray]:
    """Nearest target point of every point of ``p``: k-d tree, or the paper's Delaunay matching
    (nearest apex of the target triangle containing the point; k-d tree outside the hull)."""
    d, idx = tree.query(p, workers=workers)
    if tri is None:
        return d, idx
    simplex = tri.find_simplex(p)
    inside = simplex >= 0
    if np.any(inside):
        verts = tri.simplices[simplex[inside]]  # (m, 3)
        dd = np.linalg.norm(tgt[verts] - p[inside][:, None, :], axis=2)
        j = np.argmin(dd, axis=1)
        idx = idx.copy()
        d = d.copy()
        idx[inside] = verts[np.arange(len(j)), j]
        d[inside] = dd[np.arange(len(j)), j]
    return d, idx


def match_points(
    src_xy: ArrayLike,
    tgt_xy: ArrayLike,
    config: IcpConfig | None = None,
    init: ArrayLike | None = None,
    src_sigma: Any = None,
    tgt_sigma: Any = None,
) -> MatchResult:
    """Align ``src_xy`` (N, 2), the current scan's points in its sensor frame, to ``tgt_xy`` (M, 2),
    the previous scan's (Algorithm 1). ``init`` is the initial ``(dx, dy, dyaw)`` (e.g. the
    constant-velocity guess). Points are taken in their sensor frame (the LiDAR error model needs
    the range and beam direction, eq. 5-9). ``src_sigma``/``tgt_sigma`` are reserved (per-point
    sigmas are computed from the model of eq. 5-9 with the config's sigma_r_rel and sigma_alpha).
    """
    cfg = config or IcpConfig()
    t0 = time.perf_counter()
    src_xy = np.asarray(src_xy, dtype=float).reshape(-1, 2)
    tgt_xy = np.asarray(tgt_xy, dtype=float).reshape(-1, 2)
    src_xy = src_xy[np.all(np.isfinite(src_xy), axis=1)]
    tgt_xy = tgt_xy[np.all(np.isfinite(tgt_xy), axis=1)]
    ns, nt = len(src_xy), len(tgt_xy)
    if ns < cfg.min_points or nt < cfg.min_points:
        return _failed(f"too few points (source {ns}, target {nt}, need {cfg.min_points})", init, ns, nt, t0)

    src, tgt = _Cloud(src_xy, cfg), _Cloud(tgt_xy, cfg)
    if cfg.equalize and ns != nt:  # the paper: thin the larger set at random
        rng = np.random.default_rng(cfg.seed)
        big = src if ns > nt else tgt
        big.take(np.sort(rng.choice(max(ns, nt), min(ns, nt), replace=False)))
    tree = cKDTree(tgt.xy)
    tri = None
    if cfg.matching == "delaunay":
        from scipy.spatial import Delaunay

        tri = Delaunay(tgt.xy)
    p2l = cfg.variant == "HDL"
    normals = flat = None
    if p2l:
        normals, flat = line_normals(tgt.xy, tree, cfg.normal_k)

    th, t = _pose_parts(init)
    old_res = None
    converged = False
    it = 0
    for it in range(1, cfg.max_iter + 1):  # noqa: B007
        r = _rot(th)
        p = src.xy @ r.T + t
        d, idx = _match(tree, tri, tgt.xy, p, cfg.workers)
        q = tgt.xy[idx]
        w, _ = _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat)
        if p2l:
            dth, dt = _p2l_step(p, q, normals[idx], w)
        else:
            dth, dt = weighted_align(p, q, w)
        # eq. 21-22: accumulate the increment onto the running pose
        c, s = np.cos(dth), np.sin(dth)
        t = np.array([c * t[0] - s * t[1], s * t[0] + c * t[1]]) + dt
        th += dth
        new_res = float(d.mean())
        if old_res is not None and abs(new_res - old_res) < cfg.tol and abs(dth) < 1e-3 and np.hypot(*dt) < 1e-2:
            converged = True
            break
        old_res = new_res

    th = float(np.arctan2(np.sin(th), np.cos(th)))
    pose = np.array([t[0], t[1], th])
    return _finish(cfg, src, tgt, tree, tri, pose, normals, flat, it, converged, t0, ns, nt)


def _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat):  # noqa: ANN001, ANN202
    """Pair weights of Algorithm 1 (eq. 11-13 x Huber) and the pair variances they come from."""
    v = cfg.variant
    n = len(d)
    if v == "K":
        w = np.ones(n)
        g = None
    else:
        if v == "H":
            g = None
            w = np.ones(n)
        elif v == "HM":
            g = src.m2 + tgt.m2[idx]  # eq. 13
            w = g ** (-cfg.weight_power)
        else:
            if v == "HD":
                e = q - p
                ds = np.where(d > 0, d, 1.0)
                beta = e / ds[:, None]  # direction of the pair (eq. 12)
                beta[d <= 0] = (1.0, 0.0)
            else:  # HDL: the error along the target's normal
                beta = normals[idx]
            ur = src.u @ r.T  # source radial directions in the target frame
            g = src.dir_var(slice(None), ur, beta) + tgt.dir_var(idx, tgt.u[idx], beta)  # eq. 9, 12
            w = g ** (-cfg.weight_power)  # eq. 11
        # Huber (Algorithm 1): kHu = c * median distance
        dist = np.abs(np.einsum("ij,ij->i", p - q, normals[idx])) if v == "HDL" else d
        khu = cfg.huber_c * float(np.median(dist))
        big = dist > khu
        if khu > 0 and np.any(big):
            w = w.copy()
            w[big] *= khu / dist[big]
        if v == "HDL":
            w = w * flat[idx]
    if cfg.max_corr_dist is not None:
        w = np.where(d <= cfg.max_corr_dist, w, 0.0)
    if not np.any(w > 0):
        w = np.ones(n)
    return w, g


def _p2l_step(p: NDArray, q: NDArray, n: NDArray, w: NDArray) -> tuple[float, NDArray]:
    """One Gauss-Newton step of sum w (n.(p' - q))^2 over a left increment ``p' = R(dth) p + dt``."""
    rn = np.einsum("ij,ij->i", p - q, n)
    jac = np.column_stack([n[:, 0], n[:, 1], p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]])
    jw = jac * w[:, None]
    h = jw.T @ jac
    b = jw.T @ rn
    try:
        x = -np.linalg.solve(h + 1e-12 * np.eye(3), b)
    except np.linalg.LinAlgError:
        x = -np.linalg.lstsq(h, b, rcond=None)[0]
    # the linearisation uses p' ~ p + dt + dth J p; apply it as a rotation about the origin
    return float(x[2]), x[:2]


def _finish(cfg, src, tgt, tree, tri, pose, normals, flat, iters, converged, t0, ns, nt):  # noqa: ANN001, ANN202
    """Quality report and covariance at the solution (right perturbation in the source frame)."""
    r = _rot(pose[2])
    p = src.xy @ r.T + pose[:2]
    d, idx = _match(tree, tri, tgt.xy, p, cfg.workers)
    q = tgt.xy[idx]
    if normals is None:
        normals, flat = line_normals(tgt.xy, tree, cfg.normal_k)
    w, _ = _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat)
    e = p - q
    n = normals[idx]
    # Jacobian of the transformed source point w.r.t. xi = (vx, vy, w) applied on the right:
    # d p / d xi = R [I, J p_s], J = [[0, -1], [1, 0]]
    ps = src.xy
    inl = d <= cfg.inlier_dist
    use = w > 0
    # pair error covariances from the LiDAR model (eq. 8), source rotated into the target frame;
    # K and H assume isotropic, equal errors
    model = cfg.variant in ("HM", "HD", "HDL")
    if model:
        sig = src.cov(slice(None), r) + tgt.cov(idx)
    else:
        sig = np.broadcast_to(np.eye(2), (len(d), 2, 2))
    jp = np.column_stack([-ps[:, 1], ps[:, 0]])  # J p_s
    nr = n @ r  # rows n^T R
    if cfg.variant == "HDL":
        jac = np.column_stack([nr, np.einsum("ij,ij->i", nr, jp)])  # n^T R [I, J p_s]
        res = np.einsum("ij,ij->i", e, n)
        vi = np.einsum("ij,ijk,ik->i", n, sig, n)
        h = (jac * w[:, None]).T @ jac
        bmat = (jac * (w * w * vi)[:, None]).T @ jac
        sel = use & inl
        dof = max(int(sel.sum()) - 3, 1)
        kscale = float(np.sum(res[sel] ** 2 / vi[sel]) / dof) if sel.any() else float("nan")
        res_rms = float(np.sqrt(np.sum(w * res**2) / np.sum(w)))
    else:
        # 2 rows per pair: R [I, J p_s]
        a = np.zeros((len(d), 2, 3))
        a[:, :, 0] = r[:, 0]
        a[:, :, 1] = r[:, 1]
        a[:, :, 2] = jp @ r.T
        h = np.einsum("i,iab,iac->bc", w, a, a)
        bmat = np.einsum("i,iab,iad,idc->bc", w * w, a, sig, a)
        sel = use & inl
        dof = max(2 * int(sel.sum()) - 3, 1)
        sinv = np.linalg.inv(sig[sel]) if model else None
        if sel.any():
            kscale = float(np.einsum("ij,ijk,ik->", e[sel], sinv, e[sel]) / dof) if model \
                else float(np.sum(e[sel] ** 2) / dof)
        else:
            kscale = float("nan")
        res_rms = float(np.sqrt(np.sum(w * np.sum(e**2, 1)) / np.sum(w)))
    # degeneracy: the point-to-line information (what the geometry constrains), rotation scaled by
    # the cloud's RMS radius so the condition number is unit-free
    jl = np.column_stack([nr, np.einsum("ij,ij->i", nr, jp)])
    wl = (use & inl).astype(float) * flat[idx]
    lsc = float(np.sqrt(np.mean(np.sum((ps - ps.mean(0)) ** 2, 1)))) or 1.0
    jl[:, 2] /= lsc
    info = (jl * wl[:, None]).T @ jl
    ev = np.linalg.eigvalsh(info)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
    try:
        hinv = np.linalg.inv(h)
        cov = kscale * hinv @ bmat @ hinv.T
    except np.linalg.LinAlgError:
        cov = _BIG_COV.copy()
    cov = 0.5 * (cov + cov.T) * cfg.cov_scale + np.diag(np.square(cfg.cov_floor))
    inlier_fraction = float(inl.mean())
    degenerate = not np.isfinite(cond) or cond > cfg.max_condition
    reasons = []
    if degenerate:
        reasons.append(f"degenerate geometry (condition number {cond:.3g} > {cfg.max_condition:g})")
    if inlier_fraction < cfg.min_inlier_fraction:
        reasons.append(f"inlier fraction {inlier_fraction:.2f} < {cfg.min_inlier_fraction}")
    if not np.all(np.isfinite(cov)):
        reasons.append("non-finite covariance")
        cov = _BIG_COV.copy()
    quality = {
        "points_used": int(use.sum()),
        "points_source": ns,
        "points_target": nt,
        "inlier_fraction": inlier_fraction,
        "residual": res_rms,
        "residual_scale": kscale,
        "condition_number": cond,
        "iterations": int(iters),
        "converged": bool(converged),
        "degenerate": bool(degenerate),
        "reason": "; ".join(reasons),
        "ms": (time.perf_counter() - t0) * 1e3,
    }
    return MatchResult(pose, cov, not reasons, quality)


def scan_points(scan: Any, config: IcpConfig | None = None) -> NDArray[np.float64]:
    """Points of a :class:`graphnav.log.Scan` (eq. 10), missing returns dropped, range-gated."""
    cfg = config or IcpConfig()
    pts, _, _ = polar_to_points(scan.ranges, scan.angles, min_range=cfg.min_range, max_range=cfg.max_range)
    return pts


def match_scans(
    source: Any, target: Any, config: IcpConfig | None = None, init: ArrayLike | None = None
) -> MatchResult:
    """Match the current ``source`` :class:`~graphnav.log.Scan` to the previous ``target`` scan.

    Returns the pose of the source scan in the target's frame (motion prev -> current), see
    :class:`MatchResult` for the covariance convention.
    """
    cfg = config or IcpConfig()
    return match_points(scan_points(source, cfg), scan_points(target, cfg), cfg, init)
