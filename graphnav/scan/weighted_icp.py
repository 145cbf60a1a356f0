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

from ..config import option
from ..errors import require
from ..geometry import cov_to_world, se2_between
from ..log import MAX_STATED_RANGE
from . import covariance, degeneracy
from .lidar import SIGMA_ALPHA, SIGMA_R_REL, polar_to_points

VARIANTS = ("K", "H", "HM", "HD", "HDL")
_BIG_COV = np.diag([1e4, 1e4, 10.0])  # returned with ok=False when there is nothing to match
_MIN_RES = 1e-9  # [m] floor of a point's resolution (a cloud on one bearing has none)
_CHI2_3_999 = 16.266  # chi-square, 3 degrees of freedom, 99.9 % (scipy.stats.chi2.ppf(0.999, 3))
# 1-sigma (x, y, yaw) of an initial guess that comes without a covariance: the stated sigma of the
# constant-velocity motion model (graphnav.scan.motion_guess.CV_BRIDGE_SIGMA, the same numbers)
GUESS_SIGMA = (1.0, 1.0, math.radians(10.0))


@dataclass
class IcpConfig:
    """Settings of :func:`match_points` / :func:`match_scans` (SI units, radians).

    Lengths that depend on the scan are in units of the target scan: its resolution ``r da`` at a
    point (:func:`graphnav.scan.covariance.resolution`, ``da`` the local angular step), the pair scale
    ``sqrt((r da)^2 + 2 M^2)`` (:func:`pair_scale`: how far apart a correct pair can be) and ``D``, the
    median pair scale (marina ~0.2 m, harbour ~0.5 m, the CARMEN logs ~0.02-0.12 m). No length here
    was fitted on one dataset (docs/weighted-icp.md, "Lengths relative to the scan").
    """

    variant: str = option("HDL", "the ICP variant: K, H, HM, HD or HDL (module docstring)")
    max_iter: int = option(50, "at most this many iterations")
    tol: float = option(5e-4, "stop when |change of mean pair distance| < tol D (Algorithm 1) ...")
    tol_step: float = option(0.015, "and stop only when the last increment moved no point more than tol_step D")
    huber_c: float = option(2.0138, "kHu = huber_c * median pair distance (Algorithm 1)")
    # the LiDAR's error model (eq. 5-8), a property of the sensor: the paper's Scanse Sweep figure and 0.2 deg
    sigma_r_rel: float = option(SIGMA_R_REL, "range 1-sigma per metre of range: sigma_r = sigma_r_rel * r (eq. 7; "
                                "the paper's Scanse Sweep: 0.004258)")
    sigma_alpha: float = option(SIGMA_ALPHA, "beam angle 1-sigma (eq. 6; the paper gives none)", unit="rad")
    max_range: float | None = option(None, "returns farther than this are dropped (None: none)", unit="m")
    min_range: float = option(0.0, "returns closer than this are dropped", unit="m")
    max_corr_dist: float | None = option(None, "pairs farther apart get weight 0 (None: no fixed gate)", unit="m")
    gate0: float = option(20.0,
        "HDL: Zhang's adaptive distance gate (Zhang 1994, sect. 4.3), initial value D_max^0 = gate0 resolutions; the "
        "pair distances are taken in units of the target's resolution at the match")
    line_max_gap: float = option(8.0, "beam neighbours more than this many resolutions apart are not one surface")
    line_flat_power: float = option(4.0, "HDL: weight x flatness^power of the target's local line (0..1)")
    line_warmup: float = option(1.0,
        "HDL: point-to-point steps until a step moves no point more than this x D (0: off)")
    matching: str = option("kdtree", "\"kdtree\" (cKDTree) or \"delaunay\" (the paper's nearest triangle apex)")
    equalize: bool = option(False, "randomly thin the larger cloud to the smaller's size (the paper)")
    seed: int = option(0, "for equalize")
    weight_power: float = option(0.5, "w = G^-weight_power; 0.5 is eq. 11")
    normal_k: int = option(12, "neighbours of a target point for its line normal (HDL, degeneracy check)")
    normals: str = option("knn", "HDL normals: \"knn\" (PCA of the k nearest) or \"scan\" (k neighbours in beam order)")
    min_points: int = option(20, "fewer valid points in either scan -> ok=False")
    min_inlier_fraction: float = option(0.3, "pairs within the final gate; below -> ok=False")
    max_condition: float = option(200.0, "condition number of the point-to-line information above -> degenerate")
    max_sigma: float = option(1.0, "covariance's 1-sigma along the weakest direction above this x D -> degenerate")
    workers: int = option(1, "cKDTree query threads")
    backend: str = option("auto", "\"auto\": the kernels compiled when numba (optional dependency) is importable, "
                          "else run as plain Python (the same code, slow); \"numba\": compiled or an error")

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown ICP variant {self.variant!r}; known: {', '.join(VARIANTS)}")
        if self.backend not in ("auto", "numba"):
            raise ValueError(f"unknown backend {self.backend!r}; known: auto, numba (one implementation: "
                             "\"auto\" runs the kernels as plain Python when numba is absent)")
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

    def own(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
        """The match's own estimate, its covariance and the projector onto the directions its geometry
        cannot see (``None``: none), before the guess replaced any direction the guess knew better
        (``quality["icp_pose"]``, ``["icp_cov"]``, ``["geometry_weak_projector"]``; the returned ones
        when the quality has none): what a fusion of the match with its guess by information takes."""
        q = self.quality
        if "icp_cov" not in q:
            weak = q.get("weak_projector")
            return self.pose, self.cov, None if weak is None else np.asarray(weak, dtype=float)
        weak = q.get("geometry_weak_projector")
        return (np.asarray(q["icp_pose"], dtype=float), np.asarray(q["icp_cov"], dtype=float),
                None if weak is None else np.asarray(weak, dtype=float))

    @property
    def cov_target(self) -> NDArray[np.float64]:
        """Covariance of additive errors of ``(dx, dy, dyaw)`` in the target frame (first order)."""
        return cov_to_world(float(self.pose[2]), self.cov)


# ----------------------------------------------------------------------------- small numerics


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
    """The 2D closed form of eq. 15-20 (the kernel's :func:`graphnav.scan._icp_fast.weighted_align`):
    ``(theta, T)`` with ``R(theta) p + T ~ q``."""
    p = np.ascontiguousarray(p, dtype=float)
    q = np.ascontiguousarray(q, dtype=float)
    w = np.ascontiguousarray(w, dtype=float)
    th, tx, ty = _kernels().weighted_align(p[:, 0].copy(), p[:, 1].copy(), q[:, 0].copy(), q[:, 1].copy(),
                                           np.arange(len(p)), w, len(p), float(w.sum()))
    return th, np.array([tx, ty])


def line_normals(pts: ArrayLike, k: int = 12) -> tuple[NDArray, NDArray]:
    """Unit normals (N, 2) of the local line through each point's ``k`` nearest neighbours (PCA), and a
    flatness in [0, 1] (1 = a perfect line): HDL's target lines (``normals="knn"``)."""
    f = _kernels()
    xy = np.ascontiguousarray(np.asarray(pts, dtype=float).reshape(-1, 2).T)
    nx, ny, flat = f.knn_line_normals(xy[0], xy[1], int(k), f.build_grid(xy[0], xy[1], _GRID_CELL))
    return np.column_stack([nx, ny]), flat


# ----------------------------------------------------------------------------- the matcher


def _pose_parts(init: ArrayLike | None) -> tuple[float, tuple[float, float]]:
    """``(dyaw, (dx, dy))`` of a guess ``(dx, dy, dyaw)`` (zeros without one)."""
    if init is None:
        return 0.0, (0.0, 0.0)
    x = np.asarray(init, dtype=float).ravel().tolist()
    if len(x) != 3 or not all(map(math.isfinite, x)):
        raise ValueError(f"init must be a finite (dx, dy, dyaw), got {init!r}")
    return x[2], (x[0], x[1])


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
    init_cov: ArrayLike | None = None,
) -> MatchResult:
    """Align ``src_xy`` (N, 2), the current scan's points in its sensor frame, to ``tgt_xy`` (M, 2),
    the previous scan's (Algorithm 1). ``init`` is the initial ``(dx, dy, dyaw)`` (e.g. the
    constant-velocity guess); a degenerate match takes it along its weak directions and inflates
    the covariance there (docs/weighted-icp.md). Points are taken in their sensor frame (the
    LiDAR error model needs the range and beam direction, eq. 5-9). ``src_sigma``/``tgt_sigma``
    (scalar or one per point, metres) replace that model by an isotropic 1-sigma per point (e.g. for
    points that are not raw LiDAR returns); by default the model of eq. 5-9 with the config's
    sigma_r_rel, sigma_alpha. ``init_cov`` (3, 3), the guess's own covariance in the same
    right-perturbation convention (e.g. the odometry increment's), makes the match answer for its
    distance from the guess: beyond the 99.9 % chi-square bound of both covariances it found
    another minimum, and it is flagged (``quality["guess_mahalanobis"]``).
    """
    cfg = config or IcpConfig()
    t0 = time.perf_counter()
    f = _kernels(cfg.backend)
    src_xy = np.asarray(src_xy, dtype=float).reshape(-1, 2)
    tgt_xy = np.asarray(tgt_xy, dtype=float).reshape(-1, 2)
    src_sigma = _per_point(src_sigma, len(src_xy), "src_sigma")
    tgt_sigma = _per_point(tgt_sigma, len(tgt_xy), "tgt_sigma")
    if not _KERNELS[2]:
        _load(f, src_xy, tgt_xy, cfg)
    if not f.bounded(src_xy, tgt_xy, MAX_STATED_RANGE):
        src_xy, src_sigma = _finite(src_xy, src_sigma)
        tgt_xy, tgt_sigma = _finite(tgt_xy, tgt_sigma)
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
    out = f.match_xy(src_xy, tgt_xy, _NO_SIGMA if src_sigma is None else src_sigma,
                     _NO_SIGMA if tgt_sigma is None else tgt_sigma, _params(cfg), (th0, g0[0], g0[1]),
                     _triangulation(tgt_xy) if cfg.matching == "delaunay" else _NO_TRI)
    return _report(cfg, out, t0, ns, nt, init, init_cov)


