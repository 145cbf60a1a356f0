"""Scan-to-map registration of 3D clouds in KISS-ICP's structure (docs/scan-matching-3d.md,
"Scan-to-map"): each frame (levelled, filtered points, :func:`graphnav.scan.cloud_match.filter_cloud`)
is voxel-downsampled with GICP covariances and aligned to an incremental voxel-hashed local map of
the frames before it from a prediction; a matched frame is inserted into the map at its estimated
pose, voxels not seen for ``horizon`` insertions expire (LRU). Two variants over small_gicp:

* ``vgicp``: VGICP against a ``GaussianVoxelMap`` (one Gaussian per ``map_voxel`` cell): fast;
* ``gicp``: GICP against the points of an ``IncrementalVoxelMapCov`` local map (up to 20 points a
  ``map_voxel`` cell), rebuilt every ``rebuild`` frames as a target cloud: voxel-downsampled to
  ``target_voxel`` (about a frame's density), its KD-tree and GICP covariances. More accurate; the
  downsampling keeps it fast (the rebuild and the nearest-neighbour search scale with the target's
  points: 68 000 points undownsampled on the 3D harbour, 39 ms a frame; 15 ms downsampled).

:class:`CloudMap` is one registration and insertion per frame (the caller predicts);
:class:`CloudOdometry` chains it with the constant-velocity prediction, as KISS-ICP does. The poses
are 4x4 ``T_map_frame``, the map frame the levelled frame of the first frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import KNN, THREADS, OptionError, Range, check_fields
from .register3d import lsq_covariance

MIN_FRAME_POINTS = 10
"""A frame (or map) with fewer points is a failed match: the prediction stands in for it."""

VARIANTS = ("vgicp", "gicp")

_RANGES = {"voxel": Range(lo=1e-3, hi=1e3), "map_voxel": Range(lo=1e-3, hi=1e3), "knn": KNN,
           "max_corr": Range(lo=0.0, hi=1e4, lo_open=True), "max_iter": Range(lo=1, hi=100_000, integer=True),
           "horizon": Range(lo=1, hi=1_000_000, integer=True), "rebuild": Range(lo=1, hi=1_000_000, integer=True),
           "target_voxel": Range(lo=1e-3, hi=1e3, optional=True),
           "threads": THREADS}


@dataclass(frozen=True)
class CloudMapConfig:
    """Settings (metres): ``variant`` (``vgicp`` | ``gicp``), each frame's ``voxel`` and ``knn`` (GICP
    covariances), the map's ``map_voxel``, correspondences within ``max_corr``, ``max_iter``
    iterations, voxels expire after ``horizon`` insertions, the ``gicp`` target is rebuilt every
    ``rebuild`` frames from the map's points downsampled to ``target_voxel`` (None: all of them);
    ``threads``. The defaults are the best of a sweep on the 3D harbour (300 frames,
    docs/scan-matching-3d.md): the ``s2m-gicp`` method of ``graphnav scan-matching`` and the
    ``scan-to-map`` estimator's on clouds."""

    variant: str = "gicp"
    voxel: float = 0.5
    map_voxel: float = 1.0
    knn: int = 20
    max_corr: float = 1.0
    max_iter: int = 30
    horizon: int = 30
    rebuild: int = 10
    target_voxel: float | None = 0.4
    threads: int = 1

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise OptionError("cloud map variant", f"must be one of {', '.join(VARIANTS)}, got {self.variant!r}")
        check_fields(self, _RANGES, "cloud map option")


