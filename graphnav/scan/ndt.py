"""Normal Distributions Transform registration: Magnusson's 3D P2D-NDT and Biber & Strasser's 2D NDT.

**3D (Magnusson 2009, thesis ch. 6).** The target is cut into cubic voxels of side ``resolution``;
every voxel with at least ``min_points`` points holds a Gaussian (mean, covariance; eigenvalues
below ``eig_ratio`` times the largest raised to it, eq. 6.11). A source point x, moved by the pose
p = (t_x, t_y, t_z, phi_x, phi_y, phi_z), T(p) x = R_x(phi_x) R_y(phi_y) R_z(phi_z) x + t (eq. 6.17),
scores against each Gaussian met (the voxel that holds it and, with ``neighbors`` 7 or 27, the 6 face
or 26 surrounding voxels: ndt_omp's DIRECT7 / DIRECT26+1)::

    score = sum -d1 exp(-d2/2 q' Sigma^-1 q),  q = T(p) x - mu                     (eq. 6.9-6.10)
    c1 = 10 (1 - outlier_ratio),  c2 = outlier_ratio / resolution^3,  d3 = -log c2
    d1 = -log(c1 + c2) - d3,  d2 = -2 log((-log(c1 exp(-1/2) + c2) - d3) / d1)     (eq. 6.8)

We minimise f = -score with Newton steps on the analytic gradient (eq. 6.12) and Hessian (eq. 6.13,
with the Euler-angle Jacobian and second derivatives of eq. 6.18-6.21). Where the Hessian is
indefinite (far from the optimum) the step uses its Gauss-Newton part (:func:`_newton`); the step
is clamped (``max_step_trans`` m, ``max_step_rot`` rad) and a backtracking line search (Armijo)
replaces More-Thuente's. The source is first moved by the initial guess T0 and p starts at 0, so
the Euler angles stay small: T = T(p) T0.

**2D (Biber & Strasser 2003).** Cells of side ``resolution`` in four grids shifted by half a cell
(x, y, both), cells with at least 3 points, covariance eigenvalues floored at 1e-3 of the largest;
score = sum over points and grids of exp(-q' Sigma^-1 q / 2), maximised by Newton's method in
p = (t_x, t_y, phi) with the analytic gradient and Hessian (where it is indefinite, its Gauss-Newton
part, as in 3D; Biber adds lambda I).

**Covariance.** Near a good fit, f ~ const + k * (1/2) sum m with m = q' Sigma^-1 q and k = -d1 d2
(3D; k = 1 for Biber's 2D score), so H_f / k is the Gauss-Newton information of the Mahalanobis
residuals. With their variance s^2 = sum e m / (D sum e - n_params) (e = exp(-d2 m / 2) the soft
inlier weight, D the dimension), ``cov = s^2 k H_f^-1``, mapped to the right-perturbation tangent of
the result: 3D ``T exp(delta)``, delta = (omega, v) (GTSAM Pose3 Local coordinates; small_gicp's
convention); 2D ``T exp(delta)``, delta = (x, y, theta) (GTSAM Pose2).

**Kernels.** The voxel map and the derivatives are the kernels of :mod:`._ndt_fast` (voxel hashing), the one
implementation: compiled by numba when importable, else run as plain Python (:mod:`._jit`; the same code,
slow). ``backend``: ``auto``, or ``numba`` (compiled or an error naming the extra). Memory is linear in the
points and occupied voxels (no dense grid from the bounding box).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import require
from ..geometry import wrap_angle


def _fast():
    from . import _ndt_fast

    return _ndt_fast


def resolve_backend(backend: str) -> str:
    """``"numba"`` when the kernels are compiled, ``"python"`` when they run interpreted (numba absent);
    ``backend="numba"`` without numba raises :class:`graphnav.errors.MissingExtra`."""
    if backend not in ("auto", "numba"):
        raise ValueError(f"unknown NDT backend {backend!r}; known: auto, numba (one implementation: "
                         "\"auto\" runs the kernels as plain Python when numba is absent)")
    try:
        import numba  # noqa: F401
    except ImportError:
        if backend == "numba":
            require("numba", 'NDT backend "numba"')
        return "python"
    return "numba"


_WARM: list[float] = []


def warm_up() -> float:
    """Load (or compile) the numba kernels once per process, on a tiny problem; returns the ms it took
    (0 after the first call, or without numba). Callers that time registrations call it first, so a
    registration's time is not the one-off load."""
    if _WARM or resolve_backend("auto") != "numba":
        return 0.0
    t0 = time.perf_counter()
    rng = np.random.default_rng(0)
    pts = rng.normal(0.0, 1.0, (64, 3))
    ndt3d(pts, pts, params=NdtParams(max_iter=1))
    ndt2d(pts[:, :2], pts[:, :2], params=Ndt2Params(max_iter=1))
    _WARM.append((time.perf_counter() - t0) * 1e3)
    return _WARM[0]


