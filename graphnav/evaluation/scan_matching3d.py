"""The scan-matching paper's comparison on a log's clouds (``graphnav scan-matching LOG``; docs/
scan-matching-3d.md, "The comparison on the 3D harbour").

Every method gets the same frames: the first ``frames`` clouds with a reference pose, levelled and
filtered as the graph's matcher does (:func:`graphnav.scan.cloud_match.filter_cloud`). Per method:

* **single-frame**: each consecutive pair registered from the constant-velocity prediction (the
  previous pair's estimate; identity for the first), its planar part ``(x, y, yaw)`` against the
  reference's relative pose: RMS translation [m] and rotation [deg] error, median time per frame;
* **continuous**: the estimates chained from the first reference pose: ATE [m] (RMS, unaligned)
  against the reference, mean time per frame.

A registration that fails (not converged, too few points) counts in ``failed``; the prediction
stands in for it in both figures.

Methods: register3d's ``icp``, ``p2plane``, ``gicp``, ``vgicp``, ``ndt`` (frame to frame, each pair
preprocessed from scratch, as ``graphnav register`` does); ``gicp-graph`` (the graph's
:class:`~graphnav.scan.cloud_match.CloudMatcher`: each cloud preprocessed once); ``s2m`` (ours,
scan-to-map: small_gicp VGICP of each frame against an incremental voxel-hashed local map,
``GaussianVoxelMap`` with LRU expiry, KISS-ICP's structure); ``s2m-gicp`` (scan-to-map GICP against
the points of an ``IncrementalVoxelMapCov`` local map, its KdTree and covariances rebuilt every
``rebuild`` frames: more accurate, slower); ``kiss-icp`` (the ``kiss_icp`` Python
pipeline, the reference, when installed: voxel 1 m (max range / 100, its rule), no deskewing, one
thread).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import GraphnavError
from ..log import Cloud, NavLog
from ..scan.cloud_match import CloudMatchConfig, CloudMatcher, filter_cloud, planar_matrix, project_se2
from ..scan.native_stderr import NativeWarnings

PAIR_METHODS = ("icp", "p2plane", "gicp", "vgicp", "ndt")
METHODS = (*PAIR_METHODS, "gicp-graph", "s2m", "s2m-gicp", "kiss-icp")


def _frames(log: NavLog, n: int, cfg: CloudMatchConfig) -> tuple[list[Cloud], list[NDArray], NDArray]:
    """Clouds with a reference pose within 20 ms (the first ``n``), their filtered levelled points and
    the reference poses (N, 3)."""
    truth = log.truth()
    tt, tp = np.asarray(truth.t), np.asarray(truth.poses)
    if len(tt) == 0:
        raise ValueError("the log has no truth records: nothing to score the methods against")
    h = log.meta.get("lidar3d", {}).get("mast") if isinstance(log.meta.get("lidar3d"), dict) else None
    clouds, pts, ref = [], [], []
    for c in log.of("cloud"):
        i = int(np.clip(np.searchsorted(tt, c.t), 1, len(tt) - 1))
        j = i - 1 if abs(tt[i - 1] - c.t) <= abs(tt[i] - c.t) else i
        if abs(tt[j] - c.t) > 0.02:
            continue
        p, _ = filter_cloud(c, cfg, h)
        clouds.append(c)
        pts.append(p)
        ref.append(tp[j])
        if len(clouds) >= n:
            break
    if len(clouds) < 2:
        raise ValueError("fewer than two clouds with a reference pose")
    return clouds, pts, np.array(ref)


def _rel(a: NDArray, b: NDArray) -> NDArray:
    """Planar relative pose a -> b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    d = b[:2] - a[:2]
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], (b[2] - a[2] + math.pi) % (2 * math.pi) - math.pi])


def _compose(a: NDArray, r: NDArray) -> NDArray:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * r[0] - s * r[1], a[1] + s * r[0] + c * r[1], a[2] + r[2]])


def _score(name: str, rels: list[NDArray | None], ms: list[float], ref: NDArray, failed: int = 0) -> dict[str, Any]:
    et, er = [], []
    pose = ref[0].copy()
    traj = [pose]
    for k, r in enumerate(rels):
        if r is None or not np.all(np.isfinite(r)):
            failed += 1
            r = np.zeros(3)
        d = _rel(ref[k], ref[k + 1])
        e = _rel(d, r)
        et.append(math.hypot(e[0], e[1]))
        er.append(abs(math.degrees(e[2])))
        pose = _compose(pose, r)
        traj.append(pose)
    tr = np.array(traj)
    ate = float(np.sqrt(np.mean(np.sum((tr[:, :2] - ref[:, :2]) ** 2, axis=1))))
    return {"single_trans_rmse_m": float(np.sqrt(np.mean(np.square(et)))),
            "single_rot_rmse_deg": float(np.sqrt(np.mean(np.square(er)))),
            "single_ms_median": float(np.median(ms)), "continuous_ate_m": ate,
            "continuous_ms_per_frame": float(np.mean(ms)), "frames": len(ref), "failed": failed}


