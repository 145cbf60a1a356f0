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

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from ..errors import require
from ..log import MAX_STATED_RANGE
from . import degeneracy
from .lidar import SIGMA_ALPHA, SIGMA_R_REL, polar_to_points

VARIANTS = ("K", "H", "HM", "HD", "HDL")
# default covariance inflation per variant: mean NEES ~3 against the RTK reference on the 160 clean
# marina pairs (benchmarks/icp_marina.py prints the NEES; docs/weighted-icp.md)
COV_SCALE = {"K": 300.0, "H": 120.0, "HM": 120.0, "HD": 120.0, "HDL": 50.0}
_BIG_COV = np.diag([1e4, 1e4, 10.0])  # returned with ok=False when there is nothing to match


@dataclass
class IcpConfig:
    """Settings of :func:`match_points` / :func:`match_scans` (SI units, radians)."""

    variant: str = "HDL"
    max_iter: int = 50
    tol: float = 1e-4  # stop when |change of mean pair distance| < tol [m] (Algorithm 1) ...
    tol_step: float = 3e-3  # ... and the last increment moved no point more than this [m]
    huber_c: float = 2.0138  # kHu = huber_c * median pair distance (Algorithm 1)
    sigma_r_rel: float = SIGMA_R_REL  # sigma_r = sigma_r_rel * r (eq. 7)
    sigma_alpha: float = SIGMA_ALPHA  # angular 1-sigma [rad] (eq. 6)
    max_range: float | None = None  # range gate [m]
    min_range: float = 0.0
    max_corr_dist: float | None = None  # pairs farther apart get weight 0 (None: keep all, as the paper)
    line_max_gap: float = 1.0  # beam neighbours farther apart are not on one line (scan-order normals) [m]
    line_flat_power: float = 4.0  # HDL: weight x flatness^power of the target's local line (0..1)
    line_warmup: float = 0.05  # HDL: point-to-point steps until a step moves no point more [m] (0: off)
    line_max_dist: float = 0.5  # HDL only: a point farther than this from its match has no line there [m]
    matching: str = "kdtree"  # "kdtree" (cKDTree) or "delaunay" (the paper's nearest triangle apex)
    equalize: bool = False  # randomly thin the larger cloud to the smaller's size (the paper)
    seed: int = 0  # for equalize
    weight_power: float = 0.5  # w = G^-weight_power; 0.5 is eq. 11
    normal_k: int = 12  # neighbours of a target point for its line normal (HDL, degeneracy check)
    normals: str = "knn"  # HDL normals: "knn" (PCA of the k nearest) or "scan" (k neighbours in beam order)
    min_points: int = 20  # fewer valid points in either scan -> ok=False
    inlier_dist: float = 0.3  # a pair is an inlier when its final distance is below this [m]
    min_inlier_fraction: float = 0.3  # below -> ok=False
    max_condition: float = 200.0  # condition number of the point-to-line information above -> degenerate
    max_sigma: float = 0.5  # predicted 1-sigma along the weakest direction above -> degenerate [m]
    weak_sigma: float = 1.0  # 1-sigma added along the weak directions of a degenerate match [m]
    # inflation for correlated, unmodelled error (sampling, motion distortion); None = the value
    # measured on the marina data for the variant (COV_SCALE, docs/weighted-icp.md); 1.0 = the pure
    # least-squares model (independent errors, synthetic scans)
    cov_scale: float | None = None
    cov_floor: tuple[float, float, float] = (0.0, 0.0, 0.0)  # 1-sigma floor (x, y, yaw) added in quadrature
    workers: int = 1  # cKDTree query threads
    # "numba" = compiled loop with exact grid matching, the numpy loop's results to ~1e-12 (every variant,
    # k-d tree matching; optional dependency, the first call compiles for 10-50 s, cached afterwards);
    # "auto" = numba when importable, else numpy
    backend: str = "auto"

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown ICP variant {self.variant!r}; known: {', '.join(VARIANTS)}")
        if self.backend not in ("auto", "numba", "numpy"):
            raise ValueError(f"unknown backend {self.backend!r}; known: auto, numba, numpy")
        if self.normals not in ("knn", "scan"):
            raise ValueError(f"unknown normals {self.normals!r}; known: knn, scan")
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