def score_constants(resolution: float, outlier_ratio: float) -> tuple[float, float]:
    """Magnusson's d1 (< 0) and d2 (> 0) of eq. 6.8 for a voxel side and outlier ratio."""
    if not 0.0 < outlier_ratio < 1.0:
        raise ValueError(f"outlier_ratio must be in (0, 1), got {outlier_ratio}")
    c1 = 10.0 * (1.0 - outlier_ratio)
    c2 = outlier_ratio / resolution ** 3
    d3 = -np.log(c2)
    d1 = -np.log(c1 + c2) - d3
    d2 = -2.0 * np.log((-np.log(c1 * np.exp(-0.5) + c2) - d3) / d1)
    return float(d1), float(d2)


def neighbor_offsets(neighbors: int) -> NDArray[np.int64]:
    """Voxel offsets searched around a point's voxel: 1 (own), 7 (+ faces) or 27 (3x3x3)."""
    if neighbors == 1:
        return np.zeros((1, 3), np.int64)
    if neighbors == 7:
        return np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.int64)
    if neighbors == 27:
        r = (-1, 0, 1)
        return np.array([[a, b, c] for a in r for b in r for c in r], np.int64)
    raise ValueError(f"neighbors must be 1, 7 or 27, got {neighbors}")


# -- rotations ------------------------------------------------------------------------------------
def euler_derivatives(phi: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    """R = R_x R_y R_z (eq. 6.17), its derivatives dR (3, 3, 3) by (phi_x, phi_y, phi_z) and second
    derivatives d2R (6, 3, 3) in the order xx, xy, xz, yy, yz, zz (the matrices whose products with
    a point are the angular terms of eq. 6.19 and 6.21)."""
    a, b, c = np.asarray(phi, dtype=float)
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    X = [np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]]),
         np.array([[0, 0, 0], [0, -sa, -ca], [0, ca, -sa]]),
         np.array([[0, 0, 0], [0, -ca, sa], [0, -sa, -ca]])]
    Y = [np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]]),
         np.array([[-sb, 0, cb], [0, 0, 0], [-cb, 0, -sb]]),
         np.array([[-cb, 0, -sb], [0, 0, 0], [sb, 0, -cb]])]
    Z = [np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]]),
         np.array([[-sc, -cc, 0], [cc, -sc, 0], [0, 0, 0]]),
         np.array([[-cc, sc, 0], [-sc, -cc, 0], [0, 0, 0]])]

    def prod(i: int, j: int, k: int) -> NDArray:  # derivative orders of the x, y, z factors
        return X[i] @ Y[j] @ Z[k]

    R = prod(0, 0, 0)
    dR = np.stack([prod(1, 0, 0), prod(0, 1, 0), prod(0, 0, 1)])
    d2R = np.stack([prod(2, 0, 0), prod(1, 1, 0), prod(1, 0, 1), prod(0, 2, 0), prod(0, 1, 1), prod(0, 0, 2)])
    return R, dR, d2R


def pose_matrix(p: ArrayLike) -> NDArray[np.float64]:
    """4x4 of p = (t_x, t_y, t_z, phi_x, phi_y, phi_z) with R = R_x R_y R_z."""
    p = np.asarray(p, dtype=float)
    T = np.eye(4)
    T[:3, :3] = euler_derivatives(p[3:])[0]
    T[:3, 3] = p[:3]
    return T


