"""The IMU factor graph: preintegrated IMU motion + robust GNSS / compass, for logs with ``imu`` records.

The odometry graph of :mod:`graphnav.graph.smoother` moves each pose along its heading by the logged speed
(a unicycle), which cannot represent a boat crabbing across a current. Here the motion model is
the IMU itself (:mod:`factors.imu`): one ``Pose3`` ``X(k)``, nav-frame velocity ``V(k)`` and IMU
bias ``IB(k)`` per keyframe (default: one per GNSS epoch, or per IMU sample if they are slower;
1 s on the Solent logs), and
between consecutive keyframes

* ``ImuFactor(X_i, V_i, X_j, V_j, IB_i)`` of the IMU samples in between (GTSAM preintegration,
  gravity off, body acceleration turning with the boat within a sample);
* ``BetweenFactorConstantBias(IB_i, IB_j)``: a random walk of the residual calibration bias
  (``bias_rw_*``); ``IB(0)`` has a zero-mean prior of the calibration's accuracy (``bias_sigma_*``);

plus Huber-robust ``GPSFactor`` (GNSS, z = 0) and yaw-only ``PoseRotationPrior3D`` (compass) factors
on the keyframe nearest to each record (:func:`graphnav.graph.keyframes.schedule`: causal online). The
first pose and velocity get the log's ``pose_prior`` and ``meta["initial_velocity"]`` (as the UKFs).

Drivers (same batches, same problem), all through the one solver wrapper of
:mod:`graphnav.graph.solver` (the odometry/ICP graph's): :func:`run_isam2` (one ``ISAM2.update`` per
keyframe; the online estimate is ``calculateEstimate`` of the newest pose, velocity and bias only),
:func:`run_batch` (Levenberg-Marquardt over the whole log, initialised by the online predictions of
the IMU from the prior) and :func:`run_fixed_lag` (``IncrementalFixedLagSmoother``). The IMU graph
stays a graph of its own (``Pose3`` + velocity + bias states, not the ``Pose2`` keyframes of
:mod:`graphnav.graph.builder`); the estimators pick it for IMU logs (``motion`` option).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F
from factors.imu import IB, V

from ..config import config_from_options
from ..errors import GraphnavError
from ..geometry import cov_to_world
from ..log import NavLog
from ..result import OnEstimate, RunResult
from ..trajectory import Trajectory
from .keyframes import schedule
from .solver import LmSettings, Solver, SolverError, isam_params, levenberg_marquardt


@dataclass
class ImuGraphConfig:
    """Tunables of the IMU graph (``-O key=value``); IMU noise defaults are the filters' (Table 2)."""

    keyframe_period: float | None = None  # [s]; None: the median GNSS (or IMU, if longer) interval
    substeps: int = 4  # integration steps per IMU sample
    acc_sigma: float = 0.0039  # [m/s^2] white noise per sample (Table 2 q_1)
    gyro_sigma_deg: float = 0.033  # [deg/s] (Table 2 q_2)
    integration_sigma: float = 1e-3  # [m/sqrt(s)] position integration error (keeps dp, dv decorrelated)
    bias_sigma_acc: float = 0.01  # [m/s^2] residual bias after calibration (prior, as ukf-bias)
    bias_sigma_gyro_deg: float = 0.1  # [deg/s]
    bias_rw_acc: float = 1e-5  # [m/s^2/sqrt(s)] bias random walk (as ukf-bias)
    bias_rw_gyro_deg: float = 1e-4  # [deg/s/sqrt(s)]
    sigma_v0: float = 0.2  # [m/s] prior on the initial velocity when the log states it (else 2 m/s at 0)
    gnss_robust: str | None = "huber"
    gnss_k: float | None = None
    gnss_sigma: float | None = None  # [m] override the records' sigma
    compass_robust: str | None = "huber"
    compass_k: float | None = None
    compass_sigma_deg: float | None = None  # override the records' sigma
    anchor_sigma_xy: float | None = None  # without a pose_prior: 3 x the first fix's sigma
    anchor_sigma_yaw_deg: float = 30.0
    relinearize_threshold: float = 0.01  # poses (rad, m) and velocities (m/s)
    relinearize_threshold_bias: float = 1e-4  # biases (m/s^2, rad/s)
    relinearize_skip: int = 10  # relinearisation check every N updates (1: 4x the step time, same RMSE)
    final_updates: int = 2
    lm_tol: float = 1e-10
    lm_max_iterations: int = 50
    lag: float = 20.0  # fixed-lag window [s]
    covariances: bool = True

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> ImuGraphConfig:
        return config_from_options(cls, options, "IMU-graph")