def _pairwise(method: str, pts: list[NDArray], params: dict[str, Any]) -> tuple[list, list, int]:
    """Frame to frame; a registration that reports no convergence (NDT) counts as failed and the
    prediction stands in for it."""
    from ..scan.register3d import register

    rels, ms, failed = [], [], 0
    last = np.zeros(3)
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        c0 = time.perf_counter()
        try:
            r = register(b, a, method, planar_matrix(*last), **params)
            p, _, _ = project_se2(r.T, r.cov) if r.converged is not False else (None, None, None)
        except (ValueError, GraphnavError):  # too few points, beyond the bound: a failed match
            p = None
        ms.append((time.perf_counter() - c0) * 1e3)
        if p is None:
            failed += 1
            p = last
        rels.append(p)
        last = p
    return rels, ms, failed


def _graph_matcher(clouds: list[Cloud], cfg: CloudMatchConfig, h: float | None) -> tuple[list, list, int]:
    m = CloudMatcher(cfg, h)
    rels, ms, last, failed = [], [], np.zeros(3), 0
    for a, b in zip(clouds[:-1], clouds[1:], strict=True):
        c0 = time.perf_counter()
        ok, p, _ = m(b, a, last)
        ms.append((time.perf_counter() - c0) * 1e3)
        if not ok:
            failed += 1
            p = last
        rels.append(p)
        last = p
    return rels, ms, failed


def _chain_to_rels(poses: list[NDArray]) -> list[NDArray]:
    out = []
    for A, B in zip(poses[:-1], poses[1:], strict=True):
        p, _, _ = project_se2(np.linalg.inv(A) @ B, np.eye(6))
        out.append(p)
    return out


MIN_FRAME_POINTS = 10
"""A scan-to-map frame (or map) with fewer points is a failed match: the prediction stands in for it."""


def _odometry_loop(pts: list[NDArray], voxel: float, knn: int, align: Any, vmap: Any) -> tuple[list, list, int]:
    """The scan-to-map loop both variants share: each frame voxel-downsampled (GICP covariances),
    aligned by ``align(k, frame, guess) -> T or None`` (None: no match) from the constant-velocity
    prediction (not the first), inserted into ``vmap`` at its estimated pose; a frame of fewer than
    :data:`MIN_FRAME_POINTS` points, or one ``align`` finds no match for, is failed: the prediction
    stands in and it is not inserted. Returns the chained SE(2) increments, the ms per aligned frame
    and the failures."""
    import small_gicp

    T, delta = np.eye(4), np.eye(4)
    poses, ms, failed, mapped = [], [], 0, False
    for k, p in enumerate(pts):
        c0 = time.perf_counter()
        pc = None
        if len(p) >= MIN_FRAME_POINTS:
            pc, _ = small_gicp.preprocess_points(p, voxel, num_neighbors=knn, num_threads=1)
        matched = k == 0
        if k:
            new = align(k, pc, T @ delta) if pc is not None and mapped else None
            matched = new is not None
            if new is None:
                failed += 1
                new = T @ delta
            delta, T = np.linalg.inv(T) @ new, new
        if pc is not None and (matched or not mapped):  # (the first usable frame starts the map)
            vmap.insert(pc, T)
            mapped = True
        if k:
            ms.append((time.perf_counter() - c0) * 1e3)
        poses.append(T.copy())
    return _chain_to_rels(poses), ms, failed


def _s2m(pts: list[NDArray], voxel: float, map_voxel: float, knn: int, max_corr: float) -> tuple[list, list, int]:
    """Scan-to-map: each frame (voxel-downsampled, GICP covariances) VGICP-aligned to a voxel-hashed
    local map of the frames before it (inserted at their estimated poses; voxels unseen for 20
    insertions expire) from the constant-velocity prediction."""
    import small_gicp

    vmap = small_gicp.GaussianVoxelMap(map_voxel)
    vmap.set_lru(horizon=20, clear_cycle=10)

    def align(k: int, pc: Any, guess: NDArray) -> NDArray | None:
        r = small_gicp.align(vmap, pc, guess, max_correspondence_distance=max_corr, num_threads=1, max_iterations=30)
        return np.asarray(r.T_target_source) if r.num_inliers > 0 else None

    return _odometry_loop(pts, voxel, knn, align, vmap)


