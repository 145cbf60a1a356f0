"""The navigator: records in, the navigation solution out, online and smoothed.

::

    log = graphnav.load_log(path)
    nav = graphnav.Navigator(config=None)   # iSAM2 by default; SmootherConfig(solver="fixed-lag"), ...
    for rec in log:
        est = nav.add(rec)                  # Estimate | None: est.t, est.pose (gtsam.Pose2), est.cov (3x3, world)
    traj = nav.smoothed()                   # the smoothed Trajectory with per-pose covariances

:class:`Navigator` couples the record-by-record :class:`~graphnav.graph.builder.GraphBuilder` with a
:class:`~graphnav.graph.solver.Solver`. After every keyframe's batch the online estimate of the
newest pose and its marginal covariance (rotated to the world frame) are returned (iSAM2,
fixed-lag; batch returns nothing online). Through a gap without records the online output goes on
at its rate (the estimates' median interval, or ``coast_hz``): the newest state moved by the graph's
motion model, its covariance grown, flagged ``coasted`` (:mod:`graphnav.graph.coast`; outputs only,
the graph is untouched; ``info["coasted_estimates"]``). :meth:`Navigator.smoothed` ends the run: iSAM2's
estimate after ``final_updates`` relinearisations and, with ``converge="lm"`` (default), a closing
Levenberg-Marquardt step from it over the whole graph -- the same problem batch solves, so the two
agree --; batch LM from the chained initial guess; fixed-lag each pose as it left the window. The
batch solutions drop gross GNSS outliers by their residual and re-solve, and estimate a noise scale
per sensor group when ``noise_estimation`` asks (:mod:`graphnav.graph.noise`).

``graphnav run -e isam2|batch|fixed-lag`` (:mod:`graphnav.graph.log_runs`) and ``graphnav live``
(:mod:`graphnav.online.runner`) are loops over it. A failure of GTSAM is a
:class:`~graphnav.errors.GraphnavError` naming the record and time.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, replace
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..config import given_option
from ..errors import GraphnavError
from ..geometry import cov_to_world
from ..log import KnownBeacon, NavLog, Record, odometry_is_rot, validate_record
from ..result import Estimate, OnEstimate, RunResult
from ..trajectory import Trajectory
from .builder import GraphBuilder, Matcher, NavPrev, Step
from .coast import Coaster, Coasting
from .fix_gate import OnlineFixes
from .newest_guess import solve_newest
from .online_track import OnlineTrack, kinematics
from .position_walk import position_walk
from .smoother_config import SmootherConfig, SolverConfig, auto_motion
from .solution import Closing, joint_prior, marginal_priors, refresh_places, type_of
from .solver import LmSettings, Solver, SolverError, isam_params, levenberg_marquardt
from .space import IB, PlanarSpace, V
from .water_aim import WaterAim

BATCH_INIT_FIRST = 32  # batch_init="incremental": the first solve at this many keyframes


def world_cov(pose: gtsam.Pose2, cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """GTSAM's body-tangent Pose2 covariance -> (x, y, yaw) covariance in the world frame."""
    return cov_to_world(pose.theta(), cov)