@dataclass
class ImuStep:
    """New factors/values of keyframe ``k`` and the keys' timestamps (fixed-lag)."""

    k: int
    t: float
    graph: gtsam.NonlinearFactorGraph
    values: gtsam.Values
    stamps: dict[int, float]


class ImuGraphBuilder:
    """Per-keyframe factor batches of the IMU graph; each step is given the previous state estimate."""

    def __init__(self, log: NavLog, cfg: ImuGraphConfig) -> None:
        self.log, self.cfg = log, cfg
        imu = log.columns("imu")
        if len(imu["t"]) < 1:
            raise ValueError("the IMU graph needs imu records")
        ti = np.asarray(imu["t"], dtype=float)
        dt0 = float(np.median(np.diff(ti))) if len(ti) > 1 else 1.0
        # record i holds the mean over (start[i], ti[i]]
        self.imu_t1 = ti
        self.imu_t0 = np.concatenate([[ti[0] - dt0], ti[:-1]])
        self.imu = np.stack([imu["ax"], imu["ay"], imu["wz"]], axis=1).astype(float)
        gt = np.array([r.t for r in log.of("gnss")])
        dt_gnss = float(np.median(np.diff(gt))) if len(gt) > 1 else dt0
        period = cfg.keyframe_period or max(dt0, dt_gnss)
        if period <= 0:
            raise ValueError(f"keyframe period must be > 0, got {period}")
        t_start, t_end = float(self.imu_t0[0]), float(ti[-1])
        n = int(math.floor((t_end - t_start) / period + 1e-9)) + 1
        self.kf_t = t_start + period * np.arange(n)
        self.params = F.planar_imu_params(cfg.acc_sigma, math.radians(cfg.gyro_sigma_deg), dt0,
                                          cfg.integration_sigma)
        self.pending: list[list[tuple[int, Any]]] = [[] for _ in range(n)]
        for kind in ("gnss", "heading"):
            recs = [r for r in log.of(kind) if t_start - 0.5 * period <= r.t <= t_end + 0.5 * period]
            if not recs:
                continue
            att, add = schedule(self.kf_t, [r.t for r in recs])
            for r, a, s in zip(recs, att, add, strict=True):
                self.pending[int(s)].append((int(a), r))
        self.anchor_pose, self.anchor_sigmas, self.anchor = self._anchor()
        v0 = log.meta.get("initial_velocity") if isinstance(log.meta, dict) else None
        if v0 is not None:
            self.v0, self.sigma_v0 = (float(v0[0]), float(v0[1])), cfg.sigma_v0
        else:
            self.v0, self.sigma_v0 = (0.0, 0.0), 2.0

    def _anchor(self) -> tuple[tuple[float, float, float], tuple[float, float], str]:
        prior = self.log.pose_prior()
        if prior is not None:
            return (prior.x, prior.y, prior.yaw), (prior.sigma_xy, prior.sigma_yaw), "pose_prior"
        gnss, head = self.log.of("gnss"), self.log.of("heading")
        yaw = head[0].yaw if head else 0.0
        ys = math.radians(self.cfg.anchor_sigma_yaw_deg) if head else math.pi
        if gnss:
            g = gnss[0]
            sxy = self.cfg.anchor_sigma_xy if self.cfg.anchor_sigma_xy is not None else 3.0 * g.sigma
            return (g.x, g.y, yaw), (sxy, ys), "first GNSS+compass" if head else "first GNSS"
        return (0.0, 0.0, yaw), (1e-3, ys), "origin"

    def samples(self, ta: float, tb: float) -> list[tuple[float, float, float, float]]:
        """IMU samples ``(ax, ay, wz, dt)`` clipped to ``[ta, tb]`` (zero-order hold per record)."""
        i0 = int(np.searchsorted(self.imu_t1, ta + 1e-9))
        out = []
        for i in range(i0, len(self.imu_t1)):
            lo, hi = max(self.imu_t0[i], ta), min(self.imu_t1[i], tb)
            if self.imu_t0[i] >= tb - 1e-9:
                break
            if hi - lo > 1e-9:
                out.append((*self.imu[i], hi - lo))
        return out

    def step(self, k: int, prev: tuple[gtsam.NavState, gtsam.imuBias.ConstantBias] | None) -> ImuStep:
        """Factors/values of keyframe ``k``; ``prev`` = current (state, bias) estimate of ``k - 1``."""
        cfg = self.cfg
        t = float(self.kf_t[k])
        g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
        xk = F.X(k)
        stamps = {xk: t, V(k): t, IB(k): t}
        if k == 0:
            for f in F.initial_state_factors(0, self.anchor_pose, self.anchor_sigmas[0], self.anchor_sigmas[1],
                                             self.v0, self.sigma_v0):
                g.add(f)
            g.add(F.bias_prior(0, cfg.bias_sigma_acc, math.radians(cfg.bias_sigma_gyro_deg)))
            v.insert(xk, F.planar_pose(*self.anchor_pose))
            v.insert(V(0), np.array([self.v0[0], self.v0[1], 0.0]))
            v.insert(IB(0), gtsam.imuBias.ConstantBias())
        else:
            assert prev is not None
            state, bias = prev
            ta = float(self.kf_t[k - 1])
            pim = F.preintegrate(self.params, bias, self.samples(ta, t), cfg.substeps)
            g.add(F.imu_factor(k - 1, k, pim))
            g.add(F.bias_between(k - 1, k, cfg.bias_rw_acc, math.radians(cfg.bias_rw_gyro_deg), t - ta))
            pred = pim.predict(state, bias) if pim.deltaTij() > 0 else state
            v.insert(xk, pred.pose())
            v.insert(V(k), pred.velocity())
            v.insert(IB(k), bias)
        for a, r in self.pending[k]:
            if r.kind == "gnss":
                sig = cfg.gnss_sigma if cfg.gnss_sigma is not None else (r.sigma if math.isfinite(r.sigma) else 5.0)
                g.add(F.gnss3_factor(F.X(a), r.x, r.y, sig, robust=cfg.gnss_robust, k=cfg.gnss_k))
            else:
                sig = (math.radians(cfg.compass_sigma_deg) if cfg.compass_sigma_deg is not None
                       else (r.sigma if math.isfinite(r.sigma) else math.radians(2.0)))
                g.add(F.compass3_factor(F.X(a), r.yaw, sig, robust=cfg.compass_robust, k=cfg.compass_k))
        return ImuStep(k, t, g, v, stamps)

    def info(self) -> dict[str, Any]:
        return {"motion": "imu", "anchor": self.anchor, "keyframes": len(self.kf_t), "config": asdict(self.cfg)}


