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

from ..config import option
from ..errors import require
from ..geometry import cov_to_world, se2_between, wrap_angle
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
    backend: str = option("auto", "\"numba\": the compiled loop (optional dependency; the numpy loop's results to "
                          "~1e-12), \"numpy\", or \"auto\": numba when importable, else numpy")

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
        return cov_to_world(float(self.pose[2]), self.cov)


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
        return _match_compiled(fast, cfg, src_xy, tgt_xy, src_sigma, tgt_sigma, init, t0, ns, nt, init_cov)

    src, tgt = _Cloud(src_xy, cfg, src_sigma), _Cloud(tgt_xy, cfg, tgt_sigma)
    nnm = _NearestNeighbours(tgt.xy, cfg)
    p2l = cfg.variant == "HDL"
    if p2l:
        normals, flat = _target_lines(tgt.xy, cfg, nnm.tree)
    else:  # the degeneracy check needs the target's local lines
        normals, flat = scan_order_normals(tgt.xy, cfg.normal_k // 2, cfg.line_max_gap)

    th, t = _pose_parts(init)
    old_res = None
    converged = False
    it = 0
    moved = np.inf
    src_r = src.r.max()
    idx = np.zeros(0, dtype=int)
    res_t = covariance.resolution(tgt.xy, cfg.normal_k // 2)
    scale = pair_scale(res_t, tgt.m2)
    big_d = float(np.median(scale))
    dmax = cfg.gate0
    # HDL: point-to-point (HD) steps while far from the solution; point-to-line has a narrow basin
    warm = p2l and cfg.line_warmup > 0
    for it in range(1, cfg.max_iter + 1):  # noqa: B007
        r = _rot(th)
        p = src.xy @ r.T + t
        d, idx = nnm.match(p)
        q = tgt.xy[idx]
        u = d / scale[idx]
        dmax = zhang_gate(u, dmax)
        w, _ = _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat, p2p=warm, gate=u <= dmax)
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
            warm = moved > cfg.line_warmup * big_d
            old_res = None
            continue
        if old_res is not None and abs(new_res - old_res) < cfg.tol * big_d and moved < cfg.tol_step * big_d:
            converged = True
            break
        old_res = new_res

    pose = np.array([t[0], t[1], th])
    return _finish(cfg, src, tgt, idx, pose, normals, flat, res_t, scale, dmax, moved, it, converged, t0, ns, nt,
                   init, init_cov)


def pair_scale(res: NDArray, m2: NDArray) -> NDArray:
    """The distance a correct pair can have at each target point, ``sqrt(res^2 + 2 M^2)``: the
    scan's resolution there (:func:`graphnav.scan.covariance.resolution`) and the mean error of
    both points (eq. 5, the target's for both), floored at a nanometre. The unit of
    :func:`zhang_gate`'s distances; its median ``D`` is that of the matcher's tolerances."""
    return np.maximum(np.sqrt(res**2 + 2.0 * m2), _MIN_RES)


def zhang_gate(u: NDArray, dmax: float) -> float:
    """Zhang's adaptive distance gate (Z. Zhang, *Iterative point matching for registration of
    free-form curves and surfaces*, IJCV 13(2), 1994, sect. 4.3; the weighted-ICP paper's ref. [14]),
    with the distances ``u`` in units of the data's resolution (his ``D``; here the distance a correct
    pair can have at each match, :func:`pair_scale`): from the mean ``mu`` and
    standard deviation ``sd`` of the distances within the previous gate ``dmax``, the next gate is
    ``mu + 3 sd`` when ``mu < 1`` (registered), ``mu + 2 sd`` when ``mu < 3``, ``mu + sd`` when
    ``mu < 6``, else the median (Zhang: the valley of the histogram). Fewer than 3 pairs: unchanged."""
    sel = u[u <= dmax]
    if len(sel) < 3:
        return dmax
    mu = float(sel.mean())
    sd = float(np.sqrt(np.mean((sel - mu) ** 2)))
    if mu < 1.0:
        return mu + 3.0 * sd
    if mu < 3.0:
        return mu + 2.0 * sd
    if mu < 6.0:
        return mu + sd
    return _median(sel)


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
            from ._icp_fast import hdl_match, p2p_match, report_sums
        except ImportError as exc:
            _COMPILED.append(exc)
        else:
            _COMPILED.append((p2p_match, hdl_match, report_sums))
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
                    tgt_sigma: NDArray | None, init: ArrayLike | None, t0: float, ns: int, nt: int,
                    init_cov: ArrayLike | None = None) -> MatchResult:
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
                     cfg.line_flat_power, cfg.line_warmup, cfg.gate0, _MIN_RES)
    else:
        out = kernel(*clouds, _VARIANT_CODE[cfg.variant], cfg.huber_c, cfg.weight_power, big, cfg.tol,
                     cfg.tol_step, cfg.max_iter, th0, g[0], g[1], _GRID_CELL, cfg.normal_k // 2,
                     cfg.line_max_gap, cfg.gate0, _MIN_RES)
    th, tx, ty, it, converged, idx, px, py, w, sxx, sxy, syy, nrx, nry, fl, res_t, sc, dmax, radius, moved, src_r = out
    pose = np.array([tx, ty, th])
    final = _FinalPairs(np.column_stack([px, py]), tgt_xy[idx], w, np.column_stack([sxx, sxy, syy]),
                        np.column_stack([nrx[idx], nry[idx]]), fl[idx], res_t[idx], sc[idx], dmax, radius, moved,
                        src_r)
    c, s_ = math.cos(wrap_angle(th)), math.sin(wrap_angle(th))
    sums = _compiled()[2](px, py, final.q[:, 0].copy(), final.q[:, 1].copy(), w, sxx, sxy, syy, final.n[:, 0].copy(),
                           final.n[:, 1].copy(), final.flat, final.res, final.scale, dmax, tx, ty, c, s_, radius,
                           cfg.variant == "HDL", cfg.normal_k, covariance.SAMPLING_VARIANCE)
    return _report(cfg, pose, final, it, converged, t0, ns, nt, init, init_cov, sums)


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


