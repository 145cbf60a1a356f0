"""Scan-to-map LiDAR odometry on 3D clouds: the ``scan-to-map`` estimator on a log with ``cloud``
records (docs/scan-matching-3d.md, "Scan-to-map").

Each cloud at or after the anchor is levelled and filtered as the graph's matcher does
(:func:`graphnav.scan.cloud_match.filter_cloud`: its own roll/pitch, the range and water gates; the
``cloud`` option) and registered against the KISS-ICP style local voxel map of the clouds before it
(:class:`graphnav.scan.cloud_map.CloudMap`; the ``cloud_map`` option) from a prediction: the odometry
increment when the log has odometry (``predict="odometry"``), else the IMU's
(:class:`graphnav.scan.imu_guess.ImuGuess`, its velocity corrected by every match), else constant
velocity. A match farther than ``max_correction`` from the prediction, or with an inlier fraction
below ``min_fitness``, is rejected: the prediction stands and the cloud stays out of the map. The
map's frame is the first cloud's levelled frame placed at the start pose (the graph's anchor:
:func:`graphnav.estimators.start.log_start`; the IMU's start velocity is taken into the body frame
of its yaw); the trajectory is each cloud's planar pose ``(x, y, yaw)`` in it -- odometry, so it
drifts, and the start pose's error (its heading's above all) stays in it.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict
from typing import Any

import numpy as np

from ..errors import GraphnavError
from ..geometry import increment, se2_between, se2_compose
from ..log import Cloud, NavLog, odometry_samples
from ..result import OnEstimate, RunResult
from ..scan.cloud_map import MIN_FRAME_POINTS, CloudMap, CloudMapConfig, MapMatch
from ..scan.cloud_match import CloudMatchConfig, filter_cloud, planar_matrix, project_se2
from ..scan.imu_guess import ImuGuess, log_imu_guess
from ..scan.native_stderr import NativeWarnings
from ..trajectory import Trajectory


def usable_clouds(log: NavLog) -> int:
    """How many of the log's clouds hold enough points to register."""
    return sum(1 for c in log.of("cloud") if len(c.points) >= MIN_FRAME_POINTS)


def cloud_configs(cloud: Any, cloud_map: Any) -> tuple[CloudMatchConfig, CloudMapConfig]:
    """The filter's and the map's settings from the ``cloud`` and ``cloud_map`` options (unknown keys
    and bad values: an error naming them)."""
    if not isinstance(cloud_map, dict):
        raise GraphnavError(f"must be a table of cloud map options, got {cloud_map!r:.60}", where="option cloud_map")
    known = set(CloudMapConfig.__dataclass_fields__)
    bad = sorted(set(cloud_map) - known)
    if bad:
        raise GraphnavError(f"unknown cloud_map option(s) {', '.join(bad)}; known: {', '.join(sorted(known))}",
                            where="option cloud_map")
    return CloudMatchConfig.from_options(cloud), CloudMapConfig(**cloud_map)


def _planar(T: np.ndarray) -> np.ndarray:
    return np.array([T[0, 3], T[1, 3], math.atan2(T[1, 0], T[0, 0])])


class CloudGuess:
    """Each cloud's predicted planar motion from the previous one: the odometry increment
    (``predict="odometry"`` and the log has odometry), else the IMU's (corrected by every match),
    else constant velocity over the last two poses; ``sources`` counts which gave each guess."""

    def __init__(self, log: NavLog, predict: str, yaw0: float) -> None:
        self.odo = odometry_samples(log) if predict == "odometry" else np.zeros((0, 5))
        self.imu: ImuGuess | None = None
        if predict == "imu" or (predict == "odometry" and not len(self.odo)):
            self.imu = log_imu_guess(log, yaw0)
        self.sources: dict[str, int] = {}

    def guess(self, ts: list[float], rel: list[np.ndarray], t: float) -> np.ndarray:
        """The increment from the pose at ``ts[-1]`` (planar poses ``rel``) to the cloud at ``t``."""
        inc = increment(self.odo, ts[-1], t) if len(self.odo) else None
        imu_inc = self.imu.guess(ts[-1], t) if self.imu is not None and inc is None else None
        if inc is not None:
            step, source = inc[0], "odometry"
        elif imu_inc is not None:
            step, source = imu_inc[0], "imu"
        elif len(rel) >= 2 and ts[-1] > ts[-2]:
            step, source = se2_between(rel[-2], rel[-1]) * ((t - ts[-1]) / (ts[-1] - ts[-2])), "cv"
        else:
            step, source = np.zeros(3), "none"
        self.sources[source] = self.sources.get(source, 0) + 1
        return np.asarray(step, dtype=float)

    def update(self, t0: float, t1: float, prev: np.ndarray, m: MapMatch) -> None:
        """The IMU's velocity corrected by the match (the prediction carried on without one)."""
        if self.imu is None:
            return
        ok = m.matched and m.cov is not None and bool(np.all(np.isfinite(m.cov)))
        cov = project_se2(m.T, m.cov)[1] if ok and m.cov is not None else None
        self.imu.update(t0, t1, se2_between(prev, _planar(m.T)) if ok else None, cov)


