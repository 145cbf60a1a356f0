"""Consecutive 3D clouds -> planar relative poses for the 2D graph (docs/scan-matching-3d.md, "3D in
the graph").

1. **Level** each cloud with its own attitude (the record's ``roll``/``pitch``, an AHRS's; 0 when
   absent): ``p_l = R_y(pitch) R_x(roll) p_s`` (docs/conventions.md), a frame with the sensor's yaw
   and a vertical z.
2. **Water/spray filter** (:func:`filter_cloud`): keep a point when its range is in
   ``[min_range, max_range]`` (spray and the hull's own returns are close; ``min_range`` 4 m) and,
   when the sensor's height above the water is known (``sensor_height``: the option, else the log's
   ``meta["lidar3d"]["mast"]``), its levelled height is above the water plus ``water_margin``
   (``z_l > -sensor_height + water_margin``; 0.6 m: four sigmas of 0.15 m waves). A water return
   is a point on the sea surface: it moves with the waves and is no landmark.
3. **GICP** (small_gicp, as :func:`graphnav.scan.register3d.register` runs it: voxel-downsampled
   points, ``knn`` covariances; each cloud is preprocessed once and kept as the next target) from
   the prediction (odometry, as a planar 4x4), giving ``T_prev_cur`` (levelled frames); the 6x6
   covariance from the match's own residuals (:func:`match_covariance`: a cluster-robust sandwich
   plus the voxel quantisation; register3d's convention: delta = (omega, v) in the current, source,
   frame, right perturbation -- the tangent of a Pose3 between factor).
4. **SE(2) projection**: ``(x, y, yaw)`` of ``T`` (translation and the rotation's heading) and the
   marginal covariance of ``(v_x, v_y, omega_z)`` -- the sub-block of the 6x6 covariance, which is
   the marginal of a Gaussian (rows/columns 3, 4, 2). In the levelled frames that is the planar
   motion; ``z``, ``roll`` and ``pitch`` of ``T`` (the residual attitude change the AHRS did not
   explain, and the heave) are kept as diagnostics (:attr:`CloudMatcher.last`).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import FRACTION, KNN, THREADS, OptionError, Range, check_fields
from ..log import Cloud
from ._kdtree import cKDTree
from .native_stderr import NativeWarnings
from .register3d import gicp_terms, sandwich_covariance

IDX_SE2 = [3, 4, 2]  # (v_x, v_y, omega_z) in register3d's delta = (omega, v)


_CLOUD_RANGES = {"min_range": Range(lo=0.0, hi=1e4), "max_range": Range(lo=0.0, hi=1e4, lo_open=True),
                 "water_margin": Range(lo=-1e3, hi=1e3), "sensor_height": Range(lo=-1e3, hi=1e3, optional=True),
                 "min_intensity": Range(optional=True), "voxel": Range(lo=1e-3, hi=1e3),
                 "knn": KNN, "max_corr": Range(lo=0.0, hi=1e4, lo_open=True),
                 "max_iter": Range(lo=1, hi=100_000, integer=True), "threads": THREADS,
                 "min_points": Range(lo=7, hi=10_000_000, integer=True), "min_inliers": FRACTION,
                 "cov_cluster": Range(lo=0.0, hi=1e4, lo_open=True, optional=True)}
"""Each numeric :class:`CloudMatchConfig` field's declared range (checked on construction)."""


@dataclass(frozen=True)
class CloudMatchConfig:
    """Settings of the cloud matcher (metres, radians): the filter's ``min_range``, ``max_range``,
    ``water_margin``, ``sensor_height`` (None: the log's ``meta["lidar3d"]["mast"]``, else the
    height gate is off), ``min_intensity`` (None: no intensity gate); GICP's ``voxel``, ``knn``,
    ``max_corr``, ``max_iter``, ``threads``; a match needs ``min_points`` filtered points on each side
    and an inlier fraction of at least ``min_inliers``."""

    min_range: float = 4.0
    max_range: float = 100.0
    water_margin: float = 0.6
    sensor_height: float | None = None
    min_intensity: float | None = None
    voxel: float = 0.5
    knn: int = 20  # 10 (register3d's) takes neighbours along one ring of a 16-beam sensor: line-like
    #                covariances, and GICP pulls the ring pattern (which moves with the sensor) to zero
    #                motion: -1.6 cm of 15 cm a frame on harbour3d; 20 reaches the next ring: -0.1 cm
    max_corr: float = 2.0
    max_iter: int = 30
    threads: int = 1
    min_points: int = 100
    min_inliers: float = 0.3
    cov_cluster: float | None = None  # cell [m] of the sandwich's clusters (None: the knn neighbourhood's)
    cov_quantisation: bool = True  # the voxel quantisation term of the covariance

    def __post_init__(self) -> None:
        check_fields(self, _CLOUD_RANGES, "cloud option")
        if self.max_range <= self.min_range:
            raise OptionError("cloud option max_range", f"must exceed min_range ({self.min_range:g}), "
                                                        f"got {self.max_range:g}")
        for name in ("cov_quantisation",):
            if not isinstance(getattr(self, name), bool):
                raise OptionError(f"cloud option {name}", f"must be true or false, got {getattr(self, name)!r}")

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> CloudMatchConfig:
        known = set(cls.__dataclass_fields__)
        if not isinstance(options, dict):
            raise OptionError("option cloud", f"must be a table of cloud options, got {options!r:.60}")
        bad = sorted(set(options) - known)
        if bad:
            raise ValueError(f"unknown cloud option(s) {', '.join(bad)}; known: {', '.join(sorted(known))}")
        return cls(**options)