def scan_order_normals(pts: NDArray, half: int = 2, max_gap: float = 8.0) -> tuple[NDArray, NDArray]:
    """Normals and flatness of each point from its ``2 half + 1`` neighbours in beam order
    (sorted by bearing; no neighbour search), by PCA. A window with a gap between beam neighbours
    wider than ``max_gap`` resolutions (``r da``, the smaller of the two,
    :func:`graphnav.scan.covariance.resolution`) spans two surfaces: its flatness is 0. (A surface
    seen at incidence ``i`` has gaps of ``r da / cos i``: 8 resolutions is ``i`` > 83 deg.)"""
    n = len(pts)
    order = np.argsort(np.arctan2(pts[:, 1], pts[:, 0]), kind="stable")
    ps = pts[order]
    win = (np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :]) % n
    nrm, flat = _pca_normals(ps[win])
    gap = np.hypot(*(np.roll(ps, -1, axis=0) - ps).T)  # gap[i]: between sorted points i and i+1
    res = covariance.resolution(pts, half)[order]
    near = np.minimum(res, np.roll(res, -1))
    wide = (gap[win[:, :-1]] > max_gap * near[win[:, :-1]]).any(axis=1)
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


def _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat, p2p=False, gate=None):  # noqa: ANN001, ANN202
    """Pair weights of Algorithm 1 (eq. 11-13 x Huber) and the pair variances they come from
    (``p2p``: HD weights during HDL's point-to-point warm-up). HDL: 0 outside the ``gate`` (mask,
    :func:`zhang_gate`) and x the line's flatness."""
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
        if v == "HDL":
            w = w * flat[idx] ** cfg.line_flat_power
    if cfg.variant == "HDL" and gate is not None:  # warm-up steps too
        w = np.where(gate, w, 0.0)
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


@dataclass
class _FinalPairs:
    """The pairs at the solution, as both matcher paths give them to :func:`_report`."""

    p: NDArray  # (N, 2) source points moved by the pose (target frame)
    q: NDArray  # (N, 2) their matched target points
    w: NDArray  # (N,) the matcher's weights
    s: NDArray  # (N, 3) eq. 8 pair covariance (sxx, sxy, syy)
    n: NDArray  # (N, 2) target normal at the match (HDL: its lines; else beam-order normals)
    flat: NDArray  # (N,) flatness of that line
    res: NDArray  # (N,) the target's resolution at the match [m]
    scale: NDArray  # (N,) the distance a correct pair can have there (pair_scale) [m]
    gate: float  # the final gate [scales]
    radius: float  # the source's RMS radius [m]
    moved: float  # the last step's largest point displacement [m]
    src_range: float  # the source's largest range [m]