_VARIANT_CODE = {"K": 0, "H": 1, "HM": 2, "HD": 3, "HDL": 4}
_GRID_CELL = 1.0  # [m] cell of the nearest-neighbour grids (exact at any size; 1 m: fastest on the marina)
_NO_SIGMA = np.zeros(0)
_NO_TRI = (np.zeros((0, 3, 2)), np.zeros((0, 3), np.int64), np.zeros((0, 3), np.int64))


def _finite(xy: NDArray, sigma: NDArray | None) -> tuple[NDArray, NDArray | None]:
    """Rows of ``xy`` (and ``sigma``) with finite coordinates within
    :data:`graphnav.log.MAX_STATED_RANGE` of the sensor on each axis (no copy when all are): a
    point farther away is no LiDAR return, and bounding them bounds the matcher's grid and work."""
    if len(xy) == 0 or np.abs(xy).max() <= MAX_STATED_RANGE:  # (NaN: False)
        return xy, sigma
    with np.errstate(invalid="ignore"):
        keep = (np.abs(xy) <= MAX_STATED_RANGE).all(axis=1)  # False for NaN
    return xy[keep], None if sigma is None else sigma[keep]



def _kernels(backend: str = "auto") -> Any:
    """The kernel module :mod:`graphnav.scan._icp_fast` (compiled when numba is importable, else plain
    Python); ``backend="numba"`` insists on the compiled one."""
    if not _KERNELS:
        from . import _icp_fast
        from ._jit import HAVE_NUMBA

        _KERNELS.extend([_icp_fast, HAVE_NUMBA, False])
    if backend == "numba" and not _KERNELS[1]:
        require("numba", 'ICP backend "numba"')
    return _KERNELS[0]