def weighted_align(p: NDArray, q: NDArray, w: NDArray) -> tuple[float, NDArray]:
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
    n, flat = _pca_normals(pts[nb])
    return n, flat


class _Cloud:
    """Points of one scan with what the error model needs (range, unit radial vector)."""

    __slots__ = ("xy", "r", "u", "a2", "b2", "m2")

    def __init__(self, xy: NDArray, cfg: IcpConfig, sigma: NDArray | None = None):
        self.xy = np.ascontiguousarray(xy, dtype=float)
        self.r = np.hypot(self.xy[:, 0], self.xy[:, 1])
        rs = np.where(self.r > 0, self.r, 1.0)
        self.u = self.xy / rs[:, None]
        if sigma is None:
            self.a2 = (cfg.sigma_alpha * self.r) ** 2  # eq. 6, squared
            self.b2 = (cfg.sigma_r_rel * self.r) ** 2  # eq. 7, squared
        else:  # caller's isotropic 1-sigma per point: a circle, a = b = sigma
            self.a2 = np.broadcast_to(np.asarray(sigma, dtype=float) ** 2, self.r.shape).copy()
            self.b2 = self.a2.copy()
        self.m2 = self.a2 + self.b2  # eq. 5, squared

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
         "residual": float("nan"),
         "residual_scale": float("nan"), "condition_number": float("inf"), "iterations": 0,
         "degenerate": True, "sigma_weak": float("inf"), "weak_direction": [float("nan")] * 3, "weak_dims": 3,
         "inflated": False,
         "converged": False, "reason": reason, "ms": (time.perf_counter() - t0) * 1e3}
    return MatchResult(np.array([t[0], t[1], th]), _BIG_COV.copy(), False, q)


