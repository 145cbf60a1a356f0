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
:class:`~graphnav.scan.cloud_match.CloudMatcher`: each cloud preprocessed once); ``s2m`` and
``s2m-gicp`` (ours, scan-to-map in KISS-ICP's structure, :mod:`graphnav.scan.cloud_map` with the
constant-velocity prediction: ``s2m`` VGICP against a ``GaussianVoxelMap``, ``s2m-gicp`` GICP
against the local map's points downsampled and rebuilt every 10 frames, the ``scan-to-map``
estimator's default on clouds); ``kiss-icp`` (the ``kiss_icp`` Python pipeline, the reference, when
installed: voxel 1 m (max range / 100, its rule), no deskewing, one thread).

Times: wall (``ms``) and CPU (``cpu_ms``, ``time.process_time``) per frame, each method one thread;
``<method>_vs_kiss`` the ratios of ``s2m`` and ``s2m-gicp`` to KISS-ICP, measured in the same run.
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
from ..scan.cloud_map import CloudMapConfig, CloudOdometry
from ..scan.cloud_match import CloudMatchConfig, CloudMatcher, filter_cloud, planar_matrix, project_se2
from ..scan.native_stderr import NativeWarnings

PAIR_METHODS = ("icp", "p2plane", "gicp", "vgicp", "ndt")
S2M = ("s2m", "s2m-gicp")
METHODS = (*PAIR_METHODS, "gicp-graph", *S2M, "kiss-icp")


def s2m_config(method: str, cfg: CloudMatchConfig) -> CloudMapConfig:
    """The scan-to-map method's settings from the shared ones: ``s2m`` VGICP on a map of twice the
    frames' voxel, LRU horizon 20; ``s2m-gicp`` :class:`~graphnav.scan.cloud_map.CloudMapConfig`'s
    defaults (the ``scan-to-map`` estimator's: GICP on the map's points downsampled to 0.8 voxels,
    rebuilt every 10 frames, map cells of two voxels, horizon 30); both correspondences within half
    the pairwise methods' ``max_corr``."""
    if method == "s2m":
        return CloudMapConfig("vgicp", cfg.voxel, 2 * cfg.voxel, cfg.knn, cfg.max_corr / 2, horizon=20,
                              target_voxel=None)
    return CloudMapConfig("gicp", cfg.voxel, 2 * cfg.voxel, cfg.knn, cfg.max_corr / 2, horizon=30, rebuild=10,
                          target_voxel=0.8 * cfg.voxel)


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


class _Times:
    """Wall and CPU (``time.process_time``: this process, every thread) ms of each timed block."""

    def __init__(self) -> None:
        self.ms: list[float] = []
        self.cpu: list[float] = []

    def __enter__(self) -> _Times:
        self._c0, self._p0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.ms.append((time.perf_counter() - self._c0) * 1e3)
        self.cpu.append((time.process_time() - self._p0) * 1e3)


def _score(name: str, rels: list[NDArray | None], times: _Times, ref: NDArray, failed: int = 0,
           tracks: bool = False) -> dict[str, Any]:
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
            "single_ms_median": float(np.median(times.ms)), "continuous_ate_m": ate,
            "continuous_ms_per_frame": float(np.mean(times.ms)),
            "continuous_cpu_ms_per_frame": float(np.mean(times.cpu)), "frames": len(ref), "failed": failed,
            **({"track": tr.tolist(), "cpu_ms": times.cpu} if tracks else {})}


def _pairwise(method: str, pts: list[NDArray], params: dict[str, Any]) -> tuple[list, _Times, int]:
    """Frame to frame; a registration that reports no convergence (NDT) counts as failed and the
    prediction stands in for it."""
    from ..scan.register3d import register

    rels, times, failed = [], _Times(), 0
    last = np.zeros(3)
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        with times:
            try:
                r = register(b, a, method, planar_matrix(*last), **params)
                p, _, _ = project_se2(r.T, r.cov) if r.converged is not False else (None, None, None)
            except (ValueError, GraphnavError):  # too few points, beyond the bound: a failed match
                p = None
        if p is None:
            failed += 1
            p = last
        rels.append(p)
        last = p
    return rels, times, failed