def skew(v: ArrayLike) -> NDArray[np.float64]:
    x, y, z = np.asarray(v, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def adjoint(T: ArrayLike) -> NDArray[np.float64]:
    """Adjoint of a 4x4 rigid transform on tangent vectors ordered (omega, v):
    T exp(xi) T^-1 = exp(Ad_T xi)."""
    T = np.asarray(T, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[3:, :3] = skew(t) @ R
    return A


def euler_to_tangent(p: ArrayLike, T0: ArrayLike) -> NDArray[np.float64]:
    """G (6, 6) with T(p + dp) T0 = T(p) T0 exp(G dp) to first order, delta = (omega, v) (right
    perturbation of the result T = T(p) T0); dp in the order of p."""
    p = np.asarray(p, dtype=float)
    R, dR, _ = euler_derivatives(p[3:])
    B = np.zeros((6, 6))
    for k in range(3):
        w = R.T @ dR[k]  # skew-symmetric: body angular rate per unit phi_k
        B[:3, 3 + k] = [w[2, 1], w[0, 2], w[1, 0]]
    B[3:, :3] = R.T
    return adjoint(np.linalg.inv(np.asarray(T0, dtype=float))) @ B


# -- voxel maps -----------------------------------------------------------------------------------
@dataclass
class VoxelMap:
    """Voxel Gaussians of a target: sorted ``keys`` (V,), ``means`` (V, D), inverse covariances
    ``icovs`` (V, D, D), ``counts`` (V,); ``tkeys``/``tvals`` the hash table (:func:`._ndt_fast.hash_build`).
    2D maps hold Biber's four grids (``shifts`` (G, 2) their origins) in one key space."""

    resolution: float
    keys: NDArray[np.int64]
    means: NDArray[np.float64]
    icovs: NDArray[np.float64]
    counts: NDArray[np.int64]
    backend: str
    shifts: NDArray[np.float64] | None = None
    tkeys: NDArray[np.int64] | None = None
    tvals: NDArray[np.int64] | None = None

    def __len__(self) -> int:
        return int(self.keys.shape[0])

    def kernel_args(self) -> tuple:
        """The map as the kernels take it: ``(tkeys, tvals, means, icovs, 1 / resolution)``."""
        return self.tkeys, self.tvals, self.means, self.icovs, 1.0 / self.resolution


def build_voxels3(points: ArrayLike, resolution: float = 1.0, min_points: int = 6, eig_ratio: float = 0.01,
                  backend: str = "auto") -> VoxelMap:
    """Magnusson's voxel Gaussians of (N, 3) target points (eq. 6.3-6.4, regularised by eq. 6.11)."""
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    pts = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
    be = resolve_backend(backend)
    fast = _fast()
    k, mu, ic, cnt = fast.gaussians(pts, fast.keys3(pts, 1.0 / resolution), int(min_points), float(eig_ratio))
    tk, tv = fast.hash_build(k)
    return VoxelMap(float(resolution), k, mu, ic, cnt, be, None, tk, tv)


def biber_shifts(resolution: float, grids: int = 4) -> NDArray[np.float64]:
    """Origins of Biber's overlapping grids: (0, 0), (r/2, 0), (0, r/2), (r/2, r/2) (first ``grids``)."""
    h = resolution / 2.0
    return np.array([[0.0, 0.0], [h, 0.0], [0.0, h], [h, h]])[:grids]


def build_voxels2(points: ArrayLike, resolution: float = 1.0, min_points: int = 3, eig_ratio: float = 1e-3,
                  grids: int = 4, backend: str = "auto") -> VoxelMap:
    """Biber's cell Gaussians of (N, 2) target points in ``grids`` (1-4) overlapping grids."""
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    if not 1 <= grids <= 4:
        raise ValueError(f"grids must be 1-4, got {grids}")
    pts = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 2))
    shifts = biber_shifts(resolution, grids)
    be = resolve_backend(backend)
    tiled = np.ascontiguousarray(np.tile(pts, (grids, 1)))
    fast = _fast()
    keys = np.concatenate([fast.keys2(pts, 1.0 / resolution, g, shifts[g, 0], shifts[g, 1]) for g in range(grids)])
    k, mu, ic, cnt = fast.gaussians(tiled, keys, int(min_points), float(eig_ratio))
    tk, tv = fast.hash_build(k)
    return VoxelMap(float(resolution), k, mu, ic, cnt, be, shifts, tk, tv)