def world_cov_planar(p: gtsam.Pose3, cov6: NDArray[np.float64]) -> NDArray[np.float64]:
    """GTSAM's Pose3 tangent covariance (rotation, translation; body frame) -> world (x, y, yaw)."""
    sel = [3, 4, 2]
    c = np.asarray(cov6)[np.ix_(sel, sel)]
    return cov_to_world(p.rotation().yaw(), c)


def _bias_list(b: gtsam.imuBias.ConstantBias) -> list[float]:
    """Planar bias ``[b_ax, b_ay, b_gz]`` (m/s^2, m/s^2, rad/s)."""
    return [float(b.accelerometer()[0]), float(b.accelerometer()[1]), float(b.gyroscope()[2])]


def _params(cfg: ImuGraphConfig) -> gtsam.ISAM2Params:
    """iSAM2 parameters (:func:`graphnav.graph.solver.isam_params`): poses ``x`` and velocities ``v``
    at ``relinearize_threshold``, biases ``i`` at ``relinearize_threshold_bias``."""
    return isam_params({"x": [cfg.relinearize_threshold] * 6, "v": [cfg.relinearize_threshold] * 3,
                        "i": [cfg.relinearize_threshold_bias] * 6}, skip=cfg.relinearize_skip,
                       factorization="CHOLESKY", optimizer="gauss-newton")


def _run_incremental(log: NavLog, name: str, fixed_lag: bool, on_estimate: OnEstimate | None,
                     options: dict[str, Any]) -> RunResult:
    cfg = ImuGraphConfig.from_options(options)
    b = ImuGraphBuilder(log, cfg)
    solver = Solver("fixed-lag" if fixed_lag else "isam2", _params(cfg), lag=cfg.lag, keep_graph=False)
    n = len(b.kf_t)
    on_t, on_p, on_c, step_ms, step_cpu = [], [], [], [], []

    def track(key: int) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        p = solver.estimate(key, "Pose3")
        return F.pose_xy_yaw(p), (world_cov_planar(p, solver.marginal(key)) if cfg.covariances else None)

    prev = None
    try:
        for k in range(n):
            st = b.step(k, prev)
            c0, p0 = time.perf_counter(), time.process_time()
            solver.update(st.graph, st.values, st.stamps, t=st.t, track=track, tracked=(F.X(k),))
            pose = solver.estimate(F.X(k), "Pose3")  # the newest state only
            vel = solver.estimate(V(k), "Vector")
            bias = solver.estimate(IB(k), "ConstantBias")
            cov = world_cov_planar(pose, solver.marginal(F.X(k))) if cfg.covariances else None
            step_ms.append((time.perf_counter() - c0) * 1e3)
            step_cpu.append((time.process_time() - p0) * 1e3)
            prev = (gtsam.NavState(pose, vel), bias)
            on_t.append(st.t)
            on_p.append(F.pose_xy_yaw(pose))
            on_c.append(cov)
            if on_estimate is not None:
                on_estimate(st.t, on_p[-1], cov)
        if not fixed_lag:
            solver.relinearize(cfg.final_updates)
        est = solver.current()
    except SolverError as exc:
        raise GraphnavError(f"the IMU graph could not be solved: {exc}") from None
    final_p: list = [None] * n
    final_c: list = [None] * n
    for k in range(n):
        if F.X(k) in solver.frozen:
            final_p[k], final_c[k] = solver.frozen[F.X(k)]
            continue
        p = est.atPose3(F.X(k))
        final_p[k] = F.pose_xy_yaw(p)
        if cfg.covariances:
            final_c[k] = world_cov_planar(p, solver.marginal(F.X(k)))
    traj = Trajectory(np.array(on_t), np.array(final_p), np.array(final_c) if cfg.covariances else None, name=name)
    online = Trajectory(np.array(on_t), np.array(on_p), np.array(on_c) if cfg.covariances else None,
                        name=f"{name}-online")
    info = b.info()
    info["step_cpu_ms_median"] = float(np.median(step_cpu))
    info["bias_final"] = _bias_list(est.atConstantBias(IB(n - 1)))
    info["bias_online_final"] = _bias_list(prev[1])
    return RunResult(traj, online, np.array(step_ms), np.zeros(0), info)


