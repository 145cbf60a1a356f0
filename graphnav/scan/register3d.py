"""3D point-cloud registration behind one call: small_gicp and open3d as the peers, our NDT.

``register(source, target, method, init=None, **params) -> Registration``: ``T`` (4x4) maps source
points into the target frame (``T_target_source``, small_gicp's name).

Methods (``METHODS``):

* ``icp``, ``p2plane``, ``gicp``, ``vgicp``: small_gicp's ``align`` (point-to-point ICP,
  point-to-plane ICP, GICP of Segal et al. 2009, VGICP of Koide et al. 2021) on clouds that
  small_gicp's ``preprocess_points`` voxel-downsampled (``voxel``) and gave normals/covariances
  (``knn`` neighbours); VGICP's target is a ``GaussianVoxelMap`` of side ``vgicp_voxel``.
* ``o3d-icp``, ``o3d-p2plane``, ``o3d-gicp``: open3d's ``registration_icp`` (point-to-point,
  point-to-plane) and ``registration_generalized_icp`` on the same downsampled points, normals
  and covariances from open3d's KNN estimation (covariances regularised plane-to-plane, eps 1e-3).
* ``ndt``: Magnusson's 3D NDT (:mod:`graphnav.scan.ndt`): voxel Gaussians of the whole target at
  ``resolution``, the downsampled source, ``neighbors`` voxels per point.

**Covariance convention.** ``cov`` (6x6) is over delta in ``T exp(delta)`` (right perturbation),
delta = (omega, v): rotation first, then translation, both in the source frame. This is
small_gicp's own linearisation (``T_target_source * se3_exp(delta)``, H and b by delta) and GTSAM's
Pose3 tangent, so ``cov`` has the form of a ``BetweenFactorPose3`` noise model (its scale is
optimistic, as Hessian covariances are: docs/scan-matching-3d.md). For the least-squares
methods ``cov = s^2 H^-1`` with H the Gauss-Newton Hessian of ``e = 1/2 sum r' M r`` (M = I for ICP,
the per-axis normal weights of small_gicp's point-to-plane, ``(C_t + R C_s R')^-1`` for GICP/VGICP)
and ``s^2 = 2 e / (m - 6)`` the residual variance (m scalar residuals: 3 per inlier; 1 per inlier for
open3d's point-to-plane). small_gicp (its Levenberg-Marquardt loop) returns H and b of its last
linearisation, taken at most one converged step (below its epsilons) before ``T``, and e after that
step on the same correspondences (tests/scan/test_register3d.py checks both against
:func:`lsq_hessian`); for open3d, H and e are computed here from its correspondences at ``T``.
NDT: see :mod:`graphnav.scan.ndt`.

``fitness`` is the fraction of the (downsampled) source points with a target point within
``max_corr`` at ``T`` and ``rmse`` their RMS distance (eq. 7 of Wang et al. 2023); ``objective`` is
the method's own final value (small_gicp's ``error``, open3d's ``inlier_rmse``, NDT's score).
``ms`` is the whole registration, preprocessing of both clouds included (``ms_prep`` + ``ms_align``);
``extra["cpu_ms"]`` the process CPU time of the same span (all threads: open3d's ICP uses OpenMP);
the fitness evaluation is not timed, nor the one-off load of the compiled NDT kernels in a new
process (``ms_kernel_load``, reported apart; the libraries' imports are not timed either).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import FRACTION, KNN, POSITIVE, THREADS, OptionError, Range, check_fields
from ..errors import LogError, require
from ._kdtree import cKDTree
from .native_stderr import NativeWarnings
from .ndt import NdtParams, build_voxels3, ndt3d, skew, warm_up

METHODS = ("icp", "p2plane", "gicp", "vgicp", "ndt", "o3d-icp", "o3d-p2plane", "o3d-gicp")
_SMALL_GICP = {"icp": "ICP", "p2plane": "PLANE_ICP", "gicp": "GICP", "vgicp": "VGICP"}
COV_CONVENTION = "T exp(delta), delta = (omega_x, omega_y, omega_z, v_x, v_y, v_z) in the source frame (GTSAM Pose3)"


_REG3_RANGES = {"voxel": Range(lo=0.0, hi=1e4), "max_corr": Range(lo=0.0, hi=1e6, lo_open=True), "knn": KNN,
                "vgicp_voxel": Range(lo=0.0, hi=1e4, lo_open=True),
                "max_iter": Range(lo=1, hi=100_000, integer=True, optional=True),
                "eps_trans": POSITIVE, "eps_rot": POSITIVE, "threads": THREADS,
                "resolution": Range(lo=0.0, hi=1e4, lo_open=True), "outlier_ratio": Range(lo=0.0, hi=1.0, lo_open=True),
                "neighbors": Range(lo=1, hi=27, integer=True),
                "min_points": Range(lo=3, hi=1_000_000, integer=True),
                "eig_ratio": FRACTION}
"""Each numeric :class:`Reg3Params` field's declared range (checked on construction)."""