def _per_point(sigma: Any, n: int, name: str) -> NDArray | None:
    if sigma is None:
        return None
    s = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(s) & (s > 0)):
        raise ValueError(f"{name} must be finite and > 0")
    return s


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
    constant-velocity guess); a degenerate match takes it along its weak directions and inflates
    the covariance there (docs/weighted-icp.md). Points are taken in their sensor frame (the
    LiDAR error model needs the range and beam direction, eq. 5-9). ``src_sigma``/``tgt_sigma``
    (scalar or one per point, metres) replace that model by an isotropic 1-sigma per point (e.g. for
    points that are not raw LiDAR returns); by default the model of eq. 5-9 with the config's
    sigma_r_rel, sigma_alpha.
    """
    cfg = config or IcpConfig()
    t0 = time.perf_counter()
    src_xy = np.asarray(src_xy, dtype=float).reshape(-1, 2)
    tgt_xy = np.asarray(tgt_xy, dtype=float).reshape(-1, 2)
    src_xy, src_sigma = _finite(src_xy, _per_point(src_sigma, len(src_xy), "src_sigma"))
    tgt_xy, tgt_sigma = _finite(tgt_xy, _per_point(tgt_sigma, len(tgt_xy), "tgt_sigma"))
    ns, nt = len(src_xy), len(tgt_xy)
    if ns < cfg.min_points or nt < cfg.min_points:
        return _failed(f"too few points (source {ns}, target {nt}, need {cfg.min_points})", init, ns, nt, t0)
    th0, g0 = _pose_parts(init)
    if math.hypot(g0[0], g0[1]) > 2.0 * MAX_STATED_RANGE:  # no point of either scan can overlap the other
        return _failed(f"initial guess moves the scan {math.hypot(g0[0], g0[1]):.3g} m, beyond any LiDAR's reach",
                       init, ns, nt, t0)
    if cfg.equalize and ns != nt:  # the paper: thin the larger set at random
        rng = np.random.default_rng(cfg.seed)
        keep = np.sort(rng.choice(max(ns, nt), min(ns, nt), replace=False))
        if ns > nt:
            src_xy, src_sigma = src_xy[keep], None if src_sigma is None else src_sigma[keep]
        else:
            tgt_xy, tgt_sigma = tgt_xy[keep], None if tgt_sigma is None else tgt_sigma[keep]
    fast = _fast_kernels(cfg)
    if fast is not None:
        return _match_compiled(fast, cfg, src_xy, tgt_xy, src_sigma, tgt_sigma, init, t0, ns, nt)

    src, tgt = _Cloud(src_xy, cfg, src_sigma), _Cloud(tgt_xy, cfg, tgt_sigma)
    nnm = _NearestNeighbours(tgt.xy, cfg)
    p2l = cfg.variant == "HDL"
    normals = flat = None
    if p2l:
        normals, flat = _target_lines(tgt.xy, cfg, nnm.tree)

    th, t = _pose_parts(init)
    old_res = None
    converged = False
    it = 0
    src_r = src.r.max()
    idx = np.zeros(0, dtype=int)
    # HDL: point-to-point (HD) steps while far from the solution; point-to-line has a narrow basin
    warm = p2l and cfg.line_warmup > 0
    for it in range(1, cfg.max_iter + 1):  # noqa: B007
        r = _rot(th)
        p = src.xy @ r.T + t
        d, idx = nnm.match(p)
        q = tgt.xy[idx]
        w, _ = _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat, p2p=warm)
        if p2l and not warm:
            dth, dt = _p2l_step(p, q, normals[idx], w)
        else:
            dth, dt = weighted_align(p, q, w)
        # eq. 21-22: accumulate the increment onto the running pose
        c, s = np.cos(dth), np.sin(dth)
        t = np.array([c * t[0] - s * t[1], s * t[0] + c * t[1]]) + dt
        th += dth
        new_res = float(d.mean())
        moved = abs(dth) * src_r + np.hypot(dt[0], dt[1])  # largest displacement of a point
        if warm:
            warm = moved > cfg.line_warmup
            old_res = None
            continue
        if old_res is not None and abs(new_res - old_res) < cfg.tol and moved < cfg.tol_step:
            converged = True
            break
        old_res = new_res

    pose = np.array([t[0], t[1], th])
    return _finish(cfg, src, tgt, idx, pose, normals, flat, it, converged, t0, ns, nt, init)


_VARIANT_CODE = {"K": 0, "H": 1, "HM": 2, "HD": 3}
_GRID_CELL = 1.0  # [m] cell of the compiled nearest-neighbour grids (exact at any size; 1 m: fastest on the marina)


_NO_SIGMA = np.zeros(0)


def _finite(xy: NDArray, sigma: NDArray | None) -> tuple[NDArray, NDArray | None]:
    """Rows of ``xy`` (and ``sigma``) with finite coordinates within
    :data:`graphnav.log.MAX_STATED_RANGE` of the sensor on each axis (no copy when all are): a
    point farther away is no LiDAR return, and bounding them bounds the matcher's grid and work."""
    with np.errstate(invalid="ignore"):
        ok = np.abs(xy) <= MAX_STATED_RANGE  # False for NaN
    if ok.all():
        return xy, sigma
    keep = ok.all(axis=1)
    return xy[keep], None if sigma is None else sigma[keep]


_COMPILED: list[Any] = []  # after the first look: [(p2p_match, hdl_match)], or [the ImportError]


def _compiled() -> tuple[Any, Any] | ImportError:
    """The compiled matcher's entry points, imported once: a failed import is not retried on every
    match (without numba it cost ~8 ms a call, as much as a match)."""
    if not _COMPILED:
        try:
            from ._icp_fast import hdl_match, p2p_match
        except ImportError as exc:
            _COMPILED.append(exc)
        else:
            _COMPILED.append((p2p_match, hdl_match))
    return _COMPILED[0]


def _fast_kernels(cfg: IcpConfig) -> Any:
    """The compiled matcher when it applies (k-d-tree-equivalent exact matching: K/H/HM/HD
    ``p2p_match``, HDL ``hdl_match``) and numba is importable (backend "auto" or "numba"); else None
    (the numpy loop)."""
    if cfg.backend == "numpy" or cfg.matching != "kdtree":
        return None
    kernels = _compiled()
    if isinstance(kernels, ImportError):
        if cfg.backend == "numba":
            require("numba", 'ICP backend "numba"')
            raise kernels.with_traceback(None)
        return None
    return kernels[1] if cfg.variant == "HDL" else kernels[0]


