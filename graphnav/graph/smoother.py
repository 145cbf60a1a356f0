"""The factor-graph smoother: every sensor of a :class:`NavLog` as native GTSAM factors, solved by
iSAM2 (incremental, online + smoothed), batch Levenberg-Marquardt, or an incremental fixed-lag
smoother.

:class:`GraphBuilder` turns the log into one batch of new factors/values per keyframe
(:mod:`graphnav.graph.keyframes`); the three drivers (:func:`run_isam2`, :func:`run_batch`,
:func:`run_fixed_lag`) consume the same batches, so they solve exactly the same problem.

Factors (see :mod:`factors`): an anchor ``PriorFactorPose2`` on the first pose; weighted-ICP
``BetweenFactorPose2`` with the matcher's full covariance; odometry ``BetweenFactorPose2``
(beacon paper eq. 3, propagated sigmas); robust ``PoseTranslationPrior2D`` GNSS fixes, gated
online by their Mahalanobis distance to the prediction; compass yaw through an estimated constant
bias frame; ``BearingRangeFactor2D`` beacons (charted ones with ``PriorFactorPoint2``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..config import config_from_options
from ..geometry import increment
from ..log import NavLog, Scan, odometry_samples
from ..result import OnEstimate, RunResult
from ..trajectory import Trajectory
from .keyframes import keyframe_times, schedule

Matcher = Callable[
    [Scan, Scan, NDArray[np.float64] | None], tuple[bool, NDArray[np.float64], NDArray[np.float64]]
]


@dataclass
class SmootherConfig:
    """Every tunable of the smoother (settable as ``-O key=value`` on ``graphnav run``)."""

    keyframe_period: float | None = None  # None: one pose per scan (fixed 0.5 s grid without scans)
    scan_stride: int = 1  # with scans: a keyframe (and an ICP match) every N-th scan
    gnss_robust: str | None = "huber"  # gross outliers are gated (online) or dropped (batch)
    gnss_k: float | None = None
    gnss_gate: float | None = (
        4.0  # reject fixes whose Mahalanobis distance to the online prediction exceeds it
    )
    gnss_gate_max_rejects: int = 15  # ...unless this many in a row were rejected (re-acquire after drift)
    compass_robust: str | None = "huber"
    compass_bias: bool = True  # estimate a constant compass bias (a bias-frame variable)
    compass_bias_sigma_deg: float = 10.0
    compass_sigma_scale: float = 1.0
    beacon_robust: str | None = "huber"
    unknown_beacons: bool = True  # SLAM on beacons missing from the chart
    use_icp: bool = True
    icp_robust: str | None = None  # robust kernel on ICP factors (None, "huber", "cauchy")
    icp_max_step: float = 5.0  # [m] an ICP step farther than this from the prediction is rejected
    use_odometry: bool = True
    odo_sigma_v: float = 0.1  # used when the log gives none
    odo_sigma_w_deg: float = 1.0
    odo_lateral: float = 0.05
    compensate_attachment: bool = True  # move each measurement to its keyframe's time by the motion between
    motion_sigma_xy: float = 2.0  # fallback constant-velocity factor when no ICP/odometry bridges a gap
    motion_sigma_yaw_deg: float = 20.0
    anchor_sigma_xy: float | None = None  # prior on the first pose when there is no pose_prior record
    anchor_sigma_yaw_deg: float = 30.0
    relinearize_threshold: float = 0.05  # poses: tangent-space change that triggers relinearization
    relinearize_threshold_landmarks: float = 0.5  # [m] beacons (many factors each: relinearize rarely)
    relinearize_threshold_bias_deg: float = 2.0  # compass-bias frame (one factor per compass reading)
    relinearize_skip: int = 1
    isam_extra_updates: int = 0  # extra ISAM2.update() calls per keyframe
    final_updates: int = 2  # extra ISAM2.update() calls after the last keyframe (the smoothed result)
    wildfire_threshold: float = 0.001  # iSAM2 back-substitution stops where the change is below this
    partial_relinearization_check: bool = True
    lm_tol: float = 1e-14  # batch LM relative/absolute error-decrease tolerance
    lag: float = 20.0  # fixed-lag window [s]
    covariances: bool = True  # per-pose marginal covariances on the final trajectory
    icp: dict[str, Any] = field(default_factory=dict)  # options for graphnav.scan.icp.IcpConfig

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> SmootherConfig:
        return config_from_options(cls, options, "smoother")


def default_matcher(options: dict[str, Any]) -> Matcher | None:
    """The weighted-ICP matcher of :mod:`graphnav.scan.icp`, or ``None`` when it is not available."""
    try:
        from ..scan.icp import IcpConfig, scan_points
        from ..scan.icp_cache import match_points  # shared between estimators inside icp_cache.active()
    except ImportError:
        return None
    cfg = IcpConfig(**options)
    last: list[Any] = [None, None]  # the previous call's current scan and its points

    def match(cur: Scan, prev: Scan, init: NDArray[np.float64] | None):
        prev_xy = last[1] if prev is last[0] else scan_points(prev, cfg)  # consecutive pairs: each scan once
        cur_xy = scan_points(cur, cfg)
        last[:] = [cur, cur_xy]
        r = match_points(cur_xy, prev_xy, cfg, init=init)
        return bool(r.ok), np.asarray(r.pose, dtype=float), np.asarray(r.cov, dtype=float)

    return match


def world_cov(pose: gtsam.Pose2, cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """GTSAM's body-tangent Pose2 covariance -> (x, y, yaw) covariance in the world frame."""
    c, s = math.cos(pose.theta()), math.sin(pose.theta())
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return R @ cov @ R.T