def level_rotation(roll: float, pitch: float) -> NDArray[np.float64]:
    """``R_y(pitch) R_x(roll)``: sensor frame -> levelled frame (NaN angles count as 0)."""
    r = 0.0 if not math.isfinite(roll) else roll
    p = 0.0 if not math.isfinite(pitch) else pitch
    cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
    return np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])


def filter_cloud(c: Cloud, cfg: CloudMatchConfig, sensor_height: float | None = None
                 ) -> tuple[NDArray[np.float64], dict[str, int]]:
    """The levelled points the matcher uses and what each gate removed (see the module doc)."""
    p = c.points.astype(np.float64) @ level_rotation(c.roll, c.pitch).T
    r = np.linalg.norm(p, axis=1)
    keep = (r >= cfg.min_range) & (r <= cfg.max_range)
    stats = {"points": len(p), "range_gate": int((~keep).sum())}
    h = cfg.sensor_height if cfg.sensor_height is not None else sensor_height
    if h is not None:
        low = keep & (p[:, 2] <= -h + cfg.water_margin)
        stats["height_gate"] = int(low.sum())
        keep &= ~low
    if cfg.min_intensity is not None and c.intensity is not None:
        dim = keep & (c.intensity < cfg.min_intensity)
        stats["intensity_gate"] = int(dim.sum())
        keep &= ~dim
    stats["kept"] = int(keep.sum())
    return p[keep], stats


def planar_matrix(x: float, y: float, yaw: float) -> NDArray[np.float64]:
    """The 4x4 of a planar motion (z, roll, pitch 0)."""
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = [x, y]
    return T


def project_se2(T: NDArray[np.float64], cov6: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], dict[str, float]]:
    """``(x, y, yaw)`` of a 4x4, the marginal 3x3 covariance of ``(v_x, v_y, omega_z)`` from the 6x6
    (delta = (omega, v)), and the dropped coordinates ``z``, ``roll``, ``pitch`` (ZYX Euler)."""
    R = T[:3, :3]
    yaw = math.atan2(R[1, 0], R[0, 0])
    pitch = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    roll = math.atan2(R[2, 1], R[2, 2])
    cov = np.asarray(cov6, dtype=float)[np.ix_(IDX_SE2, IDX_SE2)]
    return np.array([T[0, 3], T[1, 3], yaw]), 0.5 * (cov + cov.T), {"z": float(T[2, 3]), "roll": roll, "pitch": pitch}


def match_covariance(s_pc: Any, t_pc: Any, t_kd: cKDTree, T: NDArray[np.float64], max_corr: float,
                     voxel: float, cell: float, quantisation: bool = True) -> NDArray[np.float64]:
    """The 6x6 covariance of a GICP match from the match itself (docs/scan-matching-3d.md, "Covariance"):
    the source's points paired with their nearest target point within ``max_corr`` at ``T`` (GICP's
    correspondences), GICP's residuals, Jacobians and weights
    (:func:`graphnav.scan.register3d.gicp_terms`), and the sandwich
    (:func:`graphnav.scan.register3d.sandwich_covariance`)::

        cov = H^-1 B H^-1,  H = sum J' M J,  B = sum_c g_c g_c' + sum J' M (2 voxel^2 / 12 I) M J

    ``g_c`` the residual score of the source points in a cell of side ``cell``
    (:func:`neighbourhood_cell`: pairs whose target covariances share neighbours are one cluster); the
    second term the voxel downsampling's quantisation: each point of
    either cloud is the centroid of the returns in its voxel, an error of up to half a voxel either way
    that the residuals of one match do not show (uniform, variance ``voxel^2 / 12`` per axis and cloud;
    Widrow & Kollar 2008, ch. 4), independent from voxel to voxel -- the 3D counterpart of the 2D
    matcher's sampling term (:mod:`graphnav.scan.covariance`)."""
    sp = np.asarray(s_pc.points())[:, :3]
    tp = np.asarray(t_pc.points())[:, :3]
    d, idx = t_kd.query(sp @ T[:3, :3].T + T[:3, 3], distance_upper_bound=max_corr)
    ok = np.isfinite(d)
    if ok.sum() <= 6:
        return np.diag(np.full(6, np.inf))
    cs, ct = np.asarray(s_pc.covs())[ok, :3, :3], np.asarray(t_pc.covs())[idx[ok], :3, :3]
    r, J, M = gicp_terms(sp[ok], tp[idx[ok]], T, cs, ct)
    cells = np.floor(sp[ok] / cell).astype(np.int64)
    groups = np.unique(cells, axis=0, return_inverse=True)[1].ravel()
    q = np.broadcast_to(2.0 * voxel**2 / 12.0 * np.eye(3), r.shape + (3,)) if quantisation else None
    return sandwich_covariance(J, M, r, groups, q)