def _finish(cfg, src, tgt, idx, pose, normals, flat, res_t, scale, dmax, moved, iters, converged, t0, ns, nt,  # noqa: ANN001, ANN202, PLR0913
            init=None, init_cov=None):
    """The numpy loop's final pairs (as the compiled matcher's), then :func:`_report`."""
    r = _rot(pose[2])
    p = src.xy @ r.T + pose[:2]
    q = tgt.xy[idx]  # the last iteration's pairs (the last increment moved no point > tol_step)
    e = p - q
    d = np.hypot(e[:, 0], e[:, 1])
    w, _ = _weights(cfg, src, tgt, r, p, q, d, idx, normals, flat, gate=d / scale[idx] <= dmax)
    if cfg.variant in ("HM", "HD", "HDL"):
        s = np.column_stack(_pair_cov(src, tgt, idx, r))
    else:
        s = np.column_stack([np.ones(len(d)), np.zeros(len(d)), np.ones(len(d))])
    final = _FinalPairs(p, q, w, s, normals[idx], flat[idx], res_t[idx], scale[idx], dmax,
                        degeneracy.rms_radius(src.xy), float(moved), float(src.r.max()))
    return _report(cfg, pose, final, iters, converged, t0, ns, nt, init, init_cov)


def _report(cfg, pose, fp, iters, converged, t0, ns, nt, init, init_cov=None, sums=None):  # noqa: ANN001, ANN202, PLR0913
    """Covariance and degeneracy (:func:`graphnav.scan.covariance.between`, the one place), the weak
    directions take ``init``'s pose, and the quality report. Shared by both matcher paths; the
    compiled one hands over its one-pass ``sums`` (:func:`graphnav.scan._icp_fast.report_sums`, the
    same quantities: :func:`graphnav.scan.covariance.from_sums`).

    Residuals and their Jacobians with respect to ``xi``, the right perturbation ``pose ∘ Exp(xi)``
    (GTSAM's Pose2 tangent space): ``d(R p_s + t)/d xi = R [I, J p_s] = [R, J (p - t)]``, ``J = [[0, -1],
    [1, 0]]``; HDL: the point-to-line residual ``n . (p - q)``, its row ``n^T [R, J (p - t)]``.
    """
    pose[2] = wrap_angle(float(pose[2]))
    c, s_ = np.cos(pose[2]), np.sin(pose[2])
    if sums is None:
        e = fp.p - fp.q
        d = np.hypot(e[:, 0], e[:, 1])
        jp = fp.p - pose[:2]
        c2 = np.column_stack([-jp[:, 1], jp[:, 0]])  # J (p - t) = R J p_s
        n = fp.n
        rows = np.column_stack([n[:, 0] * c + n[:, 1] * s_, -n[:, 0] * s_ + n[:, 1] * c, np.einsum("ij,ij->i", n, c2)])
        inl = d / fp.scale <= fp.gate
        use = fp.w > 0
        sxx, sxy, syy = fp.s.T
        if cfg.variant == "HDL":
            jac = rows[:, None, :]
            res = np.einsum("ij,ij->i", e, n)[:, None]
            lidar = (sxx * n[:, 0] ** 2 + 2 * sxy * n[:, 0] * n[:, 1] + syy * n[:, 1] ** 2)[:, None, None]
        else:
            jac = np.empty((len(d), 2, 3))
            jac[:, 0, :2] = (c, -s_)
            jac[:, 1, :2] = (s_, c)
            jac[:, :, 2] = c2
            res = e
            lidar = np.empty((len(d), 2, 2))
            lidar[:, 0, 0], lidar[:, 0, 1], lidar[:, 1, 0], lidar[:, 1, 1] = sxx, sxy, sxy, syy
        scaled = rows * np.array([1.0, 1.0, 1.0 / fp.radius])
        big_d = float(np.median(fp.scale)) if len(fp.scale) else float("nan")
        bt = covariance.between(jac, res, fp.w, lidar, fp.res, use & inl, scaled, fp.flat, fp.radius,
                                block=cfg.normal_k, max_condition=cfg.max_condition, max_sigma=cfg.max_sigma * big_d,
                                prior_cov=None if init is None else init_cov)
        inlier_fraction = float(inl.mean())
        points_used = int(use.sum())
    else:
        k, n_inl, h, b_lidar, b_samp, rms, info, inlier_fraction, points_used, big_d = sums
        bt = covariance.from_sums(k, n_inl, h, b_lidar, b_samp, rms, info, fp.radius, max_condition=cfg.max_condition,
                                  max_sigma=cfg.max_sigma * big_d, prior_cov=None if init is None else init_cov)
    cov = bt.cov
    deg = bt.degeneracy
    cond = deg.condition
    degenerate = deg.degenerate
    icp_pose = pose.copy()
    reasons = []
    failed = []  # the match as a whole is not to be trusted: the pose is the guess (when there is one)
    if not converged:  # a limit cycle within the estimate's own 1-sigma is as good as converged
        sig = np.sqrt(np.maximum(cov[0, 0] + cov[1, 1], 0.0)) + fp.src_range * np.sqrt(np.maximum(cov[2, 2], 0.0))
        if not fp.moved <= sig:
            failed.append(f"not converged in {iters} iterations (last step {fp.moved:.3g} m > its 1-sigma {sig:.3g} m)")
    if inlier_fraction < cfg.min_inlier_fraction:
        failed.append(f"inlier fraction {inlier_fraction:.2f} < {cfg.min_inlier_fraction}")
    if not np.all(np.isfinite(cov)):
        failed.append("non-finite covariance")
    maha = float("nan")
    if init is not None and init_cov is not None and not failed:
        th0, t0_ = _pose_parts(init)
        xi = se2_between(pose, np.array([t0_[0], t0_[1], th0]))
        both = cov + np.asarray(init_cov, dtype=float) + (deg.inflation(fp.radius) if degenerate else 0.0)
        try:
            maha = float(xi @ np.linalg.solve(both, xi))
        except np.linalg.LinAlgError:
            maha = float("inf")
        if not maha <= _CHI2_3_999:
            failed.append(f"inconsistent with the guess (Mahalanobis {maha:.3g} > {_CHI2_3_999:.2f})")
    if degenerate:
        why = []
        if not np.isfinite(cond) or cond > cfg.max_condition:
            why.append(f"condition number {cond:.3g} > {cfg.max_condition:g}")
        if deg.sigma_weak > cfg.max_sigma * big_d:
            why.append(f"weakest-direction 1-sigma {deg.sigma_weak:.3g} m > {cfg.max_sigma:g} x {big_d:.3g} m")
        reasons.append(f"degenerate geometry ({', '.join(why) or 'no residual scale'})")
        # along the weak directions the pose is the guess's, and so is its error: the covariance there
        # is the guess's (init_cov; without one the constant-velocity model's stated sigma, GUESS_SIGMA)
        g = np.diag(np.square(GUESS_SIGMA)) if init_cov is None else np.asarray(init_cov, dtype=float)
        proj = deg.projector()
        if init is not None and not failed:
            th0, t0_ = _pose_parts(init)
            pose = degeneracy.keep_constrained(pose, np.array([t0_[0], t0_[1], th0]), deg)
            if np.all(np.isfinite(cov)):
                keep = np.eye(3) - proj
                cov = keep @ cov @ keep.T + proj @ g @ proj.T
        elif np.all(np.isfinite(cov)):  # no guess: the estimate is all there is, only inflate
            cov = cov + proj @ g @ proj.T
    inflated = degenerate and not failed
    reasons += failed
    if failed:
        cov = _BIG_COV.copy()
        if init is not None:
            th0, t0_ = _pose_parts(init)
            pose = np.array([t0_[0], t0_[1], th0])
    quality = {
        "points_used": int(points_used),
        "points_source": ns,
        "points_target": nt,
        "inlier_fraction": inlier_fraction,
        "residual": bt.residual_rms,
        "residual_scale": bt.residual_scale,
        "resolution": big_d,
        "gate": float(fp.gate),
        "condition_number": cond,
        "iterations": int(iters),
        "converged": bool(converged),
        "degenerate": bool(degenerate),
        "sigma_weak": deg.sigma_weak,
        "weak_direction": [float(x) for x in deg.weakest],
        "weak_dims": int(deg.weak.sum()),
        "weak_projector": deg.projector().tolist() if degenerate else None,  # P: the weak directions' part of xi
        "inflated": bool(inflated),  # flagged for degeneracy only: covariance inflated along the weak directions
        "icp_pose": [float(x) for x in icp_pose],
        "guess_mahalanobis": maha,  # the estimate before a flag replaced any of it by the guess
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