# -- objective ------------------------------------------------------------------------------------
@dataclass
class NdtEval:
    """f (the negated NDT score), gradient g, Hessian H (in p), G the Gauss-Newton part of H
    (sum c J' Sigma^-1 J: positive semi-definite), points meeting a Gaussian, sum e*m, sum e."""

    f: float
    g: NDArray[np.float64]
    H: NDArray[np.float64]
    G: NDArray[np.float64]
    hits: int
    sem: float
    se: float


def derivatives3(points: NDArray, p: ArrayLike, vmap: VoxelMap, d1: float, d2: float,
                 offsets: NDArray[np.int64], hess: bool = True) -> NdtEval:
    """f, gradient (eq. 6.12) and Hessian (eq. 6.13) of the 3D objective at p (see the module doc);
    ``hess=False`` skips the Hessian (returned as zeros)."""
    p = np.asarray(p, dtype=float)
    R, dR, d2R = euler_derivatives(p[3:])
    f, g, H, G, hits, sem, se = _fast().derivs3(np.ascontiguousarray(points, dtype=float), (R, p[:3].copy(), dR, d2R),
                                                vmap.kernel_args(), np.ascontiguousarray(offsets, dtype=np.int64),
                                                (float(d1), float(d2)), hess)
    return NdtEval(float(f), g, H, G, int(hits), float(sem), float(se))


def derivatives2(points: NDArray, p: ArrayLike, vmap: VoxelMap) -> NdtEval:
    """Biber's objective f = -sum exp(-m/2), its gradient and Hessian at p = (t_x, t_y, phi)."""
    f, g, H, G, hits, sem, se = _fast().derivs2(np.ascontiguousarray(points, dtype=float),
                                                np.asarray(p, dtype=float), vmap.kernel_args(), vmap.shifts)
    return NdtEval(float(f), g, H, G, int(hits), float(sem), float(se))


# -- Newton's method ------------------------------------------------------------------------------
def _step(ev: NdtEval) -> NDArray[np.float64]:
    """Newton's step where H is positive definite; else the Gauss-Newton step on G (see :func:`_newton`)."""
    w, V = np.linalg.eigh(0.5 * (ev.H + ev.H.T))
    if w.min() > 1e-6 * w.max():
        return -(V / w) @ (V.T @ ev.g)
    w, V = np.linalg.eigh(0.5 * (ev.G + ev.G.T))
    w = np.maximum(w, 1e-6 * max(float(w.max()), 1e-300))
    return -(V / w) @ (V.T @ ev.g)


def _newton(evaluate, p0: NDArray, n_trans: int, max_iter: int, eps_trans: float, eps_rot: float,
            max_step_trans: float, max_step_rot: float) -> tuple[NDArray, NdtEval, int, bool]:
    """Minimise f by Newton steps, clamped and backtracked (Armijo). ``evaluate(p, hess)``;
    ``n_trans``: how many leading parameters are translations (the rest are angles).

    Far from the optimum the NDT Hessian is indefinite (points beyond their Gaussians' inflection
    add negative curvature); the step then uses G, the Hessian's Gauss-Newton part (sum c J' Sigma^-1
    J, positive semi-definite), a descent direction. Near the optimum H is positive definite and the
    step is Newton's. (On the KITTI pair and the synthetic scenes of the tests this took fewer
    evaluations than H with its eigenvalues' magnitudes, H shifted to positive definite, flipping an
    ascent direction, or Levenberg-Marquardt damping.) The first trial (the full step) is evaluated
    with the Hessian, backtracking trials without."""
    p = np.array(p0, dtype=float)
    ev = evaluate(p, True)
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        if ev.hits == 0:
            break
        dp = _step(ev)
        nt, nr = np.linalg.norm(dp[:n_trans]), np.linalg.norm(dp[n_trans:])
        dp *= min(1.0, max_step_trans / max(nt, 1e-300), max_step_rot / max(nr, 1e-300))
        slope = float(ev.g @ dp)  # < 0: a descent direction
        alpha, new = 1.0, None
        for k in range(12):
            cand = evaluate(p + alpha * dp, k == 0)
            if cand.f <= ev.f + 1e-4 * alpha * slope:
                new = cand if k == 0 else evaluate(p + alpha * dp, True)
                break
            alpha *= 0.5
        step = alpha * dp
        small = np.linalg.norm(step[:n_trans]) < eps_trans and np.linalg.norm(step[n_trans:]) < eps_rot
        if new is None:  # no decrease along the step: at the optimum, to the voxel discontinuities
            converged = bool(np.linalg.norm(dp[:n_trans]) < 10 * eps_trans
                             and np.linalg.norm(dp[n_trans:]) < 10 * eps_rot)
            break
        p, ev = p + step, new
        if small:
            converged = True
            break
    return p, ev, it, converged