@dataclass
class MapMatch:
    """One frame's outcome: ``T`` the frame's pose in the map (the prediction when not ``matched``),
    ``inserted`` whether it joined the map (a match, or the frame that starts the map), ``cov`` the
    6x6 ``s^2 H^-1`` of the match (register3d's delta = (omega, v), None without a match), the
    inliers and iterations."""

    T: NDArray[np.float64]
    matched: bool = False
    inserted: bool = False
    cov: NDArray[np.float64] | None = None
    inliers: int = 0
    iterations: int = 0
    points: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class CloudMap:
    """The local map and the registration against it (see the module doc)."""

    def __init__(self, cfg: CloudMapConfig | None = None) -> None:
        import small_gicp

        self.cfg = cfg = cfg or CloudMapConfig()
        if cfg.variant == "vgicp":
            self.vmap: Any = small_gicp.GaussianVoxelMap(cfg.map_voxel)
        else:
            self.vmap = small_gicp.IncrementalVoxelMapCov(cfg.map_voxel)
        self.vmap.set_lru(horizon=cfg.horizon, clear_cycle=10)
        self.mapped = False
        self.frames = 0  # frames offered (the gicp target's rebuild clock)
        self._target: tuple[Any, Any] | None = None  # gicp: (PointCloud, KdTree) of the map's points

    def preprocess(self, points: NDArray[np.float64]) -> Any:
        """The frame voxel-downsampled with GICP covariances (None below :data:`MIN_FRAME_POINTS`)."""
        import small_gicp

        if len(points) < MIN_FRAME_POINTS:
            return None
        pc, _ = small_gicp.preprocess_points(np.asarray(points, dtype=np.float64), self.cfg.voxel,
                                             num_neighbors=self.cfg.knn, num_threads=self.cfg.threads)
        return pc

    def _gicp_target(self) -> tuple[Any, Any] | None:
        import small_gicp

        if self._target is None or (self.frames - 1) % self.cfg.rebuild == 1 % self.cfg.rebuild:
            points = np.asarray(self.vmap.voxel_points())[:, :3]
            if len(points) < MIN_FRAME_POINTS:
                self._target = None
                return None
            if self.cfg.target_voxel is not None:  # one point per voxel: a frame's density
                self._target = small_gicp.preprocess_points(points, self.cfg.target_voxel,
                                                            num_neighbors=self.cfg.knn, num_threads=self.cfg.threads)
                return self._target
            target = small_gicp.PointCloud(points)
            tree = small_gicp.KdTree(target, num_threads=self.cfg.threads)
            small_gicp.estimate_normals_covariances(target, tree, num_neighbors=self.cfg.knn,
                                                    num_threads=self.cfg.threads)
            self._target = (target, tree)
        return self._target

    def align(self, pc: Any, guess: NDArray[np.float64]) -> Any:
        """small_gicp's result of ``pc`` against the map from ``guess`` (None: no map, no inliers)."""
        import small_gicp

        cfg = self.cfg
        if cfg.variant == "vgicp":
            r = small_gicp.align(self.vmap, pc, guess, max_correspondence_distance=cfg.max_corr,
                                 num_threads=cfg.threads, max_iterations=cfg.max_iter)
        else:
            tgt = self._gicp_target()
            if tgt is None:
                return None
            r = small_gicp.align(tgt[0], pc, tgt[1], guess, registration_type="GICP",
                                 max_correspondence_distance=cfg.max_corr, num_threads=cfg.threads,
                                 max_iterations=cfg.max_iter)
        return r if r.num_inliers > 0 else None

    def add(self, points: NDArray[np.float64], guess: NDArray[np.float64],
            accept: Callable[[MapMatch], bool] | None = None) -> MapMatch:
        """Register the frame's ``points`` (levelled, filtered) from ``guess`` (4x4 ``T_map_frame``)
        and insert it at the result; the first usable frame starts the map at ``guess``; a frame
        that does not match (or that ``accept`` rejects) keeps ``guess`` and stays out of the map."""
        self.frames += 1
        guess = np.asarray(guess, dtype=np.float64)
        pc = self.preprocess(points)
        if pc is None:
            return MapMatch(guess.copy(), points=len(points))
        if not self.mapped:
            self.vmap.insert(pc, guess)
            self.mapped = True
            return MapMatch(guess.copy(), inserted=True, points=pc.size())
        r = self.align(pc, guess)
        if r is None:
            return MapMatch(guess.copy(), points=pc.size())
        n = int(r.num_inliers)
        m = MapMatch(np.asarray(r.T_target_source), matched=True, inserted=True, inliers=n,
                     cov=lsq_covariance(np.asarray(r.H), float(r.error), 3 * n), iterations=int(r.iterations),
                     points=pc.size())
        if accept is not None and not accept(m):
            return MapMatch(guess.copy(), inliers=n, iterations=m.iterations, points=m.points,
                            extra={"rejected": m.T})
        self.vmap.insert(pc, m.T)
        return m


class CloudOdometry:
    """Scan-to-map odometry with KISS-ICP's constant-velocity prediction: ``step(points)`` predicts
    the frame's pose as the previous pose times the last motion (or takes ``guess``), registers it
    against the map (:meth:`CloudMap.add`) and returns the match; the first frame sits at identity."""

    def __init__(self, cfg: CloudMapConfig | None = None) -> None:
        self.map = CloudMap(cfg)
        self.T = np.eye(4)
        self.delta = np.eye(4)
        self.k = 0

    def step(self, points: NDArray[np.float64], guess: NDArray[np.float64] | None = None) -> MapMatch:
        pred = self.T @ self.delta if guess is None else np.asarray(guess, dtype=np.float64)
        m = self.map.add(points, pred if self.k else np.eye(4))
        if self.k:
            self.delta, self.T = np.linalg.inv(self.T) @ m.T, m.T
        self.k += 1
        return m