def _match_compiled(kernel: Any, cfg: IcpConfig, src_xy: NDArray, tgt_xy: NDArray, src_sigma: NDArray | None,
                    tgt_sigma: NDArray | None, init: ArrayLike | None, t0: float, ns: int, nt: int) -> MatchResult:
    """:func:`match_points` by one call of the compiled ``p2p_match`` / ``hdl_match`` (the same
    numbers as the numpy loop and :func:`_finish`), then the shared report :func:`_report`."""
    th0, g = _pose_parts(init)
    big = np.inf if cfg.max_corr_dist is None else cfg.max_corr_dist
    s, t = src_xy.T.copy(), tgt_xy.T.copy()  # contiguous x and y rows
    clouds = (s[0], s[1], _NO_SIGMA if src_sigma is None else src_sigma, src_sigma is not None,
              t[0], t[1], _NO_SIGMA if tgt_sigma is None else tgt_sigma, tgt_sigma is not None,
              cfg.sigma_alpha, cfg.sigma_r_rel)
    if cfg.variant == "HDL":
        out = kernel(*clouds, cfg.normals == "knn", cfg.normal_k, cfg.line_max_gap, cfg.huber_c,
                     cfg.weight_power, big, cfg.tol, cfg.tol_step, cfg.max_iter, th0, g[0], g[1], _GRID_CELL,
                     cfg.line_flat_power, cfg.line_warmup, cfg.line_max_dist, cfg.inlier_dist)
    else:
        out = kernel(*clouds, _VARIANT_CODE[cfg.variant], cfg.huber_c, cfg.weight_power, big, cfg.tol,
                     cfg.tol_step, cfg.max_iter, th0, g[0], g[1], _GRID_CELL, cfg.normal_k // 2,
                     cfg.line_max_gap, cfg.inlier_dist)
    th, tx, ty, it, converged, cov, cov_ok, ksum, dof, n_sel, res_rms, info, s2, n_use, n_inl, radius = out
    kscale = ksum / dof if n_sel else float("nan")
    pose = np.array([tx, ty, th])
    return _report(cfg, pose, cov if cov_ok else None, kscale, res_rms, info, s2, radius, n_use, n_inl / s.shape[1],
                   it, converged, t0, ns, nt, init)


def _target_lines(tgt_xy: NDArray, cfg: IcpConfig, tree: cKDTree | None = None) -> tuple[NDArray, NDArray]:
    """HDL's target normals and flatness (``cfg.normals``: k nearest by PCA, or beam order)."""
    if cfg.normals == "knn":
        return line_normals(tgt_xy, cKDTree(tgt_xy) if tree is None else tree, cfg.normal_k)
    return scan_order_normals(tgt_xy, cfg.normal_k // 2, cfg.line_max_gap)


class _NearestNeighbours:
    """Nearest target point of query points: k-d tree (scipy ``cKDTree``), or the paper's
    Delaunay matching (the nearest apex of the target triangle containing the point; k-d tree
    outside the hull)."""

    def __init__(self, tgt: NDArray, cfg: IcpConfig):
        self.tgt = tgt
        self.tree = cKDTree(tgt)
        self.workers = cfg.workers
        self.tri = None
        if cfg.matching == "delaunay":
            from scipy.spatial import Delaunay

            self.tri = Delaunay(tgt)

    def match(self, p: NDArray) -> tuple[NDArray, NDArray]:
        d, idx = self.tree.query(p, workers=self.workers)
        if self.tri is None:
            return d, idx
        simplex = self.tri.find_simplex(p)
        inside = simplex >= 0
        if np.any(inside):
            verts = self.tri.simplices[simplex[inside]]  # (m, 3)
            dd = np.linalg.norm(self.tgt[verts] - p[inside][:, None, :], axis=2)
            j = np.argmin(dd, axis=1)
            rows = np.arange(len(j))
            idx = idx.copy()
            d = d.copy()
            idx[inside] = verts[rows, j]
            d[inside] = dd[rows, j]
        return d, idx


def scan_order_normals(pts: NDArray, half: int = 2, max_gap: float = 1.0) -> tuple[NDArray, NDArray]:
    """Normals and flatness of each point from its ``2 half + 1`` neighbours in beam order
    (sorted by bearing; no neighbour search), by PCA. A window with a gap wider than ``max_gap``
    between beam neighbours spans two surfaces: its flatness is 0."""
    n = len(pts)
    order = np.argsort(np.arctan2(pts[:, 1], pts[:, 0]), kind="stable")
    ps = pts[order]
    win = (np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :]) % n
    nrm, flat = _pca_normals(ps[win])
    gap = np.hypot(*(np.roll(ps, -1, axis=0) - ps).T)  # gap[i]: between sorted points i and i+1
    wide = (gap[win[:, :-1]] > max_gap).any(axis=1)
    flat = np.where(wide, 0.0, flat)
    out_n = np.empty_like(nrm)
    out_f = np.empty_like(flat)
    out_n[order] = nrm
    out_f[order] = flat
    return out_n, out_f


