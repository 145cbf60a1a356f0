"""Scan-to-map LiDAR odometry: the continuous-frame experiment of Wang et al. (2023), in 2D.

Each scan is registered against a local map made of the last ``keyframes`` registered keyframe scans (a
scan becomes a keyframe when the vessel has moved ``keyframe_dist`` metres or turned
``keyframe_angle_deg`` since the last one), voxel-downsampled to ``map_voxel`` metres. The initial guess
is the odometry increment when the log has odometry (``predict="odometry"``), else the IMU's prediction
when it has an IMU, else the constant-velocity prediction; the result is the pose in SE(2) (see
:mod:`graphnav.scan.registration` for how each backend is kept planar). A registration whose
point-to-line information against the map's local lines is degenerate (:mod:`graphnav.scan.degeneracy`:
condition number above ``max_condition``, or the registration's 1-sigma along the weakest direction —
the sandwich of :mod:`graphnav.scan.covariance` over the point-to-line pairs, with the map's voxel as
the sampling resolution — above ``max_sigma`` voxels) takes the prediction along its weak directions and
is counted (``info["degenerate_registrations"]``). The trajectory is the chain of registered poses —
odometry, so it drifts, as in the paper's Table 2.

With the IMU's prediction (a log with an IMU and no odometry) it is LiDAR-inertial odometry: the pose and
the IMU's state (velocity, gyro bias) are one filter (:func:`graphnav.scan.lio.lio_step`, shared with
``icp-dr``), each registration measures the predicted pose where its geometry sees and only where it
agrees with the prediction (``consistent``; else it is not heard and does not join the map,
``info["inconsistent_with_imu"]``), and the map is built from the filter's poses (docs/weighted-icp.md,
"scan-to-map: LiDAR-inertial"). ``gyro_bias=false``: the previous fusion (the registration and the
prediction combined by information, the velocity corrected apart, the bias white noise per scan).

Options (``graphnav run LOG -e scan-to-map -O key=value``): ``backend`` (``small_gicp:VGICP``
default, ``small_gicp:GICP``, ``open3d:point_to_point``, ``open3d:point_to_plane``,
``open3d:gicp``, or the short aliases ``vgicp``, ``gicp`` ...) and every field of
:class:`ScanToMapConfig`.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..config import config_from_options, option
from ..geometry import increment, se2_adjoint_inv, se2_between, se2_compose, wrap_angle
from ..log import NavLog, Scan, odometry_samples
from ..result import OnEstimate, RunResult
from ..scan.covariance import SAMPLING_VARIANCE, sandwich
from ..scan.degeneracy import analyse, flatness, keep_constrained, line_information
from ..scan.deskew import sweep_of
from ..scan.imu_guess import ImuGuess, fuse_se2, log_imu_guess
from ..scan.lio import composed_cov, lio_step
from ..scan.registration import (
    Params,
    Target,
    local_frames_2d,
    prepare_source,
    resolve_method,
    scan_points,
    transform2,
    voxel_downsample,
)
from ..trajectory import Trajectory
from .base import BatchEstimator
from .gating import consistent
from .scan_to_map3d import cloud_configs, run_scan_to_map3d, usable_clouds
from .start import log_start


@dataclass(frozen=True)
class ScanToMapConfig:
    """Scan-to-map settings (metres, degrees where the name says so)."""

    backend: str = option("small_gicp:VGICP",
        "registration: small_gicp:VGICP|GICP, open3d:point_to_point|point_to_plane|gicp")
    keyframes: int = option(10, "the local map: the last N keyframe scans")
    deskew: bool = option(True, "de-skew each scan with the prediction's twist when the log states the LiDAR's "
                          "sweep (meta lidar sweep_s > 0)")
    keyframe_dist: float = option(1.0, "a scan becomes a keyframe after the vessel moved this far", unit="m")
    keyframe_angle_deg: float = option(10.0, "... or turned this much since the last keyframe", unit="deg")
    map_voxel: float = option(0.25, "voxel of the local map's downsampling", unit="m")
    scan_voxel: float = option(0.25, "voxel of each scan's downsampling", unit="m")
    min_range: float = option(1.0, "returns closer than this are dropped", unit="m")
    max_range: float = option(100.0, "returns farther than this (or the scan's own maximum) are dropped", unit="m")
    max_corr: float = option(2.0, "correspondence distance of the registration", unit="m")
    voxel: float = option(1.0, "VGICP voxel size", unit="m")
    neighbors: int = option(10, "neighbours for the local covariances / normals")
    max_iter: int = option(30, "registration iterations")
    planar: str = option("constrain", "\"constrain\": solve in SE(2); \"project\": 6-DoF, projected onto SE(2)")
    min_points: int = option(20, "a scan with fewer points is not registered (the prediction is kept)")
    min_fitness: float = option(0.3, "a registration below this inlier fraction is rejected")
    max_correction: float = option(5.0, "a registration farther than this from the prediction is rejected", unit="m")
    threads: int = option(1, "registration threads")
    # degeneracy of each registration (graphnav.scan.degeneracy; docs/weighted-icp.md): point-to-line pairs of
    # the scan against the map's local lines within inlier_dist map voxels
    max_condition: float = option(40.0, "a registration whose point-to-line condition number is above this is "
                                  "degenerate (unit-free; measured on the harbour log)")
    max_sigma: float = option(1.0, "the registration's 1-sigma along the weakest direction above this x map_voxel")
    inlier_dist: float = option(2.0, "degeneracy check: pairs within this many map voxels", unit="map voxels")
    degenerate: str = option("constrained",
        "a degenerate registration: \"constrained\" keeps it across the weak directions and takes the prediction along "
        "them; \"predict\" takes the prediction (either way the scan may join the map)")
    predict: str = option("odometry", "initial guess: \"odometry\" (when the log has odometry, else the IMU's when "
                          "it has an IMU, else cv), \"imu\" or \"cv\"")
    gyro_bias: bool = option(True, "with the IMU's prediction: the gyro's bias a state of one filter with the pose, "
                             "estimated from the registrations (graphnav.scan.lio; false: white noise per scan)")
    # 3D clouds (a log with cloud records and no scans: graphnav.estimators.scan_to_map3d)
    cloud: dict[str, Any] = option(help="3D: the clouds' filter, graphnav.scan.cloud_match.CloudMatchConfig "
                                   "(min_range, max_range, water_margin, sensor_height, ...)", factory=dict)
    cloud_map: dict[str, Any] = option(help="3D: the local map and its registration, "
                                       "graphnav.scan.cloud_map.CloudMapConfig (variant gicp|vgicp, voxel, "
                                       "map_voxel, knn, max_corr, max_iter, horizon, rebuild, target_voxel, threads)",
                                       factory=dict)

    def params(self) -> Params:
        return Params(max_corr=self.max_corr, voxel=self.voxel, neighbors=self.neighbors,
                      max_iter=self.max_iter, planar=self.planar, threads=self.threads)


def make_config(**options: Any) -> ScanToMapConfig:
    cfg = config_from_options(ScanToMapConfig, options, "scan-to-map")
    resolve_method(cfg.backend)  # fail early on a bad name
    if cfg.planar not in ("constrain", "project"):
        raise ValueError(f"planar must be 'constrain' or 'project', got {cfg.planar!r}")
    if cfg.degenerate not in ("constrained", "predict"):
        raise ValueError(f"degenerate must be 'constrained' or 'predict', got {cfg.degenerate!r}")
    if cfg.predict not in ("odometry", "imu", "cv"):
        raise ValueError(f"predict must be 'odometry', 'imu' or 'cv', got {cfg.predict!r}")
    cloud_configs(cfg.cloud, cfg.cloud_map)  # fail early on a bad cloud or cloud_map option
    return ScanToMapConfig(**{**asdict(cfg), "backend": resolve_method(cfg.backend)})


def predict_constant_velocity(p_prev2: np.ndarray, p_prev: np.ndarray, dt_prev: float,
                              dt: float) -> np.ndarray:
    """Pose at the next scan if the last body-frame motion repeats, scaled to the new interval."""
    d = se2_between(p_prev2, p_prev)
    s = dt / dt_prev if dt_prev > 0 else 1.0
    return se2_compose(p_prev, d * s)


def _degeneracy(xy: np.ndarray, pose: np.ndarray, target: Target, map_lines: Any, cfg: ScanToMapConfig,
                pred_cov: np.ndarray | None) -> tuple[Any, np.ndarray]:
    """Degeneracy of a registration (:func:`graphnav.scan.degeneracy.analyse`) with its covariance from
    :func:`graphnav.scan.covariance.sandwich` over the point-to-line pairs: flatness as weights, the
    residual variance along the normals plus the sampling term of the map's resolution (one point
    per ``map_voxel``, shared by the ``neighbors`` points a map line is fitted on). A direction is
    weak where the registration knows it less well than the prediction (``pred_cov``, the odometry
    increment's covariance; None without odometry) or by the condition / ``max_sigma`` tests."""
    lp = line_information(xy, pose, target.xy, *map_lines, target.tree2, cfg.inlier_dist * cfg.map_voxel)
    if len(lp.res) == 0 or not np.isfinite(lp.s2):
        cov = np.full((3, 3), np.nan)
    else:
        var = lp.s2 + cfg.neighbors * SAMPLING_VARIANCE * cfg.map_voxel**2
        cov = sandwich(lp.rows[:, None, :], lp.flat, np.full((len(lp.res), 1, 1), var))
    return analyse(lp.info, lp.radius, cov, max_condition=cfg.max_condition, max_sigma=cfg.max_sigma * cfg.map_voxel,
                   prior_cov=pred_cov), cov


class _ScanMap2d:
    """The 2D scan-to-map pass, scan by scan: predict the pose (IMU, odometry, constant velocity),
    register the scan against the local map of the last keyframes, keep the prediction along the
    directions the registration cannot see, update the map; with the IMU, fuse the registration with
    the prediction by information and correct the IMU's velocity."""

    def __init__(self, cfg: ScanToMapConfig, pose0: np.ndarray, odo: np.ndarray, imu: ImuGuess | None) -> None:
        self.cfg, self.params, self.pose0, self.odo, self.imu = cfg, cfg.params(), pose0, odo, imu
        self.ts: list[float] = []
        self.poses: list[np.ndarray] = []
        self.icp_ms: list[float] = []
        self.stats: dict[str, list[float]] = {"rmse": [], "fitness": [], "iters": [], "conds": []}
        self.failed = self.degenerate = 0
        self.map_lines: tuple[np.ndarray, np.ndarray] | None = None  # normals, flatness of the map points
        self.keyframes: deque[tuple[np.ndarray, np.ndarray, Any]] = deque(maxlen=cfg.keyframes)
        self.vgicp = cfg.backend == "small_gicp:VGICP"  # the voxel map is built from the keyframes' own clouds
        self.last_kf: np.ndarray | None = None
        self.target: Target | None = None
        self.p_pose = np.zeros((3, 3))  # with the IMU: the pose's covariance relative to the map (body frame)
        # with the gyro's bias a state: one filter over the pose and the IMU's state (vx, vy, b_g), cross their
        # covariance; _inc the IMU's predicted increment to the scan and _pred_cov the predicted pose's covariance
        self.joint = imu is not None and imu.gyro_bias
        self.cross = np.zeros((3, 3))
        self._inc, self._pred_cov = np.zeros(3), np.zeros((3, 3))
        self.inconsistent = 0  # registrations that disagree with the IMU's prediction (not heard, not mapped)
        self.sweep_s = 0.0  # [s] the LiDAR's sweep (meta lidar sweep_s, when cfg.deskew): scans are de-skewed

    def predict(self, t: float) -> tuple[np.ndarray, np.ndarray | None]:
        """The predicted pose at ``t`` and the odometry's covariance of the increment (None otherwise)."""
        ts, poses = self.ts, self.poses
        inc = increment(self.odo, ts[-1], t) if len(self.odo) else None
        imu_inc = self.imu.guess(ts[-1], t) if self.imu is not None else None
        if imu_inc is not None and self.joint:  # the pose and the IMU's state in one filter (graphnav.scan.lio)
            assert self.imu is not None
            self._inc = imu_inc[0]
            self._pred_cov = composed_cov(self.imu, ts[-1], t, self.p_pose, self.cross, imu_inc[0])
            return se2_compose(poses[-1], imu_inc[0]), None
        if imu_inc is not None:  # the IMU's prediction of the filter (see the module docstring)
            a = se2_adjoint_inv(imu_inc[0])
            self.p_pose = a @ self.p_pose @ a.T + imu_inc[1]
            return se2_compose(poses[-1], imu_inc[0]), None
        if inc is not None:
            return se2_compose(poses[-1], inc[0]), inc[1]
        if len(poses) >= 2:
            return predict_constant_velocity(poses[-2], poses[-1], ts[-1] - ts[-2], t - ts[-1]), None
        return poses[-1].copy(), None

    def register(self, xy: np.ndarray, pred: np.ndarray, pred_cov: np.ndarray | None) -> tuple[Any, ...]:
        """(pose, registered, source, covariance, degeneracy) of ``xy`` registered from ``pred``; a
        rejected registration leaves the prediction (not registered)."""
        cfg = self.cfg
        t_icp = time.perf_counter()
        source = prepare_source(xy, cfg.backend, self.params)  # kept: a keyframe reuses it
        res = self.target.align(xy, pred, source)
        self.icp_ms.append((time.perf_counter() - t_icp) * 1e3)
        self.stats["rmse"].append(res.rmse)
        self.stats["fitness"].append(res.fitness)
        self.stats["iters"].append(res.iterations)
        jump = np.hypot(*(res.pose[:2] - pred[:2]))
        if not (np.all(np.isfinite(res.pose)) and jump <= cfg.max_correction and res.fitness >= cfg.min_fitness):
            self.failed += 1
            return pred, False, source, None, None
        deg, reg_cov = _degeneracy(xy, res.pose, self.target, self.map_lines, cfg, pred_cov)
        self.stats["conds"].append(deg.condition)
        if not deg.degenerate:
            return res.pose, True, source, reg_cov, deg
        self.degenerate += 1  # the prediction (along the weak directions only: "constrained")
        pose = keep_constrained(res.pose, pred, deg) if cfg.degenerate == "constrained" else pred
        return pose, True, source, reg_cov, deg

    def update_map(self, xy: np.ndarray, pose: np.ndarray, source: Any) -> None:
        """A keyframe once the vessel moved ``keyframe_dist`` or turned ``keyframe_angle_deg``; the
        local map rebuilt from the last keyframes."""
        cfg, last = self.cfg, self.last_kf
        if not (last is None or np.hypot(*(pose[:2] - last[:2])) >= cfg.keyframe_dist
                or abs(wrap_angle(pose[2] - last[2])) >= np.radians(cfg.keyframe_angle_deg)):
            return
        if source is None and self.vgicp:
            source = prepare_source(xy, cfg.backend, self.params)
        self.keyframes.append((xy, pose.copy(), source))
        self.last_kf = pose.copy()
        world = voxel_downsample(np.vstack([transform2(p, k) for k, p, _ in self.keyframes]), cfg.map_voxel)
        parts = [(c, p) for _, p, c in self.keyframes] if self.vgicp else None
        self.target = Target(world, cfg.backend, self.params, parts)
        nrm, ev = local_frames_2d(world, cfg.neighbors, self.params.normal_radius)
        self.map_lines = (nrm, flatness(ev))

    def points(self, scan: Scan, pred: np.ndarray | None) -> np.ndarray:
        """The scan's points; with a LiDAR sweep (``sweep_s``) de-skewed to its stamp with the prediction's
        constant twist since the previous scan (:mod:`graphnav.scan.deskew`)."""
        cfg = self.cfg
        top = min(cfg.max_range, scan.max_range)
        xy = scan_points(scan.ranges, scan.angles, min_range=cfg.min_range, max_range=top)
        dt = scan.t - self.ts[-1] if self.ts else 0.0
        if not self.sweep_s or pred is None or not dt > 0.0:
            return xy
        from ..scan.deskew import deskew_mask_points, twist_of
        from ..scan.lidar import valid_returns

        keep = valid_returns(scan.ranges, scan.angles, min_range=cfg.min_range, max_range=top)
        return deskew_mask_points(xy, keep, self.sweep_s, twist_of(se2_between(self.poses[-1], pred), dt))

    def step(self, scan: Scan) -> float:
        """One scan: its pose appended; returns the registration's time [ms]."""
        cfg = self.cfg
        n_icp = len(self.icp_ms)
        pred, pred_cov = self.predict(scan.t) if self.poses else (None, None)
        xy = voxel_downsample(self.points(scan, pred), cfg.scan_voxel)
        enough = len(xy) >= cfg.min_points
        source = reg_cov = deg = None
        registered = self.target is None  # no map yet: this scan starts it at the (predicted) pose
        if pred is None:
            pose = np.array(self.pose0, dtype=float)
        else:
            pose = pred
            if self.target is not None and enough:
                pose, registered, source, reg_cov, deg = self.register(xy, pred, pred_cov)
            else:
                self.failed += 1
        fused = None
        if self.joint and self.poses:
            fused, registered = self._lio(scan.t, pred, pose, registered, source, reg_cov, deg)
        # keyframe and local-map update (timed as the step; registration time is icp_ms); a scan
        # whose registration was rejected does not enter the map
        if enough and registered:  # LiDAR-inertial: the filter's pose (else the registration's)
            self.update_map(xy, pose if fused is None else fused, source)
        if fused is not None:
            pose = fused
        elif self.imu is not None and self.poses:
            ok_reg = registered and source is not None and reg_cov is not None and np.all(np.isfinite(reg_cov))
            weak = deg.projector() if ok_reg and deg.weak.any() else None
            reg_inc = se2_between(self.poses[-1], pose)
            if ok_reg:  # the registration updates the predicted pose by the information of each
                pose, self.p_pose = fuse_se2(pred, self.p_pose, pose, reg_cov, weak)
            # the velocity: corrected by the registration, carried to this scan
            self.imu.update(self.ts[-1], scan.t, reg_inc if ok_reg else None, reg_cov if ok_reg else None, weak)
        self.ts.append(scan.t)
        self.poses.append(np.array(pose, dtype=float))
        return self.icp_ms[-1] if len(self.icp_ms) > n_icp else 0.0

    def _lio(self, t: float, pred: np.ndarray, pose: np.ndarray, registered: bool, source: Any,
             reg_cov: np.ndarray | None, deg: Any) -> tuple[np.ndarray, bool]:
        """The pose and the IMU's state after the registration ``pose`` (:func:`graphnav.scan.lio.lio_step`: the
        registration measures the composed pose, where its geometry sees and only if it agrees with the IMU's
        prediction ``pred``); returns the fused pose and whether the registration may join the map."""
        assert self.imu is not None
        meas = None
        if registered and source is not None and reg_cov is not None and np.all(np.isfinite(reg_cov)):
            meas = (pose, reg_cov, deg.projector() if deg.weak.any() else None)
            if not consistent(pred, self._pred_cov, *meas):
                meas, registered = None, False
                self.inconsistent += 1
        fused, self.p_pose, self.cross = lio_step(self.imu, self.ts[-1], t, self.poses[-1], self.p_pose, self.cross,
                                                  self._inc, meas, of_pose=True)
        return fused, registered

    def info(self) -> dict[str, Any]:
        st = self.stats
        imu = self.imu
        bias = {} if not self.joint or imu is None else {  # the gyro's bias at the end and its 1-sigma [deg/s]
            "inconsistent_with_imu": self.inconsistent, "gyro_bias_dps": float(np.degrees(imu.bg)),
            "gyro_bias_sigma_dps": float(np.degrees(np.sqrt(imu.P3[2, 2])))}
        return {**bias,
            "registrations": len(self.icp_ms),
            "failed_registrations": self.failed,
            "degenerate_registrations": self.degenerate,
            "condition_number_median": float(np.median(st["conds"])) if st["conds"] else float("nan"),
            "registration_rmse_m_mean": float(np.nanmean(st["rmse"])) if st["rmse"] else float("nan"),
            "registration_fitness_mean": float(np.mean(st["fitness"])) if st["fitness"] else float("nan"),
            "iterations_median": float(np.median(st["iters"])) if st["iters"] else float("nan"),
        }


def _imu_guess(log: NavLog, cfg: ScanToMapConfig, pose0: np.ndarray, odo: np.ndarray) -> ImuGuess | None:
    """The IMU's prediction when ``predict`` asks for it (or for odometry the log does not have)."""
    if not (cfg.predict == "imu" or (cfg.predict == "odometry" and not len(odo))):
        return None
    return log_imu_guess(log, float(pose0[2]), gyro_bias=cfg.gyro_bias)


def run_scan_to_map(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    cfg = make_config(**options)
    start = log_start(log)  # the graph's anchor: the pose prior, else the first GNSS fix and compass reading, ...
    pose0, anchor, t_anchor = start.pose, start.name, start.t
    if _usable_scans(log) < 2 and usable_clouds(log) >= 2:
        res = run_scan_to_map3d(log, pose0, predict=cfg.predict, max_correction=cfg.max_correction,
                                min_fitness=cfg.min_fitness, cloud=cfg.cloud, cloud_map=cfg.cloud_map,
                                t_anchor=t_anchor, on_estimate=on_estimate)
        res.info = {"anchor": anchor, "config": asdict(cfg), **res.info}
        return res
    scans: list[Scan] = [s for s in log.of("scan") if s.t >= t_anchor - 1e-6]
    odo = odometry_samples(log) if cfg.predict == "odometry" else np.zeros((0, 5))
    run = _ScanMap2d(cfg, pose0, odo, _imu_guess(log, cfg, pose0, odo))
    run.sweep_s = sweep_of(log) if cfg.deskew else 0.0
    step_ms: list[float] = []
    for scan in scans:
        t_step = time.perf_counter()
        this_icp = run.step(scan)
        step_ms.append((time.perf_counter() - t_step) * 1e3 - this_icp)
        if on_estimate is not None:
            on_estimate(scan.t, run.poses[-1], None)
    traj = Trajectory(np.array(run.ts), np.array(run.poses).reshape(-1, 3), name="scan-to-map")
    info = {"anchor": anchor, "config": asdict(cfg), "scans": len(scans),
            "scans_skipped_before_anchor": len(log.of("scan")) - len(scans), **run.info()}
    return RunResult(traj, traj, np.array(step_ms), np.array(run.icp_ms), info)


def _usable_scans(log: NavLog) -> int:
    return sum(1 for s in log.of("scan") if int(np.count_nonzero(s.valid())) >= ScanToMapConfig.min_points)


def _unmet(log: NavLog) -> str | None:
    if _usable_scans(log) >= 2 or usable_clouds(log) >= 2:
        return None
    return f"needs at least two scans with >= {ScanToMapConfig.min_points} returns or two 3D clouds"


def _inputs(log: NavLog, options: dict) -> set[str]:
    kinds = {"cloud" if _usable_scans(log) < 2 and usable_clouds(log) >= 2 else "scan", "pose_prior"}
    predict = make_config(**options).predict
    if predict == "odometry" and len(log.of("odometry")) >= 2:
        kinds.add("odometry")  # the initial guess
    elif predict != "cv" and len(log.of("imu")) >= 2:
        kinds.add("imu")
    return kinds


class ScanToMap(BatchEstimator):
    """LiDAR scan-to-local-map registration (:func:`run_scan_to_map`)."""

    description = "LiDAR scan-to-local-map registration (2D: small_gicp VGICP; 3D: GICP to a KISS-ICP style voxel map)"
    kind = "odometry"
    cost = 3  # every scan registered against the map
    Config = ScanToMapConfig
    what = "scan-to-map"
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)

    batch = staticmethod(run_scan_to_map)


ESTIMATORS = {"scan-to-map": ScanToMap}