def _const(pose: gtsam.Pose2 | None) -> Callable[[int], gtsam.Pose2 | None]:
    """``estimate(key)`` for the builder: the estimate of the previous keyframe (the only one asked for)."""
    return lambda key: pose


def _vec(p: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([p.x(), p.y(), p.theta()])


@dataclass
class Step:
    """New factors/values of keyframe ``k`` (time ``t``) and the keys' timestamps (fixed-lag)."""

    k: int
    t: float
    graph: gtsam.NonlinearFactorGraph
    values: gtsam.Values
    stamps: dict[int, float]
    icp_ms: float | None = None
    gnss: list[tuple[int, float]] = field(default_factory=list)  # (index in graph, sigma) of GNSS factors


class GraphBuilder:
    """Turns a log into per-keyframe factor batches. Stateless about the solver: each step gets
    the current estimate of the previous pose (and optionally its world covariance)."""

    def __init__(self, log: NavLog, cfg: SmootherConfig, matcher: Matcher | None = None) -> None:
        self.log, self.cfg = log, cfg
        self.kf_t = keyframe_times(log, cfg.keyframe_period, cfg.scan_stride)
        if len(self.kf_t) == 0:
            raise ValueError("the log has no records to place keyframes on")
        scans = log.of("scan")
        self.scans = scans[:: cfg.scan_stride] if (cfg.keyframe_period is None and scans) else None
        icp_opts = dict(cfg.icp)
        lidar = log.meta.get("lidar", {}) if isinstance(log.meta.get("lidar"), dict) else {}
        for k in ("sigma_r_rel", "sigma_alpha"):  # the log's LiDAR error model, when it states one
            if k in lidar and k not in icp_opts:
                icp_opts[k] = float(lidar[k])
        self.matcher = (
            matcher
            if matcher is not None
            else (default_matcher(icp_opts) if (cfg.use_icp and self.scans) else None)
        )
        n = len(self.kf_t)
        self.pending: list[list[tuple[int, Any]]] = [[] for _ in range(n)]
        for kind in ("gnss", "heading", "beacon"):
            recs = log.of(kind)
            if not recs:
                continue
            att, add = schedule(self.kf_t, [r.t for r in recs])
            for r, a, s in zip(recs, att, add, strict=True):
                self.pending[int(s)].append((int(a), r))
        self.odo = (odometry_samples(log, cfg.odo_sigma_v, math.radians(cfg.odo_sigma_w_deg)) if cfg.use_odometry
                    else np.zeros((0, 5)))
        self.has_heading = bool(log.of("heading"))
        self.charted = {b.id: b for b in log.beacons_known}
        self.beacon_ids: dict[str, int] = {}
        self.beacon_init: dict[str, NDArray[np.float64]] = {}
        self.last_rel = gtsam.Pose2()
        self.n_rejected = 0
        self.consecutive_rejects = 0
        self.n_icp = self.n_icp_failed = 0
        self.bias_key = F.B(0) if (cfg.compass_bias and self.has_heading) else None
        self.anchor_pose, self.anchor_sigmas, self.anchor = self._anchor()

    # -- anchoring --------------------------------------------------------------------------------
    def _anchor(self) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        cfg, log = self.cfg, self.log
        prior = log.pose_prior()
        if prior is not None:
            return (
                np.array([prior.x, prior.y, prior.yaw]),
                np.array([prior.sigma_xy, prior.sigma_xy, prior.sigma_yaw]),
                "pose_prior",
            )
        yaw_sig = math.radians(cfg.anchor_sigma_yaw_deg)
        gnss, head = log.of("gnss"), log.of("heading")
        if gnss:
            g = gnss[0]
            yaw = head[0].yaw if head else 0.0
            sxy = cfg.anchor_sigma_xy if cfg.anchor_sigma_xy is not None else 3.0 * g.sigma
            ys = yaw_sig if head else math.pi
            return (
                np.array([g.x, g.y, yaw]),
                np.array([sxy, sxy, ys]),
                "first GNSS+compass" if head else "first GNSS",
            )
        obs = [r for r in log.of("beacon") if r.id in self.charted]
        if obs:
            t0 = obs[0].t
            first = {}
            for r in obs:
                if r.t > t0 + 1e-6:
                    break
                first.setdefault(r.id, r)
            sxy = cfg.anchor_sigma_xy if cfg.anchor_sigma_xy is not None else 10.0
            if len(first) >= 2:
                a, b = list(first.values())[:2]
                ca, cb = self.charted[a.id], self.charted[b.id]
                pose = F.pose_from_two_beacons(
                    (ca.x, ca.y), (a.range, a.bearing), (cb.x, cb.y), (b.range, b.bearing)
                )
                return pose, np.array([sxy, sxy, yaw_sig]), "charted beacons"
            a = obs[0]
            yaw = head[0].yaw if head else 0.0
            ca = self.charted[a.id]
            pos = np.array([ca.x, ca.y]) - a.range * np.array(
                [math.cos(yaw + a.bearing), math.sin(yaw + a.bearing)]
            )
            return (
                np.array([pos[0], pos[1], yaw]),
                np.array([sxy, sxy, yaw_sig if head else math.pi]),
                "charted beacons",
            )
        for r in log.records:
            if r.kind == "truth":  # nothing absolute in the log: the frame is the reference's start
                return np.array([r.x, r.y, r.yaw]), np.array([1e-3, 1e-3, 1e-4]), "truth (first pose)"
        return np.zeros(3), np.array([1e-3, 1e-3, 1e-4]), "origin"

    # -- relative motion --------------------------------------------------------------------------
    def _odometry(self, t0: float, t1: float) -> tuple[gtsam.Pose2, NDArray[np.float64]] | None:
        """Compose the odometry (zero-order hold of the latest sample) over ``[t0, t1]``; no motion
        before the first sample."""
        if len(self.odo) == 0 or self.odo[0, 0] > t0 + 1e-9 and self.odo[0, 0] >= t1:
            return None
        inc = increment(self.odo, max(t0, float(self.odo[0, 0])), t1, lateral=self.cfg.odo_lateral)
        if inc is None:
            return None
        return gtsam.Pose2(*inc[0]), inc[1]

    def _offset_motion(self, a: int, t: float, k: int) -> gtsam.Pose2 | None:
        """Motion from keyframe ``a`` to time ``t`` (``None`` when they coincide): odometry when the
        log has it, else the last relative motion scaled to the time offset (constant velocity)."""
        ta = float(self.kf_t[a])
        if abs(t - ta) < 1e-6:
            return None
        if len(self.odo):
            if t > ta:
                odo = self._odometry(ta, t)
                return None if odo is None else odo[0]
            odo = self._odometry(t, ta)
            return None if odo is None else odo[0].inverse()
        if k == 0:
            return None
        gap = float(self.kf_t[k] - self.kf_t[k - 1])
        return gtsam.Pose2.Expmap(gtsam.Pose2.Logmap(self.last_rel) * ((t - ta) / gap)) if gap > 0 else None

    # -- one keyframe -----------------------------------------------------------------------------
    def step(
        self,
        k: int,
        estimate: Callable[[int], gtsam.Pose2 | None],
        prev_cov: NDArray[np.float64] | None = None,
    ) -> Step:
        """Factors and new values of keyframe ``k``. ``estimate(key)`` gives the current estimate of an
        existing pose key (``None`` if unknown); ``prev_cov`` the world covariance of pose ``k-1``."""
        cfg = self.cfg
        t = float(self.kf_t[k])
        g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
        stamps: dict[int, float] = {F.X(k): t}
        icp_ms = None
        xk = F.X(k)
        if k == 0:
            p = self.anchor_pose
            pose_k = gtsam.Pose2(*p)
            g.add(gtsam.PriorFactorPose2(xk, pose_k, gtsam.noiseModel.Diagonal.Sigmas(self.anchor_sigmas)))
            if self.bias_key is not None:
                v.insert(self.bias_key, gtsam.Pose2())
                g.add(F.compass_bias_prior(self.bias_key, math.radians(cfg.compass_bias_sigma_deg)))
        else:
            prev = estimate(F.X(k - 1))
            t_prev = float(self.kf_t[k - 1])
            odo = self._odometry(t_prev, t)
            rel = None
            if odo is not None:
                g.add(F.odometry_between(F.X(k - 1), xk, odo[0], odo[1]))
                rel = odo[0]
            if self.matcher is not None:
                init = _vec(rel if rel is not None else self.last_rel)
                c0 = time.perf_counter()
                ok, mp, mc = self.matcher(self.scans[k], self.scans[k - 1], init)
                icp_ms = (time.perf_counter() - c0) * 1e3
                self.n_icp += 1
                if (
                    ok
                    and np.all(np.isfinite(mp))
                    and np.all(np.isfinite(mc))
                    and np.hypot(mp[0] - init[0], mp[1] - init[1]) <= cfg.icp_max_step
                ):
                    g.add(F.icp_between(F.X(k - 1), xk, mp, mc, robust=cfg.icp_robust))  # the match's own cov
                    rel = gtsam.Pose2(*mp)
                else:
                    self.n_icp_failed += 1
            if rel is None:  # nothing bridges the gap: a weak constant-velocity factor keeps the chain
                rel = self.last_rel
                s = np.array(
                    [cfg.motion_sigma_xy, cfg.motion_sigma_xy, math.radians(cfg.motion_sigma_yaw_deg)]
                )
                g.add(gtsam.BetweenFactorPose2(F.X(k - 1), xk, rel, gtsam.noiseModel.Diagonal.Sigmas(s)))
            self.last_rel = rel
            pose_k = prev.compose(rel)
        v.insert(xk, pose_k)
        if self.bias_key is not None:
            stamps[self.bias_key] = t

        def est(a: int) -> gtsam.Pose2:
            return pose_k if a == k else estimate(F.X(a))

        gnss_idx: list[tuple[int, float]] = []
        for a, r in self.pending[k]:
            xa = F.X(a)
            delta = self._offset_motion(a, r.t, k) if cfg.compensate_attachment else None
            if r.kind == "gnss":
                rx, ry = r.x, r.y
                if delta is not None:  # the fix is of the pose at r.t = X_a * delta: move it back to X_a
                    c, sn = math.cos(est(a).theta()), math.sin(est(a).theta())
                    rx -= c * delta.x() - sn * delta.y()
                    ry -= sn * delta.x() + c * delta.y()
                if cfg.gnss_gate is not None and prev_cov is not None:
                    pa = est(a)
                    d = np.array([rx - pa.x(), ry - pa.y()])
                    S = prev_cov[:2, :2] + (r.sigma**2) * np.eye(2)
                    if (
                        float(d @ np.linalg.solve(S, d)) > cfg.gnss_gate**2
                        and self.consecutive_rejects < cfg.gnss_gate_max_rejects
                    ):
                        self.n_rejected += 1
                        self.consecutive_rejects += 1
                        continue
                self.consecutive_rejects = 0
                gnss_idx.append((g.size(), r.sigma))
                g.add(F.gnss_factor(xa, rx, ry, r.sigma, robust=cfg.gnss_robust, k=cfg.gnss_k))
            elif r.kind == "heading":
                sig = r.sigma * cfg.compass_sigma_scale
                yaw = r.yaw - (delta.theta() if delta is not None else 0.0)
                if self.bias_key is not None:
                    g.add(F.biased_compass_factor(self.bias_key, xa, yaw, sig, robust=cfg.compass_robust))
                else:
                    g.add(F.compass_factor(xa, yaw, sig, robust=cfg.compass_robust))
            elif r.kind == "beacon":
                charted = self.charted.get(r.id)
                if charted is None and not cfg.unknown_beacons:
                    continue
                rng_, brg = r.range, r.bearing
                if delta is not None:  # the sighting from X_a * delta, as seen from X_a
                    ba = delta.transformFrom(np.array([rng_ * math.cos(brg), rng_ * math.sin(brg)]))
                    rng_, brg = float(np.hypot(ba[0], ba[1])), math.atan2(ba[1], ba[0])
                if r.id not in self.beacon_ids:
                    i = len(self.beacon_ids)
                    self.beacon_ids[r.id] = i
                    lk = F.L(i)
                    if charted is not None:
                        p0 = np.array([charted.x, charted.y])
                        g.add(F.beacon_prior(lk, charted.x, charted.y, charted.sigma))
                    else:
                        p0 = F.init_from_sighting(_vec(est(a)), rng_, brg)
                    self.beacon_init[r.id] = p0
                    v.insert(lk, p0)
                sr = r.sigma_range if math.isfinite(r.sigma_range) else 0.5
                sb = r.sigma_bearing if math.isfinite(r.sigma_bearing) else math.radians(0.5)
                g.add(
                    F.beacon_factor(
                        xa, F.L(self.beacon_ids[r.id]), rng_, brg, sr, sb, robust=cfg.beacon_robust
                    )
                )
        for i in self.beacon_ids.values():
            stamps[F.L(i)] = t
        return Step(k, t, g, v, stamps, icp_ms, gnss_idx)

    def info(self) -> dict[str, Any]:
        return {
            "anchor": self.anchor,
            "keyframes": len(self.kf_t),
            "gnss_rejected": self.n_rejected,
            "icp_pairs": self.n_icp,
            "icp_failed": self.n_icp_failed,
            "icp": self.matcher is not None,
            "beacons": sorted(self.beacon_ids),
            "compass_bias_estimated": self.bias_key is not None,
        }


# -- drivers ---------------------------------------------------------------------------------------
def _isam_params(cfg: SmootherConfig) -> gtsam.ISAM2Params:
    p = gtsam.ISAM2Params()
    th = gtsam.ISAM2ThresholdMap()  # per variable type (the symbol's character)
    th.insert(("x", np.full(3, cfg.relinearize_threshold)))
    th.insert(("l", np.full(2, cfg.relinearize_threshold_landmarks)))
    th.insert(("b", np.array([1.0, 1.0, math.radians(cfg.relinearize_threshold_bias_deg)])))
    p.setRelinearizeThreshold(th)
    p.relinearizeSkip = cfg.relinearize_skip
    p.enablePartialRelinearizationCheck = cfg.partial_relinearization_check
    gn = gtsam.ISAM2GaussNewtonParams()
    gn.setWildfireThreshold(cfg.wildfire_threshold)
    p.setOptimizationParams(gn)
    return p


def _finish(
    builder: GraphBuilder,
    t: list[float],
    poses: list,
    covs: list | None,
    name: str,
    values: gtsam.Values | None,
) -> tuple[Trajectory, dict[str, Any]]:
    cov = np.array(covs) if covs else None
    traj = Trajectory(np.array(t), np.array(poses).reshape(-1, 3), cov, name=name)
    info = builder.info()
    info["config"] = asdict(builder.cfg)
    if values is not None:
        if builder.bias_key is not None and values.exists(builder.bias_key):
            info["compass_bias_deg"] = math.degrees(F.compass_bias(values.atPose2(builder.bias_key)))
        info["beacon_init"] = {bid: p.tolist() for bid, p in builder.beacon_init.items()}
        info["beacon_estimates"] = {
            bid: values.atPoint2(F.L(i)).tolist()
            for bid, i in builder.beacon_ids.items()
            if values.exists(F.L(i))
        }
    return traj, info


def run_isam2(
    log: NavLog, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None, **options: Any
) -> RunResult:
    """One ``ISAM2.update`` per keyframe; online = ``calculateEstimatePose2(newest)`` + its marginal."""
    cfg = SmootherConfig.from_options(options)
    b = GraphBuilder(log, cfg, matcher)
    isam = gtsam.ISAM2(_isam_params(cfg))
    on_t, on_p, on_c, step_ms, icp_ms, step_cpu = [], [], [], [], [], []
    last_pose, last_cov = None, None
    for k in range(len(b.kf_t)):
        s = b.step(k, _const(last_pose), last_cov)  # only X(k-1) is ever asked for
        if s.icp_ms is not None:
            icp_ms.append(s.icp_ms)
        c0, p0 = time.perf_counter(), time.process_time()
        isam.update(s.graph, s.values)
        for _ in range(cfg.isam_extra_updates):
            isam.update()
        pose = isam.calculateEstimatePose2(F.X(k))
        cov = world_cov(pose, isam.marginalCovariance(F.X(k)))
        step_ms.append((time.perf_counter() - c0) * 1e3)
        step_cpu.append((time.process_time() - p0) * 1e3)
        last_pose, last_cov = pose, cov
        on_t.append(s.t)
        on_p.append(_vec(pose))
        on_c.append(cov)
        if on_estimate is not None:
            on_estimate(s.t, on_p[-1], cov)
    for _ in range(cfg.final_updates):
        isam.update()
    est = isam.calculateBestEstimate()  # full back-substitution (no wildfire cut-off)
    poses = [_vec(est.atPose2(F.X(k))) for k in range(len(b.kf_t))]
    covs = None
    if cfg.covariances:
        covs = [world_cov(est.atPose2(F.X(k)), isam.marginalCovariance(F.X(k))) for k in range(len(b.kf_t))]
    traj, info = _finish(b, on_t, poses, covs, "isam2", est)
    info["step_cpu_ms_median"] = float(np.median(step_cpu))  # process CPU time: robust to machine load
    online = Trajectory(np.array(on_t), np.array(on_p), np.array(on_c), name="isam2-online")
    return RunResult(traj, online, np.array(step_ms), np.array(icp_ms), info)


def _gnss_sigma(f: gtsam.PoseTranslationPrior2D) -> float:
    """The isotropic sigma of a (possibly robust) GNSS factor's noise model."""
    nm = f.noiseModel()
    base = nm.noise() if hasattr(nm, "noise") else nm
    return float(base.sigmas()[0])


def run_batch(
    log: NavLog, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None, **options: Any
) -> RunResult:
    """Levenberg-Marquardt over the whole log (initialised by chaining the relative measurements);
    GNSS fixes left with a residual beyond ``gnss_gate`` sigmas are dropped and LM re-run."""
    cfg = SmootherConfig.from_options(options)
    b = GraphBuilder(log, cfg, matcher)
    graph, init = gtsam.NonlinearFactorGraph(), gtsam.Values()
    icp_ms = []
    gnss_sigma: dict[int, float] = {}
    last = None
    for k in range(len(b.kf_t)):
        s = b.step(k, _const(last))
        if s.icp_ms is not None:
            icp_ms.append(s.icp_ms)
        for i, sig in s.gnss:
            gnss_sigma[graph.size() + i] = sig
        graph.push_back(s.graph)
        init.insert(s.values)
        last = s.values.atPose2(F.X(k))
    c0, p0 = time.perf_counter(), time.process_time()
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    params.setRelativeErrorTol(cfg.lm_tol)
    params.setAbsoluteErrorTol(cfg.lm_tol)
    result = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    dropped = 0
    for _ in range(3 if cfg.gnss_gate is not None else 0):  # drop gross GNSS outliers, re-solve
        keep, n_drop = gtsam.NonlinearFactorGraph(), 0
        for i in range(graph.size()):
            f = graph.at(i)
            if (
                i in gnss_sigma
                and float(np.hypot(*f.unwhitenedError(result))) / gnss_sigma[i] > cfg.gnss_gate
            ):
                n_drop += 1
                continue
            keep.add(f)
        if not n_drop:
            break
        dropped += n_drop
        gnss_sigma = {}  # indices shift; the kept GNSS factors are re-found below
        for i in range(keep.size()):
            if isinstance(keep.at(i), gtsam.PoseTranslationPrior2D):
                gnss_sigma[i] = _gnss_sigma(keep.at(i))
        graph = keep
        result = gtsam.LevenbergMarquardtOptimizer(graph, result, params).optimize()
    solve_ms = (time.perf_counter() - c0) * 1e3
    solve_cpu_ms = (time.process_time() - p0) * 1e3
    n = len(b.kf_t)
    poses = [_vec(result.atPose2(F.X(k))) for k in range(n)]
    covs = None
    if cfg.covariances:
        m = gtsam.Marginals(graph, result)
        covs = [world_cov(result.atPose2(F.X(k)), m.marginalCovariance(F.X(k))) for k in range(n)]
    traj, info = _finish(b, list(b.kf_t), poses, covs, "batch", result)
    info["gnss_dropped_after_lm"] = dropped
    info["solve_ms"] = solve_ms
    info["step_cpu_ms_median"] = solve_cpu_ms / n
    if on_estimate is not None:
        for k in range(n):
            on_estimate(float(b.kf_t[k]), poses[k], None if covs is None else covs[k])
    return RunResult(traj, None, np.full(n, solve_ms / n), np.array(icp_ms), info)


def run_fixed_lag(
    log: NavLog, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None, **options: Any
) -> RunResult:
    """``IncrementalFixedLagSmoother`` with a ``lag`` [s] window: bounded memory on long runs. The
    final trajectory holds each pose's estimate (and marginal) as it leaves the window."""
    cfg = SmootherConfig.from_options(options)
    b = GraphBuilder(log, cfg, matcher)
    fl = gtsam.IncrementalFixedLagSmoother(cfg.lag, _isam_params(cfg))
    n = len(b.kf_t)
    final_p: list = [None] * n
    final_c: list = [None] * n
    on_t, on_p, on_c, step_ms, icp_ms, step_cpu = [], [], [], [], [], []
    last_pose, last_cov = None, None
    oldest = 0
    for k in range(n):
        s = b.step(k, _const(last_pose), last_cov)
        if s.icp_ms is not None:
            icp_ms.append(s.icp_ms)
        c0, p0 = time.perf_counter(), time.process_time()
        # poses about to leave the window: keep their last smoothed estimate
        while oldest < k and b.kf_t[oldest] < s.t - cfg.lag:
            p = fl.calculateEstimatePose2(F.X(oldest))
            final_p[oldest] = _vec(p)
            if cfg.covariances:
                final_c[oldest] = world_cov(p, fl.marginalCovariance(F.X(oldest)))
            oldest += 1
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        for key, ts in s.stamps.items():
            stamps.insert((key, ts))
        fl.update(s.graph, s.values, stamps)
        pose = fl.calculateEstimatePose2(F.X(k))
        cov = world_cov(pose, fl.marginalCovariance(F.X(k)))
        step_ms.append((time.perf_counter() - c0) * 1e3)
        step_cpu.append((time.process_time() - p0) * 1e3)
        last_pose, last_cov = pose, cov
        on_t.append(s.t)
        on_p.append(_vec(pose))
        on_c.append(cov)
        if on_estimate is not None:
            on_estimate(s.t, on_p[-1], cov)
    est = fl.calculateEstimate()
    for k in range(oldest, n):
        p = est.atPose2(F.X(k))
        final_p[k] = _vec(p)
        if cfg.covariances:
            final_c[k] = world_cov(p, fl.marginalCovariance(F.X(k)))
    traj, info = _finish(b, on_t, final_p, final_c if cfg.covariances else None, "fixed-lag", est)
    info["step_cpu_ms_median"] = float(np.median(step_cpu))
    online = Trajectory(np.array(on_t), np.array(on_p), np.array(on_c), name="fixed-lag-online")
    return RunResult(traj, online, np.array(step_ms), np.array(icp_ms), info)


def unmet(log: NavLog) -> str | None:
    """Why the smoother cannot run on ``log`` (``None`` if it can)."""
    if not len(log):
        return "the log is empty"
    kinds = log.counts()
    if not any(kinds.get(k) for k in ("scan", "odometry", "gnss", "beacon")):
        return "needs scans, odometry, GNSS or beacon observations"
    return None