def _pca_normals(pts: NDArray) -> tuple[NDArray, NDArray]:
    """Normals and flatness of point groups ``pts`` (N, k, 2) by PCA."""
    k = pts.shape[1]
    x = pts[:, :, 0] - pts[:, :, 0].sum(1, keepdims=True) / k
    y = pts[:, :, 1] - pts[:, :, 1].sum(1, keepdims=True) / k
    cxx = (x * x).sum(1)
    cyy = (y * y).sum(1)
    cxy = (x * y).sum(1)
    phi = 0.5 * np.arctan2(2 * cxy, cxx - cyy)  # direction of the line (major axis)
    n = np.column_stack([-np.sin(phi), np.cos(phi)])
    tr = cxx + cyy
    disc = np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy**2)
    flat = np.where(tr > 0, 2.0 * disc / np.where(tr > 0, tr, 1.0), 0.0)  # (l1 - l2) / (l1 + l2)
    return n, flat


def _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat, p2p=False):  # noqa: ANN001, ANN202
    """Pair weights of Algorithm 1 (eq. 11-13 x Huber) and the pair variances they come from
    (``p2p``: HD weights during HDL's point-to-point warm-up)."""
    v = "HD" if p2p else cfg.variant
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
        khu = cfg.huber_c * _median(dist)
        big = dist > khu
        if khu > 0 and np.any(big):
            w = w.copy()
            w[big] *= khu / dist[big]
        if v == "HDL":  # no line where the match is far (the gate widens while far from convergence)
            w = w * flat[idx] ** cfg.line_flat_power * (d <= max(cfg.line_max_dist, cfg.huber_c * _median(d)))
    if cfg.max_corr_dist is not None:
        w = np.where(d <= cfg.max_corr_dist, w, 0.0)
    if not np.any(w > 0):
        w = np.ones(n)
    return w, g


def _median(x: NDArray) -> float:
    n = len(x)
    h = n // 2
    if n % 2:
        return float(np.partition(x, h)[h])
    part = np.partition(x, (h - 1, h))
    return 0.5 * float(part[h - 1] + part[h])


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