_KERNELS: list[Any] = []  # [the kernel module, numba importable, _load done], after the first call


def _load(f: Any, src_xy: NDArray, tgt_xy: NDArray, cfg: IcpConfig) -> None:
    """The first match: the two kernels it calls loaded from numba's cache for the arguments a match passes them
    (:func:`graphnav.scan._jit.load_cached`: without numba's target-context refresh, 0.1 s CPU a process)."""
    from ._jit import load_cached

    _KERNELS[2] = True
    load_cached(f.bounded, (src_xy, tgt_xy, MAX_STATED_RANGE))
    load_cached(f.match_xy, (src_xy, tgt_xy, _NO_SIGMA, _NO_SIGMA, _params(cfg), (0.0, 0.0, 0.0), _NO_TRI))


def _params(cfg: IcpConfig) -> Any:
    """The kernels' :class:`graphnav.scan._icp_fast.Params` of a config (made once per distinct settings)."""
    key = tuple(vars(cfg).values())
    try:
        got = _PARAMS.get(key)
    except TypeError:  # (an unhashable value set on the config)
        return _make_params(cfg)
    if got is None:
        if len(_PARAMS) >= 64:
            _PARAMS.clear()
        got = _PARAMS[key] = _make_params(cfg)
    return got


_PARAMS: dict[tuple, Any] = {}  # the Params of the settings seen (keyed by the config's values)