def _vec(p: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([p.x(), p.y(), p.theta()])


def gnss_sigma_assumed(log: NavLog) -> bool:
    """Whether the log's GNSS sigmas are known only up to scale: an NMEA log's fixes without a GST
    of their own take HDOP x an assumed UERE (``graphnav.io.nmea.UERE_M``), so their group is
    rescaled like a defaulted one by the noise estimation (issue #25: estimated where redundancy allows)."""
    if log.meta.get("format") != "nmea0183":
        return False
    n = sum(1 for r in log.records if r.kind == "gnss")
    return n > int(log.meta.get("fix_sigma_from_gst", 0) or 0)


def graph_params(cfg: SolverConfig, space: PlanarSpace | None = None) -> gtsam.ISAM2Params:
    """The iSAM2 parameters of the graph: thresholds per variable type (poses ``x``, beacons ``l``,
    compass-bias frame ``b``; in the Pose3 graph also velocities ``v`` and IMU biases ``i``)."""
    space = space or PlanarSpace()
    return isam_params(space.thresholds(cfg.relinearize_threshold, cfg.relinearize_threshold_landmarks,
                                        math.radians(cfg.relinearize_threshold_bias_deg),
                                        cfg.relinearize_threshold_velocity,
                                        (cfg.relinearize_threshold_imu_acc, cfg.relinearize_threshold_imu_gyro)),
                       skip=cfg.relinearize_skip or (5 if space.name == "nav" else 1),
                       partial_check=cfg.partial_relinearization_check,
                       wildfire=wildfire_threshold(cfg, space), factorization=cfg.isam_factorization,
                       optimizer=cfg.isam_optimizer)


def lm_settings(cfg: SolverConfig) -> LmSettings:
    """Every Levenberg-Marquardt solve's stopping rules and damping, from the ``optimizer`` options."""
    return LmSettings(cfg.lm_tol, cfg.lm_max_iterations, cfg.lm_abs_tol, cfg.lm_stall_tol,
                      adaptive=cfg.lm_damping == "nielsen")


def wildfire_threshold(cfg: SolverConfig, space: PlanarSpace) -> float:
    """iSAM2's wildfire threshold: the option, else 0.01 on the Pose3 graph and GTSAM's 0.001 on the Pose2 graph."""
    if cfg.wildfire_threshold is not None:
        return cfg.wildfire_threshold
    return 0.01 if space.name == "nav" else 0.001


def solve_failure(exc: SolverError, t: float, rec: Record | None, n_records: int) -> GraphnavError:
    """The error of a keyframe at ``t`` the solver could not solve, naming the record that brought it."""
    where = f"record {n_records}" + (f" ({rec.kind} at t = {rec.t:.6g} s)" if rec is not None else "")
    return GraphnavError(f"the navigation graph could not be solved at the keyframe of t = {t:.6g} s: {exc}",
                         where=where)


def segment_length(cfg: SmootherConfig, history: bool, gnss: bool, loops: bool) -> float:
    """Keyframes between two re-anchorings of the online solver: the fixed-lag smoother's in live mode
    (``rebase_every``, no ``history`` kept); iSAM2's while ``gnss`` fixes hold the track (the smaller of
    ``isam2_segment`` and ``isam2_segment_gnss``; a loop back to an earlier segment enters only the closing
    step), else without a loop closer (``isam2_segment``); else never (``inf``)."""
    opt = cfg.optimizer
    if not history and cfg.solver == "fixed-lag":
        n = opt.rebase_every
    elif cfg.solver == "isam2" and opt.isam2_segment and gnss:
        n = min(opt.isam2_segment, opt.isam2_segment_gnss or opt.isam2_segment)
    else:
        n = opt.isam2_segment if cfg.solver == "isam2" and not loops else None
    return n if n else math.inf


def log_inputs(log: NavLog, config: SmootherConfig | None, kw: dict[str, Any]) -> dict[str, Any]:
    """The :class:`Navigator`'s arguments from ``log``: its chart, LiDAR models, whether it has scans,
    an IMU and odometry, the IMU model and initial velocity, the mounts (the log's, the option's ``kw["mounts"]``
    winning per sensor), with the other arguments ``kw``."""
    lidar = log.meta.get("lidar") if isinstance(log.meta.get("lidar"), dict) else None
    lidar3d = log.meta.get("lidar3d") if isinstance(log.meta.get("lidar3d"), dict) else None
    scans = bool(log.of("scan")) or (bool(log.of("cloud")) and (config is None or config.scan.use_cloud)
                                     and given_option(SmootherConfig, kw, "scan.use_cloud", True))
    imu_model = log.meta.get("imu") if isinstance(log.meta.get("imu"), dict) else None
    if log.meta.get("mounts") is not None:  # the log's mounts, the option's winning per sensor
        from .mounts import merged

        given = kw.get("mounts", config.mounts if config is not None else {})
        kw["mounts"] = {k: asdict(m) for k, m in merged(log.meta["mounts"], given).items()}
    motion = kw.get("motion", config.motion if config is not None else "auto")
    if motion == "auto" and auto_motion(log.counts(), log.meta) == "vessel":  # a vessel's instruments, no IMU
        kw["motion"] = "vessel"
    v0 = log.meta.get("initial_velocity")
    if imu_model is not None or v0 is not None:
        imu_model = {**(imu_model or {}), **({"initial_velocity": v0} if v0 is not None else {})}
    has_imu = any(r.kind == "imu" for r in log.records)
    if odometry_is_rot(log.meta) and not has_imu:  # a rate of turn: the vessel model's yaw rate
        imu_model = {**(imu_model or {}), "rot": True}
    if (kw.get("motion", motion) == "vessel" and not has_imu
            and (given_option(SmootherConfig, kw, "imu", config.imu if config is not None else None) or {}
                 ).get("vessel_position_walk") is None):
        walk = position_walk(log)  # how far the fixes wander from the integrated velocity
        if walk is not None:
            imu_model = {**(imu_model or {}), "vessel_position_walk": walk["walk"], "position_walk": walk}
    return {"chart": log.beacons_known, "lidar": lidar, "scans": scans, "lidar3d": lidar3d,
            "imu": has_imu, "imu_model": imu_model,
            "odometry": bool(log.of("odometry")), **kw}


class Navigator(Coasting):
    """Record-by-record navigation on one factor graph (see the module docstring).

    ``config``: a :class:`SmootherConfig` (``None``: defaults; ``**options`` override its fields).
    ``chart``: charted beacons (``KnownBeacon``; they may also be passed to :meth:`add`);
    ``lidar``: the log's LiDAR error model (``meta["lidar"]``); ``scans``: whether scans will
    come (``None``: a keyframe grid until the first scan); ``odometry``: whether odometry will come
    (the robot at rest before its first sample, :meth:`OdometryBuffer.rest_row
    <graphnav.graph.odometry_buffer.OdometryBuffer.rest_row>`; ``None``: from the first sample on);
    ``matcher``: replaces the weighted ICP;
    ``on_estimate(t, pose_vec, cov)``: called with every online estimate. ``history=False`` (live
    mode, unbounded runs) keeps neither the online trajectory nor, with fixed-lag, the poses that
    left the window: memory stays bounded (the smoothed trajectory is then the window only).
    :meth:`for_log` fills these from a :class:`NavLog`.
    """

    def __init__(self, config: SmootherConfig | None = None, *, chart: Iterable[KnownBeacon] = (),
                 lidar: dict[str, Any] | None = None, scans: bool | None = None, matcher: Matcher | None = None,
                 lidar3d: dict[str, Any] | None = None, imu: bool | None = None,
                 imu_model: dict[str, Any] | None = None, odometry: bool | None = None,
                 on_estimate: OnEstimate | None = None, history: bool = True, **options: Any) -> None:
        if config is None:
            cfg = SmootherConfig.from_options(options)
        else:
            SmootherConfig.from_options(options)  # unknown keys are an error
            cfg = replace(config, **options)
        self.cfg = cfg
        self.builder = GraphBuilder(cfg, matcher=matcher, chart=chart, lidar=lidar, scans=scans, lidar3d=lidar3d,
                                    imu=imu, imu_model=imu_model, odometry=odometry)
        self.space = self.builder.space
        self.nav = self.builder.nav
        self.last_state: NavPrev | None = None  # the Pose3 graph: the newest keyframe's full state
        self.fixes = OnlineFixes(cfg.gnss.gate_max_rejects)  # the gate's re-acquisitions online (graph.fix_gate)
        self.solver = Solver(cfg.solver, graph_params(cfg.optimizer, self.space), lag=cfg.optimizer.lag,
                             lm=lm_settings(cfg.optimizer), keep_graph=history)
        self.groups: list[str] = []  # sensor group of every factor in solver.graph
        opt = cfg.optimizer  # the water-speed factors re-aimed online (graph.water_aim) as iSAM2 relinearises
        self.aim = WaterAim(opt.relinearize_threshold, opt.relinearize_skip or (5 if self.nav else 1)) \
            if cfg.water.reaim_online else None
        self.on_estimate = on_estimate
        self.history = history
        self.track = OnlineTrack(history)  # the online estimates and step times
        self.coaster = Coaster(cfg.optimizer.coast_hz, cfg.optimizer.coast_max_s)  # output through gaps (Coasting)
        self.last_pose: gtsam.Pose2 | None = None
        self.last_cov: NDArray[np.float64] | None = None
        self._base = 0  # the keyframe the fixed-lag smoother was last re-anchored at
        self._next_init = BATCH_INIT_FIRST  # batch: the keyframe count of the next incremental solve
        self.n_records = 0
        self._rec: Record | None = None
        self._result: RunResult | None = None
        self._final: gtsam.Values | None = None
        self.extra: dict[str, Any] = {}
        # batch with loop closures: an iSAM2 front end makes the loop decisions (candidates, gates,
        # verification against the current estimate) exactly as the `isam2` run does, so both solve
        # the same graph; its online estimates are also batch's incremental initial guess
        self.front: Solver | None = None

    @classmethod
    def for_log(cls, log: NavLog, config: SmootherConfig | None = None, **kw: Any) -> Navigator:
        """A navigator for ``log``: its chart, LiDAR model, IMU, mounts and whether it has scans
        (:func:`log_inputs`); an NMEA log's assumed GNSS sigmas (:func:`gnss_sigma_assumed`)."""
        nav = cls(config, **log_inputs(log, config, kw))
        if gnss_sigma_assumed(log):
            nav.builder.assume_sigmas("gnss")
        return nav

    # -- online ----------------------------------------------------------------------------------
    def add(self, rec: Record | KnownBeacon, *, checked: bool = False) -> Estimate | None:
        """Take one record; the newest online estimate when a keyframe was solved, else ``None``.
        Each record is validated (a LogError naming it) unless ``checked`` says a reader already did
        (:meth:`NavLog.checked_records <graphnav.log.NavLog.checked_records>`)."""
        if self._result is not None:
            raise RuntimeError("the navigator has finished (smoothed() was called)")
        if not checked:
            rec = validate_record(rec, index=self.n_records + 1)  # a LogError naming the record, before the graph
        self.n_records += 1
        self._rec = self.coaster.record(rec) or self._rec
        self.builder.push(rec)
        return self._advance()

    def add_quiet(self, recs: Sequence[Record]) -> bool:
        """Checked IMU and truth records that make no keyframe ready, taken as :meth:`add` of each would (a
        log's runs between scans: :func:`feed`); ``False`` (nothing done) when they might
        (:meth:`GraphBuilder.push_quiet`)."""
        if self._result is not None or not self.builder.push_quiet(recs):
            return False
        self.n_records += len(recs)
        self._rec = recs[-1]
        self.coaster.record_times([r.t for r in recs if r.kind != "truth"])  # (truth: a reference, not an input)
        return True

    def flush(self) -> Estimate | None:
        """End of input: solve the keyframes still waiting for a later record."""
        if self.builder.finished:
            return None
        self.builder.finish()
        est = self._advance()
        late = self.builder.step_late(self._estimate_of, self.last_cov if self.solver.online else None)
        if late is not None:
            self._update(late)
        return est

    def _advance(self) -> Estimate | None:
        est = None
        for k in self.builder.ready():
            est = self._step(k) or est
        return est

    def _estimate_of(self, k: int) -> gtsam.Pose2:
        return self.space.pose2(self.solver.estimate(F.X(k), self.space.pose_type))

    def _update(self, s: Step) -> None:
        try:
            self.solver.update(s.graph, s.values, s.stamps, t=s.t, track=self._freeze if self.history else None,
                               tracked=(F.X(s.k),) if s.new_keyframe else (), kept=s.kept())
            self.solver.relinearize(self.cfg.optimizer.isam_extra_updates)
            self.fixes.step(self.solver, self.builder, s)
            if self.aim is not None:
                self.aim.step(self.solver, self.space, self.builder.meas.water, s)
        except SolverError as exc:
            raise solve_failure(exc, s.t, self._rec, self.n_records) from None
        if self.solver.keep:
            self.groups.extend(s.groups)

    def _freeze(self, key: int) -> tuple[gtsam.Pose2, NDArray[np.float64] | None]:
        p = self.solver.estimate(key, self.space.pose_type)
        cov = self.space.world_cov(p, self.solver.marginal(key)) if self.cfg.optimizer.covariances else None
        return self.space.pose2(p), cov

    def _step(self, k: int) -> Estimate | None:
        self._coast_before(k)  # the output grid through a gap before this keyframe (Coasting)
        s = self.builder.step(k, self.last_pose, self.last_cov if self.solver.online or self.front else None,
                              self.last_state)
        if s.icp_ms is not None:
            self.track.icp_ms.append(s.icp_ms)
        c0, p0 = time.perf_counter(), time.process_time()
        loops = self.builder.loops
        if k > 0 and not self.solver.online and loops is None and self.cfg.optimizer.batch_init == "incremental":
            s.values = solve_newest(s.kept(), s.values, self.solver.initial, lambda key: type_of(key, self.space))
        self._update(s)
        if not self.solver.online:
            if loops is not None:  # the front end's estimate is the next keyframe's guess
                self._front_step(s, k, loops)
                return None
            self._take(s.values, k)
            if self.cfg.optimizer.batch_init == "incremental" and k + 1 >= self._next_init:
                batch_initialise(self, k, s.t)
            return None
        pose, cov = self._newest(self.solver, k, s.t, loops)
        self.track.timing((time.perf_counter() - c0) * 1e3, (time.process_time() - p0) * 1e3)
        self.last_pose, self.last_cov = pose, cov
        vec = _vec(pose)
        prev_t, prev_p = self.track.add(s.t, vec, cov)
        if k - self._base >= segment_length(self.cfg, self.history, bool(self.builder.counts.get("gnss")),
                                            loops is not None):
            self._rebase(k, s.t)  # bounded: the fixed-lag smoother re-anchored, or iSAM2's next segment
        self.coaster.estimated(k, s.t)
        if self.on_estimate is not None:
            self.on_estimate(s.t, vec, cov)
        velocity = self.last_state[1] if self.nav and self.last_state is not None else None
        return Estimate(s.t, vec, cov, *kinematics(s.t, vec, prev_t, prev_p, velocity,
                                                   self.builder.recent_odometry(s.t)))

    def _newest(self, solver: Solver, k: int, t: float, loops: Any) -> tuple[gtsam.Pose2, NDArray[np.float64]]:
        """The newest pose's online estimate and world covariance from an incremental ``solver``;
        the loop closer (if any) first gets its places re-estimated when a loop moved the graph,
        then observes that pose."""
        try:
            if loops is not None and loops.stale:
                refresh_places(loops, solver, self.space)
            p = solver.estimate(F.X(k), self.space.pose_type)
            cov = self.space.world_cov(p, solver.marginal(F.X(k)))
            pose = self.space.pose2(p)
            if self.nav:
                vel = np.asarray(solver.estimate(V(k), "Vector"))
                bias = solver.estimate(IB(k), "ConstantBias")
                vel_cov = solver.marginal(V(k)) if self.builder.wants_velocity_cov else None
                self.last_state = (p, vel, bias, vel_cov)
                for key in self.builder.water_keys(k):
                    self.builder.observe_water(key, np.asarray(solver.estimate(key, "Vector")))
        except SolverError as exc:
            raise solve_failure(exc, t, self._rec, self.n_records) from None
        if loops is not None:
            loops.observe(k, _vec(pose), cov)
        return pose, cov

    def _front_step(self, s: Step, k: int, loops: Any) -> None:
        """Batch with loops: the iSAM2 front end takes the step (started with everything batch holds
        when the first scan brings the loop closer), and the loop closer observes its estimate."""
        try:
            if self.front is None:
                self.front = Solver("isam2", graph_params(self.cfg.optimizer, self.space), keep_graph=False)
                self.front.update(self.solver.graph, self.solver.initial)
            else:
                self.front.update(s.graph, s.values)
            self.front.relinearize(self.cfg.optimizer.isam_extra_updates)
        except SolverError as exc:
            raise solve_failure(exc, s.t, self._rec, self.n_records) from None
        self.last_pose, self.last_cov = self._newest(self.front, k, s.t, loops)
        self.extra["loop_front_end"] = "isam2"

    def _take(self, values: gtsam.Values, k: int) -> None:
        """Keyframe ``k``'s state in ``values`` is the next step's starting point (batch)."""
        self.last_pose = self.space.read(values, F.X(k))
        if self.nav:
            self.last_state = (values.atPose3(F.X(k)), np.asarray(values.atVector(V(k))),
                               values.atConstantBias(IB(k)), None)
            for key in self.builder.water_keys(k):
                if values.exists(key):
                    self.builder.observe_water(key, np.asarray(values.atVector(key)))

    def _rebase(self, k: int, t: float) -> None:
        """A fresh fixed-lag smoother (live mode) or iSAM2 with priors carrying the current marginals of
        the variables still in use: the newest pose, the compass-bias frame and the beacons."""
        keys = [F.X(k), *self.builder.carried_keys(k)]
        try:
            priors = joint_prior if self.solver.kind == "isam2" else marginal_priors
            self.solver.rebase(*priors(self.solver, self.space, keys, t))
        except SolverError as exc:
            raise solve_failure(exc, t, self._rec, self.n_records) from None
        self.fixes.forget()
        if self.aim is not None:
            self.aim.forget()
        self._base = k
        self.extra["rebases"] = self.extra.get("rebases", 0) + 1

    def info(self) -> dict[str, Any]:
        """Counts and timings so far (live mode's summary)."""
        s = np.asarray(self.track.step_ms)
        icp = np.asarray(self.track.icp_ms)
        return {"estimator": f"navigator ({self.cfg.solver})", **self.builder.info(), **self.extra,
                "keyframes_solved": self.builder.stepped,
                "icp_ms_median": float(np.median(icp)) if icp.size else None,
                "step_ms_median": float(np.median(s)) if s.size else None,
                "step_ms_p99": float(np.percentile(s, 99)) if s.size else None, **self._coast_info()}

    def online(self) -> Trajectory | None:
        """The online estimates so far (``None`` for batch)."""
        if not self.solver.online:
            return None
        return self.track.trajectory(f"{self.cfg.solver}-online")

    # -- the end ---------------------------------------------------------------------------------
    def smoothed(self) -> Trajectory:
        """Finish (:meth:`flush`) and return the smoothed trajectory with per-pose covariances."""
        return self.result().trajectory

    def result(self) -> RunResult:
        """Finish and return everything: smoothed and online trajectories, timings, info."""
        if self._result is None:
            self.flush()
            self._result = self._finish()
        return self._result

    def _finish(self) -> RunResult:
        cfg, b = self.cfg, self.builder
        n = len(b.kf_t)
        info = b.info()
        info["config"] = cfg.flat()
        info["solver"] = cfg.solver
        t = np.array(b.kf_t)
        if n == 0:
            empty = Trajectory(np.zeros(0), np.zeros((0, 3)), name=cfg.solver)
            return RunResult(empty, self.online(), np.zeros(0), np.array(self.track.icp_ms), info)
        c0, p0 = time.perf_counter(), time.process_time()
        closing = Closing(cfg, self.solver, self.space, self.groups, b.rejected_fixes, b.defaulted,
                          b.motion.intervals, b.meas.water.rows)
        try:
            values, poses, covs = closing.solve(n, self.front, info)
        except SolverError as exc:
            raise GraphnavError(f"the navigation graph could not be solved at the end of the log: {exc}",
                                where=f"record {self.n_records}") from None
        finally:
            self.groups = closing.groups
        final_ms = (time.perf_counter() - c0) * 1e3
        final_cpu = (time.process_time() - p0) * 1e3
        self._final = values
        if closing.kept is not None:  # fixed-lag without a history: the window only
            t = t[closing.kept]
        traj = Trajectory(t, np.array(poses).reshape(-1, 3), np.array(covs) if covs is not None else None,
                          name=cfg.solver)
        info["final_ms"] = final_ms
        if info.get("loop_edges"):  # the accepted loops as (older, newer) keyframe times, for plots
            info["loop_edge_times"] = [[float(t[i]), float(t[k])] for i, k in info["loop_edges"]]
        info.update(b.report(values))  # compass bias, beacons, IMU bias, water current
        info.update({**self.extra, **self._coast_info(), **self.fixes.info()})
        if self.aim is not None and self.aim.swapped:
            info["water_reaimed_online"] = self.aim.swapped
        if self.solver.online:
            info["step_cpu_ms_median"] = float(np.median(self.track.step_cpu)) if self.track.step_cpu else None
            step_ms = np.array(self.track.step_ms)
        else:
            solve_ms = final_ms + self.extra.get("batch_init_ms", 0.0)  # with the incremental initialisation
            info["solve_ms"] = solve_ms
            info["step_cpu_ms_median"] = final_cpu / n
            step_ms = np.full(n, solve_ms / n)
            if self.on_estimate is not None:
                for k in range(n):
                    self.on_estimate(float(t[k]), traj.poses[k], None if traj.cov is None else traj.cov[k])
        return RunResult(traj, self.online(), step_ms, np.array(self.track.icp_ms), info)


def batch_initialise(nav: Navigator, k: int, t: float) -> None:
    """Batch's incremental initial guess: LM over the graph so far from the current guess; the
    solution becomes the guess, and the poses and beacons to come are chained from it (not from
    dead reckoning of the whole log). Causal: only the records up to keyframe ``k`` are used."""
    c0 = time.perf_counter()
    lm = nav.solver.lm
    try:
        values, it = levenberg_marquardt(nav.solver.graph, nav.solver.initial,
                                         replace(lm, tol=max(lm.tol, 1e-8)))
    except SolverError as exc:
        raise solve_failure(exc, t, nav._rec, nav.n_records) from None
    nav.solver.initial = values
    nav._take(values, k)
    nav._next_init = max(k + 2, math.ceil((k + 1) * nav.cfg.optimizer.batch_init_growth))
    e = nav.extra
    e["batch_init_solves"] = e.get("batch_init_solves", 0) + 1
    e["batch_init_iterations"] = e.get("batch_init_iterations", 0) + it
    e["batch_init_ms"] = e.get("batch_init_ms", 0.0) + (time.perf_counter() - c0) * 1e3



QUIET = ("imu", "truth")  # the kinds :meth:`Navigator.add_quiet` takes in runs


def feed(nav: Navigator, records: Sequence[Record], checked: Sequence[bool]) -> None:
    """Every record of ``records`` into ``nav`` as ``nav.add(rec, checked=c)`` of each would (``c``: ``checked``
    at its place): the same keyframe steps, estimates and callbacks, in the same order. A run of checked IMU
    samples and truth poses (100 Hz and 10 Hz: 87 % of a vessel's log) goes in at once where it can make no
    keyframe ready (:meth:`Navigator.add_quiet`), the rest one by one."""
    n, i = len(records), 0
    while i < n:
        j = i
        while j < n and checked[j] and records[j].kind in QUIET:
            j += 1
        if j == i:
            nav.add(records[i], checked=checked[i])
            i += 1
            continue
        for _ in range(3):  # a keyframe waiting is readied by the run's first record (the second at its very time)
            if nav.add_quiet(records[i:j]):
                i = j
                break
            nav.add(records[i], checked=True)
            i += 1
            if i == j:
                break
        for rec in records[i:j]:  # (before the anchor, on a keyframe grid, a late record: one by one)
            nav.add(rec, checked=True)
        i = j