def _laplace_cov(H: NDArray, sem: float, se: float, dim: int, k: float) -> NDArray[np.float64]:
    """s^2 k H^-1 with s^2 = sum e m / (dim sum e - n) (see the module doc); directions the score
    does not constrain get a huge (not infinite) variance."""
    n = H.shape[0]
    dof = dim * se - n
    if not dof > 0 or not sem > 0:
        return np.diag(np.full(n, np.inf))
    s2 = sem / dof
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    w = np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))
    return s2 * k * (V / w) @ V.T


def _congruent(G: NDArray, C: NDArray) -> NDArray[np.float64]:
    """G C G' (a covariance in other coordinates); a covariance without information stays inf."""
    if not np.all(np.isfinite(C)):
        return np.diag(np.full(C.shape[0], np.inf))
    return G @ C @ G.T


@dataclass(frozen=True)
class NdtParams:
    """3D NDT settings (metres, radians). ``resolution`` voxel side; ``outlier_ratio`` of eq. 6.7-6.8;
    ``min_points`` per voxel (PCL: 6); ``eig_ratio`` eigenvalue floor of eq. 6.11 (PCL: 0.01);
    ``neighbors`` voxels searched per point (1, 7, 27); ``max_iter`` Newton iterations; ``eps_*``
    convergence on the step; ``max_step_*`` step clamp; ``backend`` auto/numba (:func:`resolve_backend`)."""

    resolution: float = 1.0
    outlier_ratio: float = 0.55
    min_points: int = 6
    eig_ratio: float = 0.01
    neighbors: int = 7
    max_iter: int = 35
    eps_trans: float = 1e-3
    eps_rot: float = 1e-4
    max_step_trans: float = 0.5
    max_step_rot: float = 0.1
    backend: str = "auto"


@dataclass
class NdtResult:
    """``T`` (4x4) maps source points into the target frame; ``cov`` (6x6) in the right-perturbation
    tangent (omega, v) of ``T``; ``hessian`` the objective's Hessian in that tangent; ``score`` = -f
    (eq. 6.9, larger is better), ``score_per_point`` = score / source points; ``hits`` the source
    points that met a Gaussian; ``ms`` the solve (not the voxel map)."""

    T: NDArray[np.float64]
    cov: NDArray[np.float64]
    hessian: NDArray[np.float64]
    score: float
    score_per_point: float
    hits: int
    iterations: int
    converged: bool
    ms: float
    extra: dict = field(default_factory=dict)