def run_isam2(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    """One ``ISAM2.update`` per keyframe; online = the newest pose/velocity/bias estimate."""
    return _run_incremental(log, "isam2", False, on_estimate, options)


def run_fixed_lag(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    """``IncrementalFixedLagSmoother`` (``lag`` [s]); final = each pose as it leaves the window."""
    return _run_incremental(log, "fixed-lag", True, on_estimate, options)


def run_batch(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    """Levenberg-Marquardt over the whole graph, initialised by IMU dead reckoning from the prior."""
    cfg = ImuGraphConfig.from_options(options)
    b = ImuGraphBuilder(log, cfg)
    graph, init = gtsam.NonlinearFactorGraph(), gtsam.Values()
    prev = None
    n = len(b.kf_t)
    for k in range(n):
        st = b.step(k, prev)
        graph.push_back(st.graph)
        init.insert(st.values)
        prev = (gtsam.NavState(st.values.atPose3(F.X(k)), st.values.atVector(V(k))),
                st.values.atConstantBias(IB(k)))
    c0, p0 = time.perf_counter(), time.process_time()
    try:
        result, iterations = levenberg_marquardt(graph, init, LmSettings(cfg.lm_tol, cfg.lm_max_iterations))
    except SolverError as exc:
        raise GraphnavError(f"the IMU graph could not be solved: {exc}") from None
    solve_ms = (time.perf_counter() - c0) * 1e3
    solve_cpu_ms = (time.process_time() - p0) * 1e3
    poses = [F.pose_xy_yaw(result.atPose3(F.X(k))) for k in range(n)]
    covs = None
    if cfg.covariances:
        m = gtsam.Marginals(graph, result)
        covs = [world_cov_planar(result.atPose3(F.X(k)), m.marginalCovariance(F.X(k))) for k in range(n)]
    traj = Trajectory(b.kf_t.copy(), np.array(poses), np.array(covs) if covs else None, name="batch")
    info = b.info()
    info.update(solve_ms=solve_ms, step_cpu_ms_median=solve_cpu_ms / n, lm_iterations=iterations,
                bias_final=_bias_list(result.atConstantBias(IB(n - 1))),
                planar_residual=planar_residual(result, n).tolist())
    if on_estimate is not None:
        for k in range(n):
            on_estimate(float(b.kf_t[k]), poses[k], None if covs is None else covs[k])
    return RunResult(traj, None, np.full(n, solve_ms / n), np.zeros(0), info)


RUNNERS: dict[str, Callable[..., RunResult]] = {"isam2": run_isam2, "batch": run_batch, "fixed-lag": run_fixed_lag}


def wants_imu_graph(log: NavLog) -> bool:
    """The automatic choice: the log has IMU records and nothing the IMU graph cannot use
    (no scans, no beacons) and at least one absolute fix (GNSS)."""
    c = log.counts()
    return bool(c.get("imu")) and bool(c.get("gnss")) and not c.get("scan") and not c.get("beacon")


def planar_residual(values: gtsam.Values, n: int) -> NDArray[np.float64]:
    """Max |roll|, |pitch| [rad] and |z| [m] over poses ``0..n-1`` (0 for an exactly planar estimate)."""
    out = np.zeros(3)
    for k in range(n):
        p = values.atPose3(F.X(k))
        r = p.rotation()
        out = np.maximum(out, np.abs([r.roll(), r.pitch(), p.translation()[2]]))
    return out