@dataclass(frozen=True)
class Reg3Params:
    """Settings (metres, radians). ``voxel`` downsampling of both clouds (NDT: of the source; 0: none);
    ``max_corr`` correspondence distance (ICP family, and the fitness of every method); ``knn``
    neighbours of the normals/covariances; ``vgicp_voxel``; ``max_iter`` (None: the method's
    default, small_gicp 20, open3d 30, NDT 35); ``eps_trans``/``eps_rot`` convergence (small_gicp's
    defaults 1e-3 m, 0.1 deg); ``threads``; NDT: ``resolution``, ``outlier_ratio``, ``neighbors``
    (1/7/27), ``min_points``, ``eig_ratio``, ``backend`` (PCL's defaults, ndt_omp's DIRECT7)."""

    voxel: float = 0.25
    max_corr: float = 1.0
    knn: int = 10
    vgicp_voxel: float = 1.0
    max_iter: int | None = None
    eps_trans: float = 1e-3
    eps_rot: float = float(np.radians(0.1))
    threads: int = 1
    resolution: float = 1.0
    outlier_ratio: float = 0.55
    neighbors: int = 7
    min_points: int = 6
    eig_ratio: float = 0.01
    backend: str = "auto"

    def __post_init__(self) -> None:
        check_fields(self, _REG3_RANGES, "option")
        if self.neighbors not in (1, 7, 27):
            raise OptionError("option neighbors", f"must be 1, 7 or 27, got {self.neighbors!r}")
        if self.backend not in ("auto", "numba"):
            raise OptionError("option backend", f"must be auto or numba, got {self.backend!r}")

    @classmethod
    def from_kwargs(cls, **params: Any) -> Reg3Params:
        known = {f.name for f in fields(cls)}
        bad = sorted(set(params) - known)
        if bad:
            raise ValueError(f"unknown registration parameter(s) {', '.join(bad)}; known: {', '.join(sorted(known))}")
        return cls(**params)


@dataclass
class Registration:
    """One registration's result (see the module doc for every field's meaning)."""

    method: str
    T: NDArray[np.float64]
    ms: float
    fitness: float
    rmse: float
    objective: float
    cov: NDArray[np.float64]
    converged: bool | None
    iterations: int | None
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["T"] = self.T.tolist()
        d["cov"] = self.cov.tolist()
        d["cov_convention"] = COV_CONVENTION
        return d


