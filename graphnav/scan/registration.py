"""Thin wrappers over small_gicp and open3d for registering 2D LiDAR scans, constrained to SE(2).

2D points are embedded in 3D at z = 0. Methods (``METHODS``):

* ``small_gicp:GICP``, ``small_gicp:VGICP`` — the FastGICP/FastVGICP family that the
  scan-matching comparison (Wang et al. 2023, Table 2) found best for continuous frames;
  ``small_gicp:ICP`` and ``small_gicp:PLANE_ICP`` for completeness.
* ``open3d:point_to_point``, ``open3d:point_to_plane``, ``open3d:gicp``.

A scan lies in one plane, so 3D local features are degenerate: the plane's own normal (z) is as
thin as a wall's. To give the libraries the 2D structure (the line a wall traces), each point is
extruded into a short vertical "curtain" (copies at ``z = ±curtain`` m) for small_gicp, whose
covariance estimation then sees a vertical plane per wall and its plane-to-plane GICP becomes
2D line-to-line; for open3d the in-plane normals / covariances are computed here from 2D PCA.

``planar="constrain"`` (default) keeps the solver in SE(2): for small_gicp a Gauss-Newton loop on
the library's own 6x6 Hessian/gradient restricted to (yaw, x, y) (the rows/columns of
``T ⊕ exp(δ)`` with δ = (ω, v) in small_gicp's order); for open3d the pose is re-projected onto
SE(2) after every single library iteration. ``planar="project"`` runs the unconstrained 6-DoF
solve and projects the 4x4 once (yaw + x, y).

The registration RMSE is the paper's eq. 7: sqrt(mean ||R p + t - q||^2) over source points whose
nearest target point ``q`` lies within the correspondence distance; ``fitness`` is that fraction.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import FRACTION, KNN, POSITIVE, THREADS, Range, check_fields
from ..errors import require
from ..geometry import wrap_angle
from ..log import DEFAULT_MAX_RANGE
from ._kdtree import cKDTree
from .lidar import polar_to_points

METHODS = (
    "small_gicp:VGICP",
    "small_gicp:GICP",
    "small_gicp:ICP",
    "small_gicp:PLANE_ICP",
    "open3d:point_to_point",
    "open3d:point_to_plane",
    "open3d:gicp",
)
DEFAULT_METHOD = "small_gicp:VGICP"
_ALIASES = {
    "vgicp": "small_gicp:VGICP", "gicp": "small_gicp:GICP", "icp": "small_gicp:ICP",
    "plane_icp": "small_gicp:PLANE_ICP", "point_to_point": "open3d:point_to_point",
    "point_to_plane": "open3d:point_to_plane", "o3d_gicp": "open3d:gicp",
}


def resolve_method(method: str) -> str:
    """Canonical ``backend:method`` name (accepts the short aliases, case-insensitive)."""
    m = _ALIASES.get(method.lower(), method)
    for full in METHODS:
        if full.lower() == m.lower():
            return full
    raise ValueError(f"unknown registration method {method!r}; known: {', '.join(METHODS)} "
                     f"(aliases: {', '.join(_ALIASES)})")


@dataclass(frozen=True)
class Params:
    """Registration settings (metres, radians).

    ``max_corr`` correspondence distance; ``voxel`` VGICP voxel size; ``neighbors`` for local
    covariances/normals (open3d: within ``normal_radius``, and a normal only where the smaller
    eigenvalue is below ``planarity`` times the larger: a line, not a corner); ``curtain``
    half-height of the vertical extrusion (small_gicp);
    ``max_iter`` iterations; ``eps_*`` convergence thresholds of the SE(2) update.
    """

    max_corr: float = 2.0
    voxel: float = 1.0
    neighbors: int = 10
    normal_radius: float = 2.0
    planarity: float = 0.3
    curtain: float = 0.3
    max_iter: int = 30
    eps_trans: float = 1e-3
    eps_rot: float = 1e-4
    planar: str = "constrain"
    threads: int = 1

    def __post_init__(self) -> None:
        check_fields(self, {"max_corr": Range(lo=0.0, hi=1e4, lo_open=True), "voxel": Range(lo=1e-3, hi=1e3),
                            "neighbors": KNN, "normal_radius": Range(lo=0.0, hi=1e4, lo_open=True),
                            "planarity": FRACTION, "curtain": Range(lo=0.0, hi=1e3, lo_open=True),
                            "max_iter": Range(lo=1, hi=100_000, integer=True), "eps_trans": POSITIVE,
                            "eps_rot": POSITIVE, "threads": THREADS}, "option")


@dataclass
class Aligned:
    """Result of one registration: ``pose`` (x, y, yaw) of the source in the target frame,
    ``rmse`` [m] (eq. 7) and ``fitness`` (inlier fraction) at that pose, ``ms`` solve time,
    ``iterations``, ``converged``; ``hessian`` 3x3 in (x, y, yaw) when the backend gives one."""

    pose: NDArray[np.float64]
    rmse: float
    fitness: float
    ms: float
    iterations: int
    converged: bool
    hessian: NDArray[np.float64] | None = None


# -- geometry helpers -----------------------------------------------------------------------------
def scan_points(ranges: ArrayLike, angles: ArrayLike, *, min_range: float = 0.0,
                max_range: float = DEFAULT_MAX_RANGE) -> NDArray[np.float64]:
    """Polar scan -> (N, 2) body-frame points; missing returns (NaN, inf, <= 0, beyond
    ``max_range``) dropped (:func:`graphnav.scan.lidar.polar_to_points`, the one conversion)."""
    return polar_to_points(ranges, angles, min_range=min_range, max_range=max_range)[0]


def transform2(pose: ArrayLike, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points of a frame at ``pose`` expressed in the parent frame."""
    x, y, th = np.asarray(pose, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return xy @ np.array([[c, s], [-s, c]]) + np.array([x, y])


_SE2 = np.array([3, 4, 2])  # (v_x, v_y, ω_z) of small_gicp's (ω_xyz, v_xyz)
_SE2_IX = np.ix_(_SE2, _SE2)
_EPS_I3 = 1e-9 * np.eye(3)


def pose_to_matrix4(pose: ArrayLike) -> NDArray[np.float64]:
    x, y, th = (float(v) for v in pose)
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def matrix4_to_pose(m: ArrayLike) -> NDArray[np.float64]:
    """Project a 4x4 rigid transform onto SE(2): yaw of the rotated x axis, and x, y."""
    m = np.asarray(m, dtype=float)
    return np.array([m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])])