def _make_params(cfg: IcpConfig) -> Any:
    """:func:`_params`, made."""
    from ._icp_fast import Params

    return Params(_VARIANT_CODE[cfg.variant], float(cfg.huber_c), float(cfg.weight_power),
                  np.inf if cfg.max_corr_dist is None else float(cfg.max_corr_dist), float(cfg.tol),
                  float(cfg.tol_step), int(cfg.max_iter), _GRID_CELL, int(cfg.normal_k), cfg.normals == "knn",
                  float(cfg.line_max_gap), float(cfg.line_flat_power), float(cfg.line_warmup), float(cfg.gate0),
                  _MIN_RES, float(cfg.sigma_alpha), float(cfg.sigma_r_rel), cfg.matching == "delaunay",
                  float(covariance.SAMPLING_VARIANCE), float(cfg.max_condition), float(cfg.max_sigma))


def _triangulation(tgt_xy: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """The target's Delaunay triangulation as the kernel walks it: scipy's barycentric transforms,
    neighbours and vertices."""
    from scipy.spatial import Delaunay

    tri = Delaunay(tgt_xy)
    return (np.ascontiguousarray(tri.transform), tri.neighbors.astype(np.int64), tri.simplices.astype(np.int64))


def _report(cfg: IcpConfig, out: tuple, t0: float, ns: int, nt: int, init: ArrayLike | None,
            init_cov: ArrayLike | None) -> MatchResult:
    """Covariance and degeneracy (:func:`graphnav.scan.covariance.from_kernel`: the kernel's evaluation of
    :func:`~graphnav.scan.covariance.from_sums` on its one-pass sums),
    the flags, the weak directions taken from ``init``, and the quality report.

    Residuals and their Jacobians with respect to ``xi``, the right perturbation ``pose ∘ Exp(xi)``
    (GTSAM's Pose2 tangent space): ``d(R p_s + t)/d xi = R [I, J p_s] = [R, J (p - t)]``, ``J = [[0, -1],
    [1, 0]]``; HDL: the point-to-line residual ``n . (p - q)``, its row ``n^T [R, J (p - t)]``.
    """
    pose, ((th, tx, ty), iters, converged, gate, moved, src_range, radius, sums, algebra) = out
    k, n_inl, _, _, _, rms, _, inlier_fraction, points_used, big_d = sums
    finite, geo_weak, weakest = algebra[6:]  # the covariance is finite; the geometry's weak directions, weakest
    bt = covariance.from_kernel(k, n_inl, rms, radius, algebra, prior_cov=None if init is None else init_cov)
    deg = bt.degeneracy
    # the geometry's own weak directions (without the guess's "known better" rule): what a fusion of the
    # match with its guess by information may not hear from the match
    geo = bt.geometry
    n_weak = geo_weak if deg is geo else int(deg.weak.sum())
    degenerate = n_weak > 0
    failed, maha = _failures(cfg, pose, bt, finite, iters, converged, moved, src_range, inlier_fraction, radius,
                             init, init_cov)
    cov, reasons = bt.cov, []
    if degenerate:
        why = []
        if not np.isfinite(deg.condition) or deg.condition > cfg.max_condition:
            why.append(f"condition number {deg.condition:.3g} > {cfg.max_condition:g}")
        if deg.sigma_weak > cfg.max_sigma * big_d:
            why.append(f"weakest-direction 1-sigma {deg.sigma_weak:.3g} m > {cfg.max_sigma:g} x {big_d:.3g} m")
        reasons.append(f"degenerate geometry ({', '.join(why) or 'no residual scale'})")
        pose, cov = _weak_from_guess(pose, cov, deg, None if failed else init, init_cov)
    reasons += failed
    if failed:
        cov = _BIG_COV.copy()
        if init is not None:
            th0, g0 = _pose_parts(init)
            pose = np.array([g0[0], g0[1], th0])
    quality = {
        "points_used": int(points_used), "points_source": ns, "points_target": nt,
        "inlier_fraction": float(inlier_fraction), "residual": bt.residual_rms, "residual_scale": bt.residual_scale,
        "resolution": float(big_d), "gate": float(gate), "condition_number": deg.condition,
        "iterations": int(iters), "converged": bool(converged), "degenerate": degenerate,
        "sigma_weak": deg.sigma_weak, "weak_direction": list(weakest),
        "weak_dims": n_weak,
        "weak_projector": deg.projector().tolist() if degenerate else None,  # P: the weak directions' part of xi
        "inflated": degenerate and not failed,  # flagged for degeneracy only: covariance inflated there
        "icp_pose": [tx, ty, th],
        "icp_cov": bt.cov.tolist(),  # the covariance of icp_pose (before any weak direction took the guess's)
        "geometry_weak_projector": geo.projector().tolist() if geo_weak else None,  # weak by geometry alone
        "guess_mahalanobis": maha,  # the estimate before a flag replaced any of it by the guess
        "reason": "; ".join(reasons),
        "ms": (time.perf_counter() - t0) * 1e3,
    }
    return MatchResult(pose, cov, not reasons, quality)


def _failures(cfg: IcpConfig, pose: NDArray, bt: Any, finite: bool, iters: int, converged: bool, moved: float,
              src_range: float, inlier_fraction: float, radius: float, init: ArrayLike | None,
              init_cov: ArrayLike | None) -> tuple[list[str], float]:
    """Why the match as a whole is not to be trusted (then the pose is the guess, when there is one), and
    its Mahalanobis distance from the guess (with ``init_cov``); ``finite``: whether ``bt.cov`` is."""
    cov, deg = bt.cov, bt.degeneracy
    failed = []
    if not converged:  # a limit cycle within the estimate's own 1-sigma is as good as converged
        sig = np.sqrt(np.maximum(cov[0, 0] + cov[1, 1], 0.0)) + src_range * np.sqrt(np.maximum(cov[2, 2], 0.0))
        if not moved <= sig:
            failed.append(f"not converged in {iters} iterations (last step {moved:.3g} m > its 1-sigma {sig:.3g} m)")
    if inlier_fraction < cfg.min_inlier_fraction:
        failed.append(f"inlier fraction {inlier_fraction:.2f} < {cfg.min_inlier_fraction}")
    if not finite:
        failed.append("non-finite covariance")
    maha = float("nan")
    if init is not None and init_cov is not None and not failed:
        th0, g0 = _pose_parts(init)
        xi = se2_between(pose, np.array([g0[0], g0[1], th0]))
        both = cov + np.asarray(init_cov, dtype=float) + (deg.inflation(radius) if deg.degenerate else 0.0)
        try:
            maha = float(xi @ np.linalg.solve(both, xi))
        except np.linalg.LinAlgError:
            maha = float("inf")
        if not maha <= _CHI2_3_999:
            failed.append(f"inconsistent with the guess (Mahalanobis {maha:.3g} > {_CHI2_3_999:.2f})")
    return failed, maha


def _weak_from_guess(pose: NDArray, cov: NDArray, deg: Any, init: ArrayLike | None,
                     init_cov: ArrayLike | None) -> tuple[NDArray, NDArray]:
    """A degenerate match: along the weak directions the pose is the guess's (``init``; None: no guess or a
    failed match), and so is its error: the covariance there is the guess's (``init_cov``; without one the
    constant-velocity model's stated sigma, :data:`GUESS_SIGMA`). Without a guess only inflate."""
    g = np.diag(np.square(GUESS_SIGMA)) if init_cov is None else np.asarray(init_cov, dtype=float)
    proj = deg.projector()
    if init is not None:
        th0, g0 = _pose_parts(init)
        pose = degeneracy.keep_constrained(pose, np.array([g0[0], g0[1], th0]), deg)
        if np.all(np.isfinite(cov)):
            keep = np.eye(3) - proj
            cov = keep @ cov @ keep.T + proj @ g @ proj.T
    elif np.all(np.isfinite(cov)):  # no guess: the estimate is all there is, only inflate
        cov = cov + proj @ g @ proj.T
    return pose, cov


def scan_points(scan: Any, config: IcpConfig | None = None, *, sweep_s: float = 0.0,
                twist: ArrayLike | None = None) -> NDArray[np.float64]:
    """Points of a :class:`graphnav.log.Scan` (eq. 10), missing returns dropped, range-gated by the
    config's ``max_range`` and the scan's own maximum (:attr:`graphnav.log.Scan.max_range`). With a
    ``sweep_s`` and the body's ``twist`` (vx, vy, wz) the points are de-skewed to the scan's stamp (its
    first beam; :mod:`graphnav.scan.deskew`)."""
    cfg = config or IcpConfig()
    top = getattr(scan, "max_range", None)
    if cfg.max_range is not None:
        top = cfg.max_range if top is None else min(top, cfg.max_range)
    pts, _, _ = polar_to_points(scan.ranges, scan.angles, min_range=cfg.min_range, max_range=top)
    if sweep_s and twist is not None:
        from .deskew import deskew_mask_points
        from .lidar import valid_returns

        keep = valid_returns(scan.ranges, scan.angles, min_range=cfg.min_range, max_range=top)
        pts = deskew_mask_points(pts, keep, sweep_s, twist)
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