# -- helpers --------------------------------------------------------------------------------------
def pose_error(T: ArrayLike, T_ref: ArrayLike) -> tuple[float, float]:
    """Translation [m] and rotation [deg] of ``T_ref^-1 T`` (the error of T against the reference)."""
    E = np.linalg.inv(np.asarray(T_ref, dtype=float)) @ np.asarray(T, dtype=float)
    c = np.clip((np.trace(E[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.linalg.norm(E[:3, 3])), float(np.degrees(np.arccos(c)))


def xyzrpy_matrix(x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """4x4 of a translation and roll/pitch/yaw [rad]: R = R_z(yaw) R_y(pitch) R_x(roll)."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    T[:3, 3] = [x, y, z]
    return T


def lsq_hessian(src: NDArray, tgt: NDArray, T: ArrayLike, kind: str, tgt_normals: NDArray | None = None,
                src_covs: NDArray | None = None, tgt_covs: NDArray | None = None
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, int]:
    """H, b, e and the residual count m of ``e = 1/2 sum r' M r`` over matched pairs ``src[i] <-> tgt[i]``
    (already paired), r = tgt - T src, linearised in ``T exp(delta)``, delta = (omega, v):
    J = [R [s]x, -R] (small_gicp's Jacobian). ``kind``: ``icp`` (M = I), ``p2plane`` (scalar n'r, as
    open3d; m = pairs), ``p2plane_axes`` (small_gicp's per-axis n * r), ``gicp`` (M = (C_t + R C_s R')^-1)."""
    T = np.asarray(T, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    r = tgt - (src @ R.T + t)
    n = len(src)
    J = np.zeros((n, 3, 6))
    J[:, :, :3] = np.einsum("ab,nbc->nac", R, np.stack([skew(s) for s in src]) if n else np.zeros((0, 3, 3)))
    J[:, :, 3:] = -R
    if kind == "icp":
        M = np.broadcast_to(np.eye(3), (n, 3, 3))
        m = 3 * n
    elif kind == "p2plane":
        M = np.einsum("na,nb->nab", tgt_normals, tgt_normals)
        m = n
    elif kind == "p2plane_axes":
        M = np.einsum("na,ab->nab", tgt_normals ** 2, np.eye(3))
        m = 3 * n
    elif kind == "gicp":
        M = np.linalg.inv(tgt_covs + np.einsum("ab,nbc,dc->nad", R, src_covs, R))
        m = 3 * n
    else:
        raise ValueError(f"unknown residual kind {kind!r}")
    MJ = np.einsum("nab,nbj->naj", M, J)
    H = np.einsum("nai,naj->ij", J, MJ)
    b = np.einsum("naj,na->j", MJ, r)
    e = 0.5 * float(np.einsum("na,nab,nb->", r, M, r))
    return H, b, e, m


def gicp_terms(src: NDArray, tgt: NDArray, T: ArrayLike, src_covs: NDArray, tgt_covs: NDArray
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per pair of GICP (paired ``src[i] <-> tgt[i]``) the residual ``r = tgt - T src`` (n, 3), its
    Jacobian ``J = [R [s]x, -R]`` in ``T exp(delta)``, delta = (omega, v) (n, 3, 6; :func:`lsq_hessian`'s)
    and the weight ``M = (C_t + R C_s R')^-1`` (n, 3, 3)."""
    T = np.asarray(T, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    n = len(src)
    S = np.zeros((n, 3, 3))  # [s]x, vectorised
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -src[:, 2], src[:, 1], -src[:, 0]
    S -= S.transpose(0, 2, 1)
    J = np.zeros((n, 3, 6))
    J[:, :, :3] = R @ S
    J[:, :, 3:] = -R
    M = np.linalg.inv(tgt_covs + R @ src_covs @ R.T)
    return tgt - (src @ R.T + t), J, M


def sandwich_covariance(J: NDArray, M: NDArray, r: NDArray, groups: NDArray | None = None,
                        extra: NDArray | None = None) -> NDArray[np.float64]:
    """Cluster-robust sandwich covariance of the M-weighted least-squares estimate (Huber 1967; White
    1980; Liang & Zeger 1986 for clusters): ``H^-1 B H^-1`` with ``H = sum J' M J`` and
    ``B = G/(G-1) sum_c g_c g_c'``, ``g_c = sum_{i in c} J_i' M_i r_i`` the score of cluster ``c`` (``groups``
    an integer label per pair; None: each pair its own cluster) and G the number of clusters. For iid
    residuals of variance ``s^2`` and M = I its expectation is ``s^2 H^-1`` (tests/scan/test_register3d.py).
    ``extra`` (n, d, d): per-pair error covariances the residuals cannot show (independent across pairs),
    added to B as ``sum J' M S M J``. ``J`` (n, d, p), ``M`` (n, d, d), ``r`` (n, d)."""
    MJ = M @ J
    p = J.shape[2]
    H = J.reshape(-1, p).T @ MJ.reshape(-1, p)
    g = np.einsum("naj,na->nj", MJ, r)
    if groups is not None:
        _, inv = np.unique(groups, return_inverse=True)
        gc = np.zeros((int(inv.max()) + 1 if len(inv) else 0, g.shape[1]))
        np.add.at(gc, inv.ravel(), g)
        g = gc
    G = len(g)
    if G <= H.shape[0]:
        return np.diag(np.full(H.shape[0], np.inf))
    B = G / (G - 1.0) * (g.T @ g)
    if extra is not None:
        B = B + MJ.reshape(-1, p).T @ (extra @ MJ).reshape(-1, p)
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    w = np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))
    Hi = (V / w) @ V.T
    C = Hi @ B @ Hi
    return 0.5 * (C + C.T)


def lsq_covariance(H: NDArray, e: float, m: int) -> NDArray[np.float64]:
    """``s^2 H^-1`` with ``s^2 = 2 e / (m - 6)``; an unconstrained direction gets a huge variance."""
    if m <= 6 or not e > 0:
        return np.diag(np.full(H.shape[0], np.inf))
    s2 = 2.0 * e / (m - 6)
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    w = np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))
    return s2 * (V / w) @ V.T