def _graph_matcher(clouds: list[Cloud], cfg: CloudMatchConfig, h: float | None) -> tuple[list, _Times, int]:
    m = CloudMatcher(cfg, h)
    rels, times, last, failed = [], _Times(), np.zeros(3), 0
    for a, b in zip(clouds[:-1], clouds[1:], strict=True):
        with times:
            ok, p, _ = m(b, a, last)
        if not ok:
            failed += 1
            p = last
        rels.append(p)
        last = p
    return rels, times, failed


def _chain_to_rels(poses: list[NDArray]) -> list[NDArray]:
    out = []
    for A, B in zip(poses[:-1], poses[1:], strict=True):
        p, _, _ = project_se2(np.linalg.inv(A) @ B, np.eye(6))
        out.append(p)
    return out


def _s2m(pts: list[NDArray], cfg: CloudMapConfig) -> tuple[list, _Times, int]:
    """Scan-to-map odometry (:class:`graphnav.scan.cloud_map.CloudOdometry`: each frame aligned to the
    local map from the constant-velocity prediction): the chained SE(2) increments, the times of
    each aligned frame (the first, which starts the map, is not timed) and the failures."""
    odo = CloudOdometry(cfg)
    poses, times, failed = [odo.step(pts[0]).T.copy()], _Times(), 0
    for p in pts[1:]:
        with times:
            m = odo.step(p)
        failed += not m.matched
        poses.append(m.T.copy())
    return _chain_to_rels(poses), times, failed


def _kiss(pts: list[NDArray], max_range: float) -> tuple[list, _Times]:
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
    kiss.register_frame(np.ascontiguousarray(pts[0]), np.zeros(len(pts[0])))
    poses, times = [np.asarray(kiss.last_pose).copy()], _Times()
    for p in pts[1:]:
        with times:
            kiss.register_frame(np.ascontiguousarray(p), np.zeros(len(p)))
        poses.append(np.asarray(kiss.last_pose).copy())
    return _chain_to_rels(poses), times


def compare(log: NavLog, frames: int = 100, methods: tuple[str, ...] = METHODS,
            cloud: dict[str, Any] | None = None, tracks: bool = False) -> dict[str, Any]:
    """Every method on the log's first ``frames`` clouds (see the module doc): ``methods`` keyed by
    name, each with its single-frame and continuous figures (``skipped`` with the reason when its
    library is missing); with ``tracks`` also each method's chained poses (``track``, (x, y, yaw)
    per frame), its CPU ms per frame (``cpu_ms``) and the reference poses (``reference``)."""
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
                    rels, times, failed = _pairwise(m, pts, params)
                elif m == "gicp-graph":
                    rels, times, failed = _graph_matcher(clouds, cfg, h)
                elif m in S2M:
                    rels, times, failed = _s2m(pts, s2m_config(m, cfg))
                else:
                    rels, times = _kiss(pts, cfg.max_range)
        except ImportError as exc:  # MissingExtra: the line naming the extra
            out[m] = {"skipped": str(exc)}
            continue
        out[m] = {**_score(m, rels, times, ref, failed, tracks), "native_warnings": native.count}
    res: dict[str, Any] = {"frames": len(clouds), "t0": clouds[0].t, "t1": clouds[-1].t,
                           "points_per_frame": float(np.mean([len(p) for p in pts])),
                           "filter": asdict(cfg), "sensor_height": h, "methods": out,
                           **({"reference": ref.tolist()} if tracks else {})}
    k = out.get("kiss-icp", {})
    for name in S2M:
        s = out.get(name, {})
        if k and s and "skipped" not in k and "skipped" not in s:
            res[f"{name}_vs_kiss"] = {
                "time_ratio": s["continuous_ms_per_frame"] / k["continuous_ms_per_frame"],
                "cpu_ratio": s["continuous_cpu_ms_per_frame"] / k["continuous_cpu_ms_per_frame"],
                "ate_ratio": s["continuous_ate_m"] / max(k["continuous_ate_m"], 1e-12)}
    return res