def _s2m_gicp(pts: list[NDArray], voxel: float, map_voxel: float, knn: int, max_corr: float, rebuild: int = 10,
              horizon: int = 30) -> tuple[list, list, int]:
    """Scan-to-map GICP: the target is the local map's voxel points (``IncrementalVoxelMapCov``, LRU
    expiry after ``horizon`` insertions) with fresh GICP covariances, rebuilt every ``rebuild`` frames."""
    import small_gicp

    vm = small_gicp.IncrementalVoxelMapCov(map_voxel)
    vm.set_lru(horizon=horizon, clear_cycle=10)
    built: list[Any] = []  # (target, tree), rebuilt every `rebuild` frames

    def align(k: int, pc: Any, guess: NDArray) -> NDArray | None:
        if not built or k % rebuild == 1:
            points = np.asarray(vm.voxel_points())[:, :3]
            if len(points) < MIN_FRAME_POINTS:
                built.clear()
                return None
            target = small_gicp.PointCloud(points)
            tree = small_gicp.KdTree(target)
            small_gicp.estimate_normals_covariances(target, tree, num_neighbors=knn)
            built[:] = [target, tree]
        r = small_gicp.align(built[0], pc, built[1], guess, registration_type="GICP",
                             max_correspondence_distance=max_corr, num_threads=1, max_iterations=30)
        return np.asarray(r.T_target_source) if r.num_inliers > 0 else None

    return _odometry_loop(pts, voxel, knn, align, vm)


def _kiss(pts: list[NDArray], max_range: float) -> tuple[list, list]:
    from ..errors import require

    KISSConfig = require("kiss_icp.config", "the kiss-icp reference").KISSConfig
    KissICP = require("kiss_icp.kiss_icp", "the kiss-icp reference").KissICP

    cfg = KISSConfig()
    cfg.data.max_range = max_range
    cfg.data.min_range = 0.0
    cfg.data.deskew = False
    cfg.mapping.voxel_size = max_range / 100.0
    cfg.registration.max_num_threads = 1
    kiss = KissICP(cfg)
    poses, ms = [], []
    for k, p in enumerate(pts):
        c0 = time.perf_counter()
        kiss.register_frame(np.ascontiguousarray(p), np.zeros(len(p)))
        if k:
            ms.append((time.perf_counter() - c0) * 1e3)
        poses.append(np.asarray(kiss.last_pose).copy())
    return _chain_to_rels(poses), ms


def compare(log: NavLog, frames: int = 100, methods: tuple[str, ...] = METHODS,
            cloud: dict[str, Any] | None = None) -> dict[str, Any]:
    """Every method on the log's first ``frames`` clouds (see the module doc): ``methods`` keyed by
    name, each with its single-frame and continuous figures (``skipped`` with the reason when its
    library is missing)."""
    bad = sorted(set(methods) - set(METHODS))
    if bad:
        raise ValueError(f"unknown method(s) {', '.join(bad)}; known: {', '.join(METHODS)}")
    cfg = CloudMatchConfig.from_options(dict(cloud or {}))
    clouds, pts, ref = _frames(log, frames, cfg)
    h = log.meta.get("lidar3d", {}).get("mast") if isinstance(log.meta.get("lidar3d"), dict) else None
    params = {"voxel": cfg.voxel, "max_corr": cfg.max_corr, "knn": cfg.knn, "resolution": 2 * cfg.voxel}
    out: dict[str, Any] = {}
    for m in methods:
        try:
            with NativeWarnings(m) as native:
                failed = 0
                if m in PAIR_METHODS:
                    if m == "ndt":  # the compiled kernels' one-off load is not a registration's time
                        from ..scan.ndt import warm_up

                        warm_up()
                    rels, ms, failed = _pairwise(m, pts, params)
                elif m == "gicp-graph":
                    rels, ms, failed = _graph_matcher(clouds, cfg, h)
                elif m == "s2m":
                    rels, ms, failed = _s2m(pts, cfg.voxel, 2 * cfg.voxel, cfg.knn, cfg.max_corr / 2)
                elif m == "s2m-gicp":
                    rels, ms, failed = _s2m_gicp(pts, cfg.voxel, cfg.voxel, cfg.knn, cfg.max_corr / 2)
                else:
                    rels, ms = _kiss(pts, cfg.max_range)
        except ImportError as exc:  # MissingExtra: the line naming the extra
            out[m] = {"skipped": str(exc)}
            continue
        out[m] = {**_score(m, rels, ms, ref, failed), "native_warnings": native.count}
    res: dict[str, Any] = {"frames": len(clouds), "t0": clouds[0].t, "t1": clouds[-1].t,
                           "points_per_frame": float(np.mean([len(p) for p in pts])),
                           "filter": asdict(cfg), "sensor_height": h, "methods": out}
    if "kiss-icp" in out and "s2m" in out and "skipped" not in out["kiss-icp"] and "skipped" not in out["s2m"]:
        k, s = out["kiss-icp"], out["s2m"]
        res["s2m_vs_kiss"] = {"time_ratio": s["continuous_ms_per_frame"] / k["continuous_ms_per_frame"],
                              "ate_ratio": s["continuous_ate_m"] / max(k["continuous_ate_m"], 1e-12)}
    return res