def plane_covariances(covs: NDArray, eps: float = 1e-3) -> NDArray[np.float64]:
    """Segal et al. 2009's plane-to-plane regularisation of local covariances: the eigenvalues
    replaced by (eps, 1, 1), the smallest along the normal (open3d's and small_gicp's choice)."""
    _, V = np.linalg.eigh(covs)
    return np.einsum("nae,e,nbe->nab", V, np.array([eps, 1.0, 1.0]), V)


def fit_quality(src: NDArray, tree: cKDTree, T: NDArray, max_corr: float) -> tuple[float, float]:
    """Inlier fraction and inlier RMS distance (eq. 7) of the source moved by ``T``."""
    if len(src) == 0:
        return 0.0, float("nan")
    d, _ = tree.query(src @ T[:3, :3].T + T[:3, 3], distance_upper_bound=max_corr)
    ok = np.isfinite(d)
    return float(ok.mean()), float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("nan")


MAX_COORD = 1e5
"""[m] A registered point farther than this from the origin is refused: small_gicp's voxel keys hold
2^20 voxels a side (beyond, "voxel coord is out of range" and a silent identity) and float32 clouds
resolve 1 cm only up to 1e5 m; shift georeferenced clouds to a local origin first."""
MIN_POINTS = 10


def _as_points(a: ArrayLike, name: str) -> NDArray[np.float64]:
    p = np.asarray(a, dtype=float)
    if p.ndim != 2 or p.shape[1] < 3:
        raise LogError(f"expected (N, 3) points, got shape {p.shape}", file=name)
    p = np.ascontiguousarray(p[:, :3])
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < MIN_POINTS:
        raise LogError(f"only {len(p)} finite points; a registration needs {MIN_POINTS}", file=name)
    far = float(np.abs(p).max())
    if far > MAX_COORD:
        raise LogError(f"a point lies {far:.3g} m from the origin, beyond the registration bound "
                       f"({MAX_COORD:g} m); shift the cloud to a local origin", file=name)
    return p


def degeneracy(points: NDArray[np.float64], resolution: float) -> str | None:
    """Why ``points`` cannot fix a 3D pose (all at one spot, on a line, on a plane, within ``resolution``),
    or None: from the spread of the points along their principal axes."""
    c = points - points.mean(axis=0)
    sd = np.sqrt(np.maximum(np.linalg.eigvalsh(c.T @ c / max(len(c) - 1, 1)), 0.0))  # ascending
    tol = max(resolution, 1e-6 * float(sd[-1]), 1e-9)
    flat = int(np.sum(sd <= tol))
    if flat == 3:
        return "all points at one spot"
    if flat == 2:
        return "the points lie on a line"
    if flat == 1:
        return "the points lie on a plane"
    return None


def _failed(method: str, T0: NDArray, reason: str, src: NDArray, tgt: NDArray) -> Registration:
    """The result of a registration that could not run: ``converged`` false, ``reason`` in extra."""
    return Registration(method, T0.copy(), 0.0, 0.0, float("nan"), float("nan"), np.diag(np.full(6, np.inf)),
                        False, 0, {"reason": reason, "ms_prep": 0.0, "ms_align": 0.0, "cpu_ms": 0.0,
                                   "source_points": len(src), "target_points": len(tgt), "source_used": 0})