def _pair_cov(src: _Cloud, tgt: _Cloud, idx: NDArray, r: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Eq. 8 covariance of the pair difference (source point rotated into the target frame plus
    its target match), as its entries ``(sxx, sxy, syy)``."""
    u = src.u @ r.T
    ds = src.b2 - src.a2
    ut = tgt.u[idx]
    dt = tgt.b2[idx] - tgt.a2[idx]
    a2 = src.a2 + tgt.a2[idx]
    sxx = a2 + ds * u[:, 0] ** 2 + dt * ut[:, 0] ** 2
    syy = a2 + ds * u[:, 1] ** 2 + dt * ut[:, 1] ** 2
    sxy = ds * u[:, 0] * u[:, 1] + dt * ut[:, 0] * ut[:, 1]
    return sxx, sxy, syy


def _terms_numpy(cfg, src, tgt, idx, pose, normals, flat):  # noqa: ANN001, ANN202
    """``H``, ``B``, residual scale, RMS residual, point-to-line information, pairs used,
    inlier fraction, residual variance along the normals and the source's RMS radius at the
    solution (see :func:`_finish`)."""
    r = _rot(pose[2])
    p = src.xy @ r.T + pose[:2]
    q = tgt.xy[idx]  # the last iteration's pairs (the last increment moved no point > tol_step)
    e = p - q
    d = np.hypot(e[:, 0], e[:, 1])
    if normals is None:  # the degeneracy check needs the target's local lines
        normals, flat = scan_order_normals(tgt.xy, cfg.normal_k // 2, cfg.line_max_gap)
    w, _ = _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat)
    n, fl = normals[idx], flat[idx]
    jp = p - pose[:2]
    c2 = np.column_stack([-jp[:, 1], jp[:, 0]])  # J (p - t) = R J p_s
    inl = d <= cfg.inlier_dist
    use = w > 0
    sel = use & inl
    model = cfg.variant in ("HM", "HD", "HDL")
    if model:
        sxx, sxy, syy = _pair_cov(src, tgt, idx, r)
    else:
        sxx, sxy, syy = np.ones(len(d)), np.zeros(len(d)), np.ones(len(d))
    # point-to-line rows n^T [R, J (p - t)]: the HDL Jacobian and the degeneracy check
    nr = n @ r
    jl = np.column_stack([nr, np.einsum("ij,ij->i", n, c2)])
    if cfg.variant == "HDL":
        res = np.einsum("ij,ij->i", e, n)
        vi = sxx * n[:, 0] ** 2 + 2 * sxy * n[:, 0] * n[:, 1] + syy * n[:, 1] ** 2
        h = (jl * w[:, None]).T @ jl
        bmat = (jl * (w * w * vi)[:, None]).T @ jl
        dof = max(int(sel.sum()) - 3, 1)
        kscale = float(np.sum(res[sel] ** 2 / vi[sel]) / dof) if sel.any() else float("nan")
        res_rms = float(np.sqrt(np.sum(w * res**2) / np.sum(w)))
    else:
        a = np.empty((len(d), 2, 3))
        a[:, :, 0] = r[:, 0]
        a[:, :, 1] = r[:, 1]
        a[:, :, 2] = c2
        sa = np.empty_like(a)
        sa[:, 0, :] = sxx[:, None] * a[:, 0, :] + sxy[:, None] * a[:, 1, :]
        sa[:, 1, :] = sxy[:, None] * a[:, 0, :] + syy[:, None] * a[:, 1, :]
        h = (a * w[:, None, None]).reshape(-1, 3).T @ a.reshape(-1, 3)
        bmat = (a * (w * w)[:, None, None]).reshape(-1, 3).T @ sa.reshape(-1, 3)
        dof = max(2 * int(sel.sum()) - 3, 1)
        det = sxx * syy - sxy**2
        m = (syy * e[:, 0] ** 2 - 2 * sxy * e[:, 0] * e[:, 1] + sxx * e[:, 1] ** 2) / det
        kscale = float(m[sel].sum() / dof) if sel.any() else float("nan")
        res_rms = float(np.sqrt(np.sum(w * np.sum(e**2, 1)) / np.sum(w)))
    # degeneracy: the point-to-line information (what the geometry constrains), rotation scaled by
    # the cloud's RMS radius so that the condition number is unit-free
    lsc = degeneracy.rms_radius(src.xy)
    jl[:, 2] /= lsc
    info = (jl * (sel * fl)[:, None]).T @ jl
    s2 = degeneracy.residual_var(e, n, sel * fl)
    return h, bmat, kscale, res_rms, info, int(use.sum()), float(inl.mean()), s2, lsc


def _finish(cfg, src, tgt, idx, pose, normals, flat, iters, converged, t0, ns, nt, init=None):  # noqa: ANN001, ANN202
    """Quality report and covariance at the solution.

    The covariance is the sandwich ``k H^-1 B H^-1`` of the weighted least-squares problem at
    convergence: ``H = sum w J^T J``, ``B = sum w^2 J^T S J`` with ``S`` the pair's error covariance
    from the LiDAR model (eq. 8; identity for K and H) and ``k`` its scale estimated from the
    inlier residuals (``k = sum e^T S^-1 e / dof``). ``J`` is the Jacobian of the residual with
    respect to ``xi``, the right perturbation ``pose ∘ Exp(xi)`` (GTSAM's Pose2 tangent space):
    ``d(R p_s + t)/d xi = R [I, J p_s] = [R, J (p - t)]``, ``J = [[0, -1], [1, 0]]``.

    Degeneracy (:mod:`graphnav.scan.degeneracy`, every variant): weak directions of the point-to-line
    information; there the pose is replaced by ``init``'s and ``weak_sigma^2`` is added to ``cov``.
    """
    h, bmat, kscale, res_rms, info, n_use, inlier_fraction, s2, radius = _terms_numpy(
        cfg, src, tgt, idx, pose, normals, flat)
    try:
        hinv = np.linalg.inv(h)
        cov = kscale * hinv @ bmat @ hinv.T
    except np.linalg.LinAlgError:
        cov = None
    return _report(cfg, pose, cov, kscale, res_rms, info, s2, radius, n_use,
                   inlier_fraction, iters, converged, t0, ns, nt, init)


def _report(cfg, pose, cov, kscale, res_rms, info, s2, radius, n_use, inlier_fraction, iters, converged, t0,  # noqa: ANN001, ANN202, PLR0913
            ns, nt, init):
    """The part of :func:`_finish` shared with the compiled matcher: covariance scaling (``cov``
    None: ``H`` was singular), degeneracy (the weak directions take ``init``'s pose), the report."""
    pose[2] = np.arctan2(np.sin(pose[2]), np.cos(pose[2]))
    if cov is None:
        cov = _BIG_COV.copy()
    scale = COV_SCALE[cfg.variant] if cfg.cov_scale is None else cfg.cov_scale
    cov = 0.5 * (cov + cov.T) * scale + np.diag(np.square(cfg.cov_floor))
    # degeneracy (docs/weighted-icp.md): the point-to-line information's weak directions, whatever
    # the variant's metric, its predicted covariance inflated as HDL's (the point-to-line scale);
    # along weak directions the pose is the initial guess's and the covariance is inflated
    line_scale = COV_SCALE["HDL"] if cfg.cov_scale is None else cfg.cov_scale
    deg = degeneracy.analyse(info, s2, radius, scale=line_scale,
                             max_condition=cfg.max_condition, max_sigma=cfg.max_sigma)
    cond = deg.condition
    degenerate = deg.degenerate
    reasons = []
    if degenerate:
        why = []
        if not np.isfinite(cond) or cond > cfg.max_condition:
            why.append(f"condition number {cond:.3g} > {cfg.max_condition:g}")
        if deg.sigma_weak > cfg.max_sigma:
            why.append(f"weakest-direction 1-sigma {deg.sigma_weak:.3g} m > {cfg.max_sigma:g} m")
        reasons.append(f"degenerate geometry ({', '.join(why) or 'no residual scale'})")
        if init is not None:  # without a guess the estimate is all there is: only inflate
            th0, t0_ = _pose_parts(init)
            pose = degeneracy.keep_constrained(pose, np.array([t0_[0], t0_[1], th0]), deg)
        if np.all(np.isfinite(cov)):
            cov = cov + deg.inflation(cfg.weak_sigma)
    inflated = degenerate
    if inlier_fraction < cfg.min_inlier_fraction:
        reasons.append(f"inlier fraction {inlier_fraction:.2f} < {cfg.min_inlier_fraction}")
        inflated = False
    if not np.all(np.isfinite(cov)):
        reasons.append("non-finite covariance")
        cov = _BIG_COV.copy()
        inflated = False
    quality = {
        "points_used": int(n_use),
        "points_source": ns,
        "points_target": nt,
        "inlier_fraction": inlier_fraction,
        "residual": res_rms,
        "residual_scale": kscale,
        "condition_number": cond,
        "iterations": int(iters),
        "converged": bool(converged),
        "degenerate": bool(degenerate),
        "sigma_weak": deg.sigma_weak,
        "weak_direction": [float(x) for x in deg.weakest],
        "weak_dims": int(deg.weak.sum()),
        "inflated": bool(inflated),  # flagged for degeneracy only: covariance inflated along the weak directions
        "reason": "; ".join(reasons),
        "ms": (time.perf_counter() - t0) * 1e3,
    }
    return MatchResult(pose, cov, not reasons, quality)


def scan_points(scan: Any, config: IcpConfig | None = None) -> NDArray[np.float64]:
    """Points of a :class:`graphnav.log.Scan` (eq. 10), missing returns dropped, range-gated by the
    config's ``max_range`` and the scan's own maximum (:attr:`graphnav.log.Scan.max_range`)."""
    cfg = config or IcpConfig()
    top = getattr(scan, "max_range", None)
    if cfg.max_range is not None:
        top = cfg.max_range if top is None else min(top, cfg.max_range)
    pts, _, _ = polar_to_points(scan.ranges, scan.angles, min_range=cfg.min_range, max_range=top)
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