def ndt3d(source: ArrayLike, target: ArrayLike | VoxelMap, init: ArrayLike | None = None,
          params: NdtParams | None = None) -> NdtResult:
    """Register (N, 3) ``source`` points to ``target`` ((M, 3) points, or a :class:`VoxelMap` built
    with the same ``resolution``) from the 4x4 ``init`` (identity if None)."""
    prm = params or NdtParams()
    resolve_backend(prm.backend)
    vmap = target if isinstance(target, VoxelMap) else build_voxels3(target, prm.resolution, prm.min_points,
                                                                        prm.eig_ratio, prm.backend)
    t0 = time.perf_counter()
    T0 = np.eye(4) if init is None else np.asarray(init, dtype=float).reshape(4, 4)
    src = np.asarray(source, dtype=float).reshape(-1, 3)
    x = np.ascontiguousarray(src @ T0[:3, :3].T + T0[:3, 3])
    d1, d2 = score_constants(vmap.resolution, prm.outlier_ratio)
    offs = neighbor_offsets(prm.neighbors)

    def evaluate(p: NDArray, hess: bool) -> NdtEval:
        return derivatives3(x, p, vmap, d1, d2, offs, hess)

    p, ev, it, conv = _newton(evaluate, np.zeros(6), 3, prm.max_iter, prm.eps_trans, prm.eps_rot,
                              prm.max_step_trans, prm.max_step_rot)
    T = pose_matrix(p) @ T0
    G = euler_to_tangent(p, T0)
    Gi = np.linalg.inv(G)
    cov = _congruent(G, _laplace_cov(ev.H, ev.sem, ev.se, 3, -d1 * d2))
    ms = (time.perf_counter() - t0) * 1e3
    n = max(len(src), 1)
    return NdtResult(T, 0.5 * (cov + cov.T), Gi.T @ ev.H @ Gi, -ev.f, -ev.f / n, ev.hits, it, conv, ms,
                     {"voxels": len(vmap), "d1": d1, "d2": d2, "backend": vmap.backend})


@dataclass(frozen=True)
class Ndt2Params:
    """2D NDT settings (Biber & Strasser 2003): ``resolution`` cell side [m], ``grids`` overlapping
    grids (4 in the paper), ``min_points`` per cell (3), ``eig_ratio`` (1e-3), and the Newton loop's."""

    resolution: float = 1.0
    grids: int = 4
    min_points: int = 3
    eig_ratio: float = 1e-3
    max_iter: int = 50
    eps_trans: float = 1e-4
    eps_rot: float = 1e-5
    max_step_trans: float = 0.5
    max_step_rot: float = 0.2
    backend: str = "auto"


@dataclass
class Ndt2Result:
    """``pose`` (x, y, yaw) of the source frame in the target frame; ``cov`` 3x3 in GTSAM Pose2's
    tangent (body x, y, theta); ``score`` = sum exp(-m/2); ``hits`` points that met a cell."""

    pose: NDArray[np.float64]
    cov: NDArray[np.float64]
    hessian: NDArray[np.float64]
    score: float
    hits: int
    iterations: int
    converged: bool
    ms: float


def ndt2d(source: ArrayLike, target: ArrayLike | VoxelMap, init: ArrayLike = (0.0, 0.0, 0.0),
          params: Ndt2Params | None = None) -> Ndt2Result:
    """Biber's 2D NDT: register (N, 2) ``source`` points to ``target`` ((M, 2) points or a 2D
    :class:`VoxelMap`) from ``init`` = (x, y, yaw)."""
    prm = params or Ndt2Params()
    resolve_backend(prm.backend)
    vmap = target if isinstance(target, VoxelMap) else build_voxels2(target, prm.resolution, prm.min_points,
                                                                        prm.eig_ratio, prm.grids, prm.backend)
    t0 = time.perf_counter()
    x = np.ascontiguousarray(np.asarray(source, dtype=float).reshape(-1, 2))

    def evaluate(p: NDArray, hess: bool) -> NdtEval:
        return derivatives2(x, p, vmap)

    p, ev, it, conv = _newton(evaluate, np.asarray(init, dtype=float), 2, prm.max_iter, prm.eps_trans, prm.eps_rot,
                              prm.max_step_trans, prm.max_step_rot)
    c, s = np.cos(p[2]), np.sin(p[2])
    B = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # dp -> body-frame tangent (R^T dt, dphi)
    Bi = np.linalg.inv(B)
    cov = _congruent(B, _laplace_cov(ev.H, ev.sem, ev.se, 2, 1.0))
    p[2] = wrap_angle(p[2])
    return Ndt2Result(p, 0.5 * (cov + cov.T), Bi.T @ ev.H @ Bi, -ev.f, ev.hits, it, conv,
                      (time.perf_counter() - t0) * 1e3)