# -- backends -------------------------------------------------------------------------------------
def _small_gicp(method: str, src: NDArray, tgt: NDArray, T0: NDArray, p: Reg3Params) -> dict[str, Any]:
    import small_gicp

    t0 = time.perf_counter()
    kind = _SMALL_GICP[method]
    s_pc, _ = small_gicp.preprocess_points(src, p.voxel, num_neighbors=p.knn, num_threads=p.threads)
    t_pc, t_tree = small_gicp.preprocess_points(tgt, p.voxel, num_neighbors=p.knn, num_threads=p.threads)
    vmap = None
    if kind == "VGICP":
        vmap = small_gicp.GaussianVoxelMap(p.vgicp_voxel)
        vmap.insert(t_pc)
    t1 = time.perf_counter()
    kw = {"max_correspondence_distance": p.max_corr, "num_threads": p.threads,
          "max_iterations": p.max_iter or 20, "rotation_epsilon": p.eps_rot, "translation_epsilon": p.eps_trans}
    if vmap is not None:
        r = small_gicp.align(vmap, s_pc, T0, **kw)
    else:
        r = small_gicp.align(t_pc, s_pc, t_tree, T0, registration_type=kind, **kw)
    t2 = time.perf_counter()
    H = np.asarray(r.H)
    return {"T": np.asarray(r.T_target_source), "ms_prep": (t1 - t0) * 1e3, "ms_align": (t2 - t1) * 1e3,
            "cov": lsq_covariance(H, float(r.error), 3 * int(r.num_inliers)), "objective": float(r.error),
            "converged": bool(r.converged), "iterations": int(r.iterations) + 1,
            "src": s_pc.points()[:, :3], "tgt": t_pc.points()[:, :3],
            "extra": {"inliers": int(r.num_inliers), "hessian": H.tolist()}}


def _open3d(method: str, src: NDArray, tgt: NDArray, T0: NDArray, p: Reg3Params) -> dict[str, Any]:
    o3d = require("open3d", f"registration method {method!r}")
    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    s = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src))
    t = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt))
    if p.voxel > 0:
        s, t = s.voxel_down_sample(p.voxel), t.voxel_down_sample(p.voxel)
    knn = o3d.geometry.KDTreeSearchParamKNN(p.knn)
    if method == "o3d-p2plane":
        t.estimate_normals(knn)
    elif method == "o3d-gicp":
        for pc in (s, t):  # Segal's plane-to-plane covariances, as open3d builds them when given none
            pc.estimate_covariances(knn)
            pc.covariances = o3d.utility.Matrix3dVector(plane_covariances(np.asarray(pc.covariances)))
    t1 = time.perf_counter()
    crit = reg.ICPConvergenceCriteria(1e-6, 1e-6, p.max_iter or 30)
    if method == "o3d-gicp":
        r = reg.registration_generalized_icp(s, t, p.max_corr, T0, reg.TransformationEstimationForGeneralizedICP(),
                                             crit)
    else:
        est = (reg.TransformationEstimationPointToPlane() if method == "o3d-p2plane"
               else reg.TransformationEstimationPointToPoint())
        r = reg.registration_icp(s, t, p.max_corr, T0, est, crit)
    t2 = time.perf_counter()
    T = np.asarray(r.transformation).copy()
    sp, tp = np.asarray(s.points), np.asarray(t.points)
    c = np.asarray(r.correspondence_set, dtype=np.int64).reshape(-1, 2)
    kind = {"o3d-icp": "icp", "o3d-p2plane": "p2plane", "o3d-gicp": "gicp"}[method]
    H, _, e, m = lsq_hessian(sp[c[:, 0]], tp[c[:, 1]], T, kind,
                             tgt_normals=np.asarray(t.normals)[c[:, 1]] if kind == "p2plane" else None,
                             src_covs=np.asarray(s.covariances)[c[:, 0]] if kind == "gicp" else None,
                             tgt_covs=np.asarray(t.covariances)[c[:, 1]] if kind == "gicp" else None)
    return {"T": T, "ms_prep": (t1 - t0) * 1e3, "ms_align": (t2 - t1) * 1e3, "cov": lsq_covariance(H, e, m),
            "objective": float(r.inlier_rmse), "converged": None, "iterations": None, "src": sp, "tgt": tp,
            "extra": {"inliers": len(c), "hessian": H.tolist()}}