def neighbourhood_cell(kd: cKDTree, knn: int) -> float:
    """The median diameter of a cloud's ``knn`` neighbourhoods (twice the distance to the knn-th
    neighbour): the extent over which GICP's local covariances, and so the residuals, are shared."""
    return 2.0 * float(np.median(kd.query(kd.data, k=[knn])[0]))


class CloudMatcher:
    """``match(cur, prev, init) -> (usable, (x, y, yaw), 3x3 cov)``, the builder's matcher signature
    (``init`` the predicted planar motion prev -> cur); :attr:`last` holds the newest match's
    diagnostics (z, roll, pitch, the 6x6 covariance's planar block, filter counts, ms)."""

    def __init__(self, cfg: CloudMatchConfig, sensor_height: float | None = None) -> None:
        self.cfg = cfg
        self.sensor_height = sensor_height
        self._cache: tuple[Cloud, Any, Any] | None = None  # the previous cloud, preprocessed
        self.last: dict[str, Any] = {}

    def prepare(self, c: Cloud) -> tuple[Any, Any, dict[str, int]]:
        import small_gicp

        pts, stats = filter_cloud(c, self.cfg, self.sensor_height)
        if len(pts) < self.cfg.min_points:
            return None, None, stats
        pc, tree = small_gicp.preprocess_points(pts, self.cfg.voxel, num_neighbors=self.cfg.knn,
                                                num_threads=self.cfg.threads)
        kd = cKDTree(np.asarray(pc.points())[:, :3])
        return pc, (tree, kd, self.cfg.cov_cluster or neighbourhood_cell(kd, self.cfg.knn)), stats

    def __call__(self, cur: Cloud, prev: Cloud, init: NDArray[np.float64] | None
                 ) -> tuple[bool, NDArray[np.float64], NDArray[np.float64]]:
        with NativeWarnings("small_gicp") as native:  # its C++ warnings: counted, logged once, not raw
            out = self._match(cur, prev, init)
        self.last["native_warnings"] = native.count
        return out

    def _match(self, cur: Cloud, prev: Cloud, init: NDArray[np.float64] | None
               ) -> tuple[bool, NDArray[np.float64], NDArray[np.float64]]:
        import small_gicp

        cfg = self.cfg
        c0 = time.perf_counter()
        if self._cache is not None and self._cache[0] is prev:
            t_pc, t_tree = self._cache[1], self._cache[2]
        else:
            t_pc, t_tree, _ = self.prepare(prev)
        s_pc, s_tree, stats = self.prepare(cur)
        self._cache = (cur, s_pc, s_tree)
        nan3 = np.full(3, np.nan)
        if t_pc is None or s_pc is None:
            self.last = {"ok": False, "why": "too few points after the filter", "filter": stats}
            return False, nan3, np.full((3, 3), np.nan)
        T0 = planar_matrix(*init) if init is not None else np.eye(4)
        r = small_gicp.align(t_pc, s_pc, t_tree[0], T0, registration_type="GICP",
                             max_correspondence_distance=cfg.max_corr,
                             num_threads=cfg.threads, max_iterations=cfg.max_iter)
        T = np.asarray(r.T_target_source)
        cov6 = match_covariance(s_pc, t_pc, t_tree[1], T, cfg.max_corr, cfg.voxel, t_tree[2], cfg.cov_quantisation)
        pose, cov, diag = project_se2(T, cov6)
        inl = int(r.num_inliers) / max(s_pc.size(), 1)
        ok = bool(r.converged) and inl >= cfg.min_inliers and np.all(np.isfinite(cov))
        self.last = {"ok": ok, "inliers": inl, "iterations": int(r.iterations), **diag, "filter": stats,
                     "ms": (time.perf_counter() - c0) * 1e3}
        return ok, pose, cov

    def config(self) -> dict[str, Any]:
        return {**asdict(self.cfg), "sensor_height_used": self.cfg.sensor_height if self.cfg.sensor_height is not None
                else self.sensor_height}