def se2_exp(d: ArrayLike) -> NDArray[np.float64]:
    """SE(2) exponential of the twist (v_x, v_y, ω) as a pose (x, y, yaw)."""
    return np.array(_se2_exp(*(float(v) for v in d)))


def _se2_exp(vx: float, vy: float, w: float) -> tuple[float, float, float]:
    if abs(w) < 1e-4:  # series: (1 - cos w) / w cancels catastrophically for small w
        a, b = 1.0 - w * w / 6.0, 0.5 * w * (1.0 - w * w / 12.0)
    else:
        s, c = math.sin(w), math.cos(w)
        a, b = s / w, (1.0 - c) / w
    return a * vx - b * vy, b * vx + a * vy, w


def compose(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    ax, ay, ath = (float(v) for v in a)
    bx, by, bth = (float(v) for v in b)
    c, s = math.cos(ath), math.sin(ath)
    return np.array([ax + c * bx - s * by, ay + s * bx + c * by, wrap_angle(ath + bth)])


def local_frames_2d(xy: NDArray[np.float64], k: int, radius: float = np.inf
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """In-plane unit normals (N, 2) and ascending eigenvalues (N, 2) of the covariance of each
    point's ``k`` nearest neighbours within ``radius`` (a neighbourhood must not reach round a
    corner onto the next wall). Points with fewer than 3 such neighbours get eigenvalues NaN."""
    n = len(xy)
    k = int(min(max(k, 3), n))
    dist, idx = cKDTree(xy).query(xy, k=k, distance_upper_bound=radius)
    w = np.isfinite(dist).astype(float)
    idx = np.where(np.isfinite(dist), idx, 0)
    cnt = w.sum(axis=1)
    nb = xy[idx]
    mean = (nb * w[..., None]).sum(axis=1) / cnt[:, None]
    d = (nb - mean[:, None, :]) * w[..., None]
    cov = np.einsum("nki,nkj->nij", d, d) / cnt[:, None, None]
    evals, evecs = np.linalg.eigh(cov)
    evals[cnt < 3] = np.nan
    return evecs[:, :, 0], evals


def voxel_downsample(xy: NDArray[np.float64], voxel: float) -> NDArray[np.float64]:
    """Centroid of the points in each ``voxel`` x ``voxel`` cell (cells keyed by ``floor(p / voxel)``,
    as small_gicp's ``voxelgrid_sampling``); order of the cells is unspecified."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if voxel <= 0 or len(xy) == 0:
        return xy.copy()
    keys = np.floor(xy / voxel).astype(np.int64)
    keys -= keys.min(axis=0)
    flat = keys[:, 0] * (int(keys[:, 1].max()) + 1) + keys[:, 1]
    _, inv, cnt = np.unique(flat, return_inverse=True, return_counts=True)
    out = np.column_stack([np.bincount(inv, xy[:, 0]), np.bincount(inv, xy[:, 1])])
    return out / cnt[:, None]


def embed(xy: NDArray[np.float64], z: float = 0.0) -> NDArray[np.float64]:
    return np.column_stack([xy, np.full(len(xy), z)])


def registration_rmse(src_xy: NDArray[np.float64], tgt_xy: NDArray[np.float64], pose: ArrayLike,
                      max_corr: float, tree: cKDTree | None = None) -> tuple[float, float]:
    """Eq. 7 RMSE [m] over inliers (nearest-neighbour distance <= ``max_corr``), and inlier fraction."""
    if len(src_xy) == 0 or len(tgt_xy) == 0:
        return float("nan"), 0.0
    tree = tree if tree is not None else cKDTree(tgt_xy)
    d, _ = tree.query(transform2(pose, src_xy), distance_upper_bound=max_corr)
    ok = np.isfinite(d)
    if not ok.any():
        return float("nan"), 0.0
    return float(np.sqrt(np.mean(d[ok] ** 2))), float(ok.mean())


# -- backend clouds -------------------------------------------------------------------------------
def _sg_cloud(xy: NDArray[np.float64], kind: str, p: Params):
    """small_gicp cloud of 2D points extruded to a curtain at z = -h, 0, h, with covariances
    (GICP/VGICP) or normals (PLANE_ICP) estimated by small_gicp, and its KD-tree."""
    import small_gicp

    h = p.curtain
    pc = small_gicp.PointCloud(np.vstack([embed(xy, z) for z in (-h, 0.0, h)]))
    tree = small_gicp.KdTree(pc, num_threads=p.threads)
    if kind in ("GICP", "VGICP"):
        small_gicp.estimate_covariances(pc, tree, num_neighbors=3 * p.neighbors, num_threads=p.threads)
    elif kind == "PLANE_ICP":
        small_gicp.estimate_normals(pc, tree, num_neighbors=3 * p.neighbors, num_threads=p.threads)
    return pc, tree


def _o3d_cloud(xy: NDArray[np.float64], p: Params, normals: bool, covs: bool):
    """open3d cloud of 2D points at z = 0 with in-plane normals / GICP covariances from 2D PCA over
    neighbours within ``p.normal_radius``. With ``normals`` the points without a defined normal
    (isolated returns) are left out: a made-up normal would pull the solution."""
    o3d = require("open3d", "the open3d scan-matching backends")
    nrm = ok = None
    if normals or covs:
        nrm, ev = local_frames_2d(xy, p.neighbors, p.normal_radius)
        ok = np.isfinite(ev[:, 0]) & (ev[:, 0] <= p.planarity * ev[:, 1])
    if normals:
        xy, nrm = xy[ok], nrm[ok]
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(embed(xy)))
    if normals:
        pc.normals = o3d.utility.Vector3dVector(embed(nrm))
    if covs:
        # plane-to-plane regularisation (Segal et al. 2009) in 2D: thin across the line; isotropic
        # in the plane where no line is defined; always thin in z (the scan plane)
        t = np.column_stack([-nrm[:, 1], nrm[:, 0]])
        c = np.zeros((len(xy), 3, 3))
        c[:, :2, :2] = 1e-3 * np.einsum("ni,nj->nij", nrm, nrm) + np.einsum("ni,nj->nij", t, t)
        c[~ok, :2, :2] = np.eye(2)
        c[:, 2, 2] = 1e-3
        pc.covariances = o3d.utility.Matrix3dVector(c)
    return pc


def prepare_source(xy: ArrayLike, method: str = DEFAULT_METHOD, params: Params | None = None) -> Any:
    """Backend cloud of body-frame 2D points, with the local features the method needs."""
    backend, kind = resolve_method(method).split(":")
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    p = params or Params()
    if backend == "small_gicp":
        return _sg_cloud(xy, kind, p)[0]
    return _o3d_cloud(xy, p, normals=False, covs=kind == "gicp")


# -- backends -------------------------------------------------------------------------------------
class Target:
    """A target cloud prepared once for repeated registrations (KD-tree, covariances, voxel map)."""

    def __init__(self, xy: ArrayLike, method: str = DEFAULT_METHOD, params: Params | None = None,
                 parts: list[tuple[Any, NDArray[np.float64]]] | None = None) -> None:
        """``xy`` (N, 2) target points. ``parts``: optional ``(prepare_source(xy_i), pose_i)`` pairs
        whose union is ``xy``; VGICP then builds its voxel map from them without re-estimating
        covariances (small_gicp's incremental mapping), other methods ignore them."""
        self.method = resolve_method(method)
        self.params = params or Params()
        self.xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        self.tree2 = cKDTree(self.xy)
        backend, kind = self.method.split(":")
        self.backend, self.kind = backend, kind
        if backend == "small_gicp":
            self._prep_small_gicp(parts)
        else:
            self._prep_open3d()

    def prepare_source(self, xy: ArrayLike) -> Any:
        """Backend cloud of body-frame points (covariances/normals as the method needs)."""
        return prepare_source(xy, self.method, self.params)

    # small_gicp ----------------------------------------------------------------------------------
    def _prep_small_gicp(self, parts) -> None:
        import small_gicp

        self._vmap = None
        if self.kind == "VGICP":
            self._vmap = small_gicp.GaussianVoxelMap(self.params.voxel)
            if parts:
                for cloud, pose in parts:
                    self._vmap.insert(cloud, pose_to_matrix4(pose))
            else:
                self._vmap.insert(_sg_cloud(self.xy, self.kind, self.params)[0])
        else:
            self._pc, self._tree = _sg_cloud(self.xy, self.kind, self.params)

    def _sg_call(self, src, T: NDArray[np.float64], iters: int):
        import small_gicp

        p = self.params
        if self._vmap is not None:
            return small_gicp.align(self._vmap, src, T, max_correspondence_distance=p.max_corr,
                                    num_threads=p.threads, max_iterations=iters)
        return small_gicp.align(self._pc, src, self._tree, T, registration_type=self.kind,
                                max_correspondence_distance=p.max_corr, num_threads=p.threads,
                                max_iterations=iters)

    def _align_small_gicp(self, src, init: NDArray[np.float64]):
        p = self.params
        if p.planar == "project":
            r = self._sg_call(src, pose_to_matrix4(init), p.max_iter)
            return matrix4_to_pose(r.T_target_source), int(r.iterations), bool(r.converged), None
        # Gauss-Newton in SE(2) on small_gicp's linearisation: delta = (ω_xyz, v_xyz), T <- T exp(delta)
        pose = np.array(init, dtype=float)
        H3 = None
        converged = False
        it = 0
        for it in range(1, p.max_iter + 1):  # noqa: B007
            r = self._sg_call(src, pose_to_matrix4(pose), 1)
            H3 = np.asarray(r.H)[_SE2_IX]
            if r.num_inliers < 3 or not np.isfinite(H3).all():
                break
            try:
                d = -np.linalg.solve(H3 + _EPS_I3, np.asarray(r.b).reshape(-1)[_SE2])
            except np.linalg.LinAlgError:
                break
            pose = compose(pose, _se2_exp(*d.tolist()))
            if np.hypot(d[0], d[1]) < p.eps_trans and abs(d[2]) < p.eps_rot:
                converged = True
                break
        return pose, it, converged, H3

    # open3d --------------------------------------------------------------------------------------
    def _prep_open3d(self) -> None:
        self._o3d = _o3d_cloud(self.xy, self.params, normals=self.kind == "point_to_plane",
                               covs=self.kind == "gicp")

    def _align_open3d(self, src, init: NDArray[np.float64]):
        o3d = require("open3d", "the open3d scan-matching backends")
        reg = o3d.pipelines.registration
        p = self.params

        def run(T: NDArray[np.float64], iters: int):
            crit = reg.ICPConvergenceCriteria(1e-9, 1e-9, iters)
            if self.kind == "gicp":
                return reg.registration_generalized_icp(src, self._o3d, p.max_corr, T,
                                                        reg.TransformationEstimationForGeneralizedICP(), crit)
            est = (reg.TransformationEstimationPointToPlane() if self.kind == "point_to_plane"
                   else reg.TransformationEstimationPointToPoint())
            return reg.registration_icp(src, self._o3d, p.max_corr, T, est, crit)

        if p.planar == "project":
            r = run(pose_to_matrix4(init), p.max_iter)
            return matrix4_to_pose(r.transformation), -1, True, None  # open3d does not report iterations
        pose = np.array(init, dtype=float)
        converged = False
        it = 0
        for it in range(1, p.max_iter + 1):  # noqa: B007
            r = run(pose_to_matrix4(pose), 1)
            new = matrix4_to_pose(r.transformation)  # re-projected onto SE(2) after every iteration
            step = new - pose
            pose = np.array([new[0], new[1], wrap_angle(new[2])])
            if np.hypot(step[0], step[1]) < p.eps_trans and abs(wrap_angle(step[2])) < p.eps_rot:
                converged = True
                break
        return pose, it, converged, None

    # public --------------------------------------------------------------------------------------
    def align(self, src_xy: ArrayLike, init: ArrayLike = (0.0, 0.0, 0.0), source: Any = None) -> Aligned:
        """Register body-frame points ``src_xy`` (N, 2) to this target from pose ``init``.

        ``source``: the cloud from :meth:`prepare_source` when the caller keeps it (it is then not
        rebuilt); the time ``ms`` includes the source preparation either way when built here.
        """
        src_xy = np.asarray(src_xy, dtype=float).reshape(-1, 2)
        init = np.asarray(init, dtype=float)
        t0 = time.perf_counter()
        src = source if source is not None else self.prepare_source(src_xy)
        if self.backend == "small_gicp":
            pose, it, conv, H3 = self._align_small_gicp(src, init)
        else:
            pose, it, conv, H3 = self._align_open3d(src, init)
        ms = (time.perf_counter() - t0) * 1e3
        pose = np.array([pose[0], pose[1], wrap_angle(pose[2])])
        rmse, fit = registration_rmse(src_xy, self.xy, pose, self.params.max_corr, self.tree2)
        return Aligned(pose, rmse, fit, ms, it, conv, H3)


def align(src_xy: ArrayLike, tgt_xy: ArrayLike, init: ArrayLike = (0.0, 0.0, 0.0),
          method: str = DEFAULT_METHOD, **params: Any) -> Aligned:
    """Register 2D points ``src_xy`` to ``tgt_xy`` (both (N, 2)) from ``init`` = (x, y, yaw).

    The returned pose maps source coordinates into the target frame. ``ms`` includes the
    target's preparation (KD-tree, covariances), as a one-off pair registration does.
    """
    t0 = time.perf_counter()
    tgt = Target(tgt_xy, method, Params(**params))
    prep = (time.perf_counter() - t0) * 1e3
    out = tgt.align(src_xy, init)
    out.ms += prep
    return out


def single_frame(pairs: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
                 methods: tuple[str, ...] = METHODS, init: ArrayLike = (0.0, 0.0, 0.0),
                 **params: Any) -> dict[str, dict[str, float]]:
    """The paper's single-frame experiment: mean eq. 7 RMSE [m] and mean time [ms] per method over
    ``pairs`` of (source, target) scans (adjacent frames)."""
    out: dict[str, dict[str, float]] = {}
    for m in methods:
        align(pairs[0][0], pairs[0][1], init, m, **params)  # warm-up: imports and first-call setup
        rs = [align(s, t, init, m, **params) for s, t in pairs]
        out[resolve_method(m)] = {
            "rmse_m": float(np.nanmean([r.rmse for r in rs])),
            "fitness": float(np.mean([r.fitness for r in rs])),
            "ms_mean": float(np.mean([r.ms for r in rs])),
            "pairs": len(rs),
        }
    return out