def _ndt(src: NDArray, tgt: NDArray, T0: NDArray, p: Reg3Params) -> dict[str, Any]:
    import small_gicp

    ms_load = warm_up() if p.backend in ("auto", "numba") else 0.0
    t0 = time.perf_counter()
    s = small_gicp.voxelgrid_sampling(src, p.voxel).points()[:, :3] if p.voxel > 0 else src
    prm = NdtParams(resolution=p.resolution, outlier_ratio=p.outlier_ratio, min_points=p.min_points,
                    eig_ratio=p.eig_ratio, neighbors=p.neighbors, max_iter=p.max_iter or 35, backend=p.backend)
    vmap = build_voxels3(tgt, prm.resolution, prm.min_points, prm.eig_ratio, prm.backend)
    t1 = time.perf_counter()
    r = ndt3d(s, vmap, T0, prm)
    t2 = time.perf_counter()
    return {"T": r.T, "ms_prep": (t1 - t0) * 1e3, "ms_align": (t2 - t1) * 1e3, "cov": r.cov,
            "objective": r.score, "converged": r.converged, "iterations": r.iterations, "src": s, "tgt": None,
            "extra": {"score_per_point": r.score_per_point, "hits": r.hits, "voxels": r.extra["voxels"],
                      "backend": r.extra["backend"], "ms_kernel_load": ms_load, "hessian": r.hessian.tolist()}}


def register(source: ArrayLike, target: ArrayLike, method: str = "gicp", init: ArrayLike | None = None,
             **params: Any) -> Registration:
    """Register (N, 3) ``source`` points to (M, 3) ``target`` points from the 4x4 ``init`` (identity
    if None) with ``method`` (one of ``METHODS``); ``params``: fields of :class:`Reg3Params`."""
    if method not in METHODS:
        raise ValueError(f"unknown registration method {method!r}; known: {', '.join(METHODS)}")
    p = Reg3Params.from_kwargs(**params)
    src, tgt = _as_points(source, "source"), _as_points(target, "target")
    T0 = np.eye(4) if init is None else np.asarray(init, dtype=float).reshape(4, 4)
    for name, pts in (("source", src), ("target", tgt)):
        why = degeneracy(pts, 0.0)
        if why is not None:
            return _failed(method, T0, f"{name}: degenerate geometry ({why})", src, tgt)
    for name, size in (("voxel", p.voxel), ("vgicp_voxel", p.vgicp_voxel if method == "vgicp" else 0.0),
                       ("resolution", p.resolution if method == "ndt" else 0.0)):
        if size > 0 and max(float(np.abs(src).max()), float(np.abs(tgt).max())) / size >= 2**20:
            raise OptionError(f"option {name}", f"{size:g} m is too fine for clouds that reach "
                                                f"{max(float(np.abs(src).max()), float(np.abs(tgt).max())):.3g} m "
                                                "(2^20 voxels a side at most)")
    c0 = time.process_time()
    with NativeWarnings(method) as native:
        if method in _SMALL_GICP:
            out = _small_gicp(method, src, tgt, T0, p)
        elif method == "ndt":
            out = _ndt(src, tgt, T0, p)
        else:
            out = _open3d(method, src, tgt, T0, p)
    cpu = (time.process_time() - c0) * 1e3
    out["extra"]["native_warnings"] = native.count
    if out["tgt"] is None:  # NDT: the fitness is measured on the target downsampled as the others'
        import small_gicp

        out["tgt"] = small_gicp.voxelgrid_sampling(tgt, p.voxel).points()[:, :3] if p.voxel > 0 else tgt
    fit, rmse = fit_quality(out["src"], cKDTree(out["tgt"]), out["T"], p.max_corr)
    converged, reason = out["converged"], None
    if not np.all(np.isfinite(out["T"])):
        converged, reason = False, "the estimate is not finite"
    elif fit == 0.0:
        converged, reason = False, f"no source point within max_corr ({p.max_corr:g} m) of the target at T"
    elif len(out["src"]) < MIN_POINTS:
        converged, reason = False, f"only {len(out['src'])} source points after the voxel filter"
    else:
        why = degeneracy(out["src"], 0.0)
        if why is not None:
            converged, reason = False, f"source after the voxel filter: degenerate geometry ({why})"
    if reason is not None:
        out["extra"]["reason"] = reason
    elif converged is None:  # open3d does not say: a result with inliers
        converged = True
    extra = {"ms_prep": out["ms_prep"], "ms_align": out["ms_align"], "cpu_ms": cpu, "source_points": len(src),
             "target_points": len(tgt), "source_used": len(out["src"]), **out["extra"]}
    return Registration(method, out["T"], out["ms_prep"] + out["ms_align"], fit, rmse, out["objective"],
                        0.5 * (out["cov"] + out["cov"].T), converged, out["iterations"], extra)