def run_scan_to_map3d(log: NavLog, pose0: np.ndarray, *, predict: str, max_correction: float, min_fitness: float,
                      cloud: Any, cloud_map: Any, t_anchor: float = -np.inf,
                      on_estimate: OnEstimate | None = None) -> RunResult:
    """The 3D path of :func:`graphnav.estimators.scan_to_map.run_scan_to_map` (see the module doc)."""
    fcfg, mcfg = cloud_configs(cloud, cloud_map)
    lidar = log.meta.get("lidar3d") if isinstance(log.meta, dict) else None
    height = float(lidar["mast"]) if isinstance(lidar, dict) and lidar.get("mast") is not None else None
    clouds: list[Cloud] = [c for c in log.of("cloud") if c.t >= t_anchor - 1e-6]
    predictor = CloudGuess(log, predict, float(pose0[2]))
    cmap = CloudMap(mcfg)
    ts: list[float] = []
    rel: list[np.ndarray] = []  # planar poses in the map frame
    icp_ms: list[float] = []
    step_ms: list[float] = []
    matches: list[MapMatch] = []
    pred = T = np.eye(4)

    def accept(m: MapMatch) -> bool:
        jump = float(np.hypot(*(m.T[:2, 3] - pred[:2, 3])))
        return jump <= max_correction and m.inliers >= min_fitness * max(m.points, 1)

    with NativeWarnings("small_gicp") as native:
        for c in clouds:
            c0 = time.perf_counter()
            pts, _ = filter_cloud(c, fcfg, height)
            pred = T @ planar_matrix(*predictor.guess(ts, rel, c.t)) if ts else np.eye(4)
            t_reg = time.perf_counter()
            m = cmap.add(pts, pred, accept)
            this_icp = (time.perf_counter() - t_reg) * 1e3
            if ts:
                icp_ms.append(this_icp)
                matches.append(m)
                predictor.update(ts[-1], c.t, rel[-1], m)
            T = m.T
            ts.append(c.t)
            rel.append(_planar(T))
            step_ms.append((time.perf_counter() - c0) * 1e3 - this_icp)
            if on_estimate is not None:
                on_estimate(c.t, se2_compose(pose0, rel[-1]), None)
    poses = np.array([se2_compose(pose0, p) for p in rel]).reshape(-1, 3)
    traj = Trajectory(np.array(ts), poses, name="scan-to-map")
    inl = [m.inliers / max(m.points, 1) for m in matches]
    info: dict[str, Any] = {
        "dimension": "3d", "clouds": len(clouds), "clouds_skipped_before_anchor": len(log.of("cloud")) - len(clouds),
        "registrations": len(matches), "failed_registrations": sum(not m.matched for m in matches),
        "rejected_registrations": sum("rejected" in m.extra for m in matches), "guess_sources": predictor.sources,
        "cloud": asdict(fcfg) | {"sensor_height_used": fcfg.sensor_height if fcfg.sensor_height is not None
                                 else height},
        "cloud_map": asdict(mcfg),
        "inlier_fraction_mean": float(np.mean(inl)) if inl else float("nan"),
        "iterations_median": float(np.median([m.iterations for m in matches])) if matches else float("nan"),
        "native_warnings": native.count,
    }
    return RunResult(traj, traj, np.array(step_ms), np.array(icp_ms), info)
