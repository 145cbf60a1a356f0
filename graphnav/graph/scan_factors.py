"""Scan and cloud factors of the navigation graph: the weighted-ICP matcher (its guess, covariance
and acceptance rule), the loop closer's matcher, and the 3D cloud path (GICP projected to SE(2)).

A match becomes a between factor with the match's own covariance (:mod:`graphnav.scan.covariance`);
:func:`screen_match` is the one acceptance rule for scans and clouds (failed / gated / kept).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..log import Cloud, Scan
from .smoother_config import ScanConfig
from .step import Step

#: ``matcher(cur, prev, init, init_cov, guess_in_graph) -> (usable, pose, cov)``: ``init`` the motion
#: guess prev -> cur and ``init_cov`` its covariance (the odometry integrated, the IMU's prediction, else
#: the motion model's); ``guess_in_graph``: which factor of the graph that guess is already (``"odometry"``,
#: ``"imu"``; ``""``: none, the motion model's), so the match's factor must not repeat it along the
#: directions it does not observe (a non-empty string is true: a matcher may test it as a flag)
Matcher = Callable[
    [Scan, Scan, NDArray[np.float64] | None, NDArray[np.float64] | None, str],
    tuple[bool, NDArray[np.float64], NDArray[np.float64]],
]
#: [m^2, m^2, rad^2] the factor's covariance added along a degenerate match's weak directions when the
#: guess there is already in the graph: the factor then says nothing there (the matcher's failure value)
UNOBSERVED_COV = np.diag([1e4, 1e4, 10.0])


def default_matcher(options: dict[str, Any], sweep_s: float = 0.0) -> Matcher | None:
    """The weighted-ICP matcher of :mod:`graphnav.scan.weighted_icp`, or ``None`` when it is not available.
    A match is usable when it converged, or when it was flagged degenerate only (its covariance is
    then inflated along the unobserved directions, which the factor keeps weak).

    The guess's covariance goes to the matcher as ``init_cov``: a match beyond the 99.9 % bound of
    both covariances from the guess fails (another minimum), and a direction the guess knows better
    is weak. Along weak directions the matcher returns the guess with the guess's covariance; when
    the guess is a factor of the graph already (``guess_in_graph``) the match's factor gets
    :data:`UNOBSERVED_COV` there instead, so the guess is not counted twice.

    With the IMU's prediction as the guess (``"imu"``) the factor is the match's own estimate and
    covariance (:meth:`~graphnav.scan.weighted_icp.MatchResult.own`), weak only where the scans'
    geometry is: "a direction the guess knows better" compares one step's covariances, and the IMU's
    error between keyframes is mostly its bias, the same from step to step, which the matches'
    independent errors average out and its one-step covariance does not show (docs/smoother.md, "The
    LiDAR in the IMU graph"). The odometry's factor is white noise step by step: there the rule stays
    (measured on CARMEN: mixed, docs/smoother.md).

    With a LiDAR ``sweep_s`` (``meta["lidar"]``, 0: instantaneous scans) both scans' points are de-skewed to
    their stamps with the guess's constant twist ``Log(init) / (cur.t - prev.t)`` (:mod:`graphnav.scan.deskew`)."""
    try:
        from ..scan.icp_cache import match_points  # shared between estimators inside icp_cache.active()
        from ..scan.weighted_icp import IcpConfig, scan_points
    except ImportError:
        return None
    cfg = IcpConfig(**options)
    last: list[Any] = [None, None]  # the previous call's current scan and its points

    def match(cur: Scan, prev: Scan, init: NDArray[np.float64] | None,
              init_cov: NDArray[np.float64] | None = None, guess_in_graph: str = ""):
        twist = _sweep_twist(sweep_s, cur, prev, init)
        if twist is not None:  # de-skewed with this pair's twist: nothing to share with the next pair
            prev_xy = scan_points(prev, cfg, sweep_s=sweep_s, twist=twist)
            cur_xy = scan_points(cur, cfg, sweep_s=sweep_s, twist=twist)
            last[:] = [None, None]
        else:
            prev_xy = last[1] if prev is last[0] else scan_points_of(prev, cfg)  # consecutive pairs: each scan once
            cur_xy = scan_points_of(cur, cfg)
            last[:] = [cur, cur_xy]
        r = match_points(cur_xy, prev_xy, cfg, init=init, init_cov=init_cov)
        inflated = bool(r.quality.get("inflated", False))
        if guess_in_graph == "imu" and (r.ok or inflated):  # the match's own, weak where the geometry is
            pose, cov, weak = r.own()
            cov = np.asarray(cov, dtype=float)
            if weak is not None:
                cov = cov + weak @ UNOBSERVED_COV @ weak.T
            return True, np.asarray(pose, dtype=float), cov
        cov = np.asarray(r.cov, dtype=float)
        if inflated and guess_in_graph and r.quality.get("weak_projector") is not None:
            p = np.asarray(r.quality["weak_projector"], dtype=float)
            cov = cov + p @ UNOBSERVED_COV @ p.T
        return bool(r.ok) or inflated, np.asarray(r.pose, dtype=float), cov

    return match


def _sweep_twist(sweep_s: float, cur: Scan, prev: Scan, init: NDArray[np.float64] | None
                 ) -> NDArray[np.float64] | None:
    """The constant twist (vx, vy, wz) the guess ``init`` (prev -> cur) implies over ``cur.t - prev.t``, or
    ``None`` (no sweep, no finite guess, no time between the scans): the de-skew's input."""
    dt = float(cur.t) - float(prev.t)
    if not sweep_s or init is None or not dt > 0.0 or not np.all(np.isfinite(init)):
        return None
    from ..scan.deskew import twist_of

    return twist_of(np.asarray(init, dtype=float), dt)


def conjugate(pose: NDArray[np.float64], cov: NDArray[np.float64] | None, frame: gtsam.Pose2
              ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """A relative pose and its covariance expressed in ``frame`` instead: ``frame T frame^-1`` and
    ``Ad(frame) cov Ad(frame)^T``. With ``frame`` the LiDAR's extrinsic (its pose in the body frame) a
    sensor-frame match becomes the body's motion; with its inverse, the reverse."""
    T = frame.compose(gtsam.Pose2(*pose)).compose(frame.inverse())
    out = np.array([T.x(), T.y(), T.theta()])
    if cov is None:
        return out, None
    A = frame.AdjointMap()
    return out, A @ np.asarray(cov, dtype=float) @ A.T


def mounted(matcher: Matcher | None, extrinsic: gtsam.Pose2 | None) -> Matcher | None:
    """``matcher`` for a LiDAR mounted at ``extrinsic`` (body frame): its guess goes to the sensor frame,
    its match (and covariance) comes back to the body frame (:func:`conjugate`); unchanged without one."""
    if matcher is None or extrinsic is None:
        return matcher
    inv = extrinsic.inverse()

    def match(cur: Scan, prev: Scan, init: NDArray[np.float64] | None,
              init_cov: NDArray[np.float64] | None = None, guess_in_graph: str = ""):
        if init is not None:
            init, init_cov = conjugate(np.asarray(init, dtype=float), init_cov, inv)
        ok, pose, cov = matcher(cur, prev, init, init_cov, guess_in_graph)
        if not np.all(np.isfinite(pose)):
            return ok, pose, cov
        body, bcov = conjugate(np.asarray(pose, dtype=float), cov, extrinsic)
        return ok, body, bcov

    return match


def make_loop_closer(cfg: ScanConfig, icp_opts: dict[str, Any], extrinsic: gtsam.Pose2 | None = None) -> Any:
    """The loop closer of :mod:`graphnav.graph.loops` with the weighted ICP as its refinement and the
    graph's ICP covariance treatment (the match's own, as the consecutive factors; the loop closer
    adds its floor); ``None`` without the matcher. With a LiDAR ``extrinsic`` the places' points are
    moved into the body frame (the places are body poses)."""
    try:
        from ..scan.weighted_icp import IcpConfig, match_points
    except ImportError:
        return None
    from .loops import LoopCloser, LoopConfig

    icfg = IcpConfig(**icp_opts)

    def refine(src: NDArray[np.float64], tgt: NDArray[np.float64], init: NDArray[np.float64]):
        r = match_points(src, tgt, icfg, init=init)
        return bool(r.ok), np.asarray(r.pose, dtype=float), np.asarray(r.cov, dtype=float), r.quality

    from dataclasses import fields

    known = {f.name for f in fields(LoopConfig)}
    unknown = sorted(set(cfg.loop) - known)
    if unknown:
        raise ValueError(f"unknown loop option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    if extrinsic is None:
        def points(scan: Scan) -> NDArray[np.float64]:
            return scan_points_of(scan, icfg)
    else:
        c, s = math.cos(extrinsic.theta()), math.sin(extrinsic.theta())
        rot, off = np.array([[c, s], [-s, c]]), np.array([extrinsic.x(), extrinsic.y()])

        def points(scan: Scan) -> NDArray[np.float64]:
            return scan_points_of(scan, icfg) @ rot + off
    return LoopCloser(LoopConfig(**cfg.loop), refine, lambda c: proper_cov(np.asarray(c, dtype=float), np.zeros(3)),
                      points)


#: the newest scan's points and the config they were made with (:func:`scan_points_of`)
_newest_points: tuple[Any, Any, NDArray[np.float64] | None] = (None, None, None)


def scan_points_of(scan: Scan, icfg: Any) -> NDArray[np.float64]:
    """A scan's points (:func:`graphnav.scan.weighted_icp.scan_points`, not de-skewed), a copy: the newest
    scan's are kept for the next one asking with an equal config (the matcher and the loop closer take each
    keyframe's scan in turn)."""
    global _newest_points
    last, cfg, pts = _newest_points
    if last is not scan or pts is None or not (cfg is icfg or cfg == icfg):
        from ..scan.weighted_icp import scan_points

        pts = scan_points(scan, icfg)
        _newest_points = (scan, icfg, pts)
    return pts.copy()


def screen_match(cfg: ScanConfig, ok: bool, mp: Any, cov: NDArray[np.float64] | None, init: NDArray[np.float64],
                 odo_rel: gtsam.Pose2 | None, odo_cov: NDArray[np.float64] | None) -> str | None:
    """Whether a scan or cloud match becomes a factor: ``"failed"`` (not usable, no proper
    covariance, not finite, or farther than ``icp_max_step`` from the guess), ``"gated"`` (beyond
    ``icp_gate`` Mahalanobis units of ``odo_cov + cov`` from the odometry increment) or None (kept)."""
    if (not ok or cov is None or not np.all(np.isfinite(mp))
            or np.hypot(mp[0] - init[0], mp[1] - init[1]) > cfg.icp_max_step):
        return "failed"
    if cfg.icp_gate is not None and odo_rel is not None and odo_cov is not None:
        d = np.asarray(gtsam.Pose2.Logmap(odo_rel.between(gtsam.Pose2(*mp))))
        if float(d @ np.linalg.solve(odo_cov + cov, d)) > cfg.icp_gate**2:
            return "gated"
    return None


class CloudPath:
    """The 3D path of the builder: consecutive keyframe clouds -> GICP in levelled frames -> an SE(2)
    between factor (group ``cloud``) with the marginal (x, y, yaw) of the match's own sandwich
    covariance (:func:`graphnav.scan.cloud_match.match_covariance`, not scaled) plus a floor; gated
    against the odometry like the 2D matches (``icp_gate``, ``icp_max_step``); z/roll/pitch of each
    match kept as diagnostics (docs/scan-matching-3d.md)."""

    def __init__(self, cfg: ScanConfig, lidar3d: dict[str, Any] | None,
                 extrinsic: gtsam.Pose2 | None = None) -> None:
        self.cfg = cfg
        self.extrinsic = extrinsic  # the LiDAR's planar mount: matches conjugated to the body frame
        self.height = float(lidar3d["mast"]) if lidar3d and "mast" in lidar3d else None
        self.matcher: Any = None
        self.n = self.failed = self.gated = 0
        self.diag: list[tuple[float, float, float]] = []  # z, roll, pitch of each used match

    def factor(self, s: Step, k: int, cur: Cloud, prev: Any, odo_rel: gtsam.Pose2 | None,
               odo_cov: NDArray[np.float64] | None, last_rel: gtsam.Pose2
               ) -> tuple[gtsam.Pose2, NDArray[np.float64]] | None:
        """The GICP factor of keyframe ``k``'s cloud ``cur`` against ``prev`` (added to ``s``): the
        relative pose and its covariance, or ``None`` (no previous cloud, failed or gated)."""
        cfg = self.cfg
        if not isinstance(prev, Cloud):
            return None
        if self.matcher is None:
            from ..scan.cloud_match import CloudMatchConfig, CloudMatcher

            self.matcher = CloudMatcher(CloudMatchConfig.from_options(dict(cfg.cloud)), self.height)
        init = _vec(odo_rel if odo_rel is not None else last_rel)
        c0 = time.perf_counter()
        if self.extrinsic is None:
            ok, mp, mc = self.matcher(cur, prev, init)
        else:
            ok, mp, mc = self.matcher(cur, prev, conjugate(init, None, self.extrinsic.inverse())[0])
            if ok and np.all(np.isfinite(mp)):
                mp, mc = conjugate(np.asarray(mp, dtype=float), mc, self.extrinsic)
        s.icp_ms = (time.perf_counter() - c0) * 1e3
        self.n += 1
        floor = np.array([cfg.cloud_sigma_floor_xy] * 2 + [math.radians(cfg.cloud_sigma_floor_yaw_deg)])
        cov = proper_cov(np.asarray(mc, dtype=float), floor) if ok else None
        verdict = screen_match(cfg, ok, mp, cov, init, odo_rel, odo_cov)
        if verdict is not None:
            self.failed += verdict == "failed"
            self.gated += verdict == "gated"
            return None
        last = self.matcher.last
        self.diag.append((last["z"], last["roll"], last["pitch"]))
        s.add(s.space.between(F.X(k - 1), F.X(k), mp, cov, robust=cfg.icp_robust), "cloud")
        return gtsam.Pose2(*mp), cov

    def info(self) -> dict[str, Any]:
        if self.matcher is None:
            return {}
        d = np.array(self.diag).reshape(-1, 3)
        rms = np.sqrt(np.mean(d**2, axis=0)) if len(d) else np.full(3, np.nan)
        return {"cloud_pairs": self.n, "cloud_failed": self.failed, "cloud_gated": self.gated,
                "cloud_sensor_height": self.height,
                "cloud_dropped_rms": {"z_m": float(rms[0]), "roll_deg": float(np.degrees(rms[1])),
                                      "pitch_deg": float(np.degrees(rms[2]))}}


class ScanFactors:
    """The LiDAR's factors of the graph: each keyframe's scan matched to the previous keyframe's (the
    weighted ICP, group ``icp``; 3D clouds through :class:`CloudPath`, group ``cloud``) and the loop
    closer (:mod:`graphnav.graph.loops`, group ``loop``), which is fed every keyframe.

    ``matcher``: replaces the weighted ICP (tests); ``lidar``: the log's LiDAR error model
    (``sigma_r_rel``, ``sigma_alpha``); ``mount``: the LiDAR's mount (its planar part is the extrinsic)."""

    def __init__(self, cfg: ScanConfig, space: Any, *, matcher: Matcher | None = None,
                 lidar: dict[str, Any] | None = None, lidar3d: dict[str, Any] | None = None, mount: Any = None) -> None:
        self.cfg = cfg
        self.space = space
        self.extrinsic = None if mount is None or mount.is_identity else gtsam.Pose2(*mount.planar)
        self.cloud3d = CloudPath(cfg, lidar3d, self.extrinsic)  # the 3D path (clouds): graphnav.scan.cloud_match
        icp_opts = dict(cfg.icp)
        for k in ("sigma_r_rel", "sigma_alpha"):  # the log's LiDAR error model, when it states one
            if lidar and k in lidar and k not in icp_opts:
                icp_opts[k] = float(lidar[k])
        self._matcher_given = matcher
        self._icp_opts = icp_opts
        #: [s] the LiDAR's sweep (meta["lidar"]["sweep_s"]); scans are de-skewed when it is stated and cfg.deskew
        self.sweep_s = float(lidar.get("sweep_s", 0.0) or 0.0) if lidar and cfg.deskew else 0.0
        self.matcher: Matcher | None = None
        self.loops: Any = None  # graphnav.graph.loops.LoopCloser, with scans and cfg.loops
        self._loop_cov: NDArray[np.float64] | None = None  # the loop closer's covariance of the newest pose
        self.n = self.failed = self.gated = 0

    def want_matcher(self) -> None:
        """Scans come: the matcher (unless ``use_icp`` is off) and the loop closer (``loops``)."""
        if self.matcher is None and self.cfg.use_icp:
            self.matcher = mounted(self._matcher_given if self._matcher_given is not None
                                   else default_matcher(self._icp_opts, self.sweep_s), self.extrinsic)
        if self.loops is None and self.cfg.loops:
            self.loops = make_loop_closer(self.cfg, self._icp_opts, self.extrinsic)

    def match(self, s: Step, k: int, cur: Any, prev: Any, odo_rel: gtsam.Pose2 | None,
              odo_cov: NDArray[np.float64] | None, guess: tuple[Any, NDArray[np.float64], NDArray[np.float64]] | None,
              last_rel: gtsam.Pose2, prior: Callable[[], tuple[gtsam.Pose2, NDArray[np.float64], str]]
              ) -> tuple[gtsam.Pose2, NDArray[np.float64]] | None:
        """The match factor of keyframe ``k``'s scan ``cur`` against ``k-1``'s ``prev`` (added to ``s``):
        the relative pose and its covariance, or ``None`` when there is no usable match. The guess is
        the odometry (``odo_rel``, ``odo_cov``); without it the IMU's prediction (``guess``: state,
        relative pose, covariance), which is in the graph already (the ``ImuFactor``): along the
        directions the match cannot see, its factor says nothing and the IMU and GNSS decide; else
        the motion model's ``prior()`` (constant velocity from the last measured motion, random walk)."""
        in_graph = "odometry"
        if odo_rel is None and guess is not None:
            odo_rel, odo_cov, in_graph = gtsam.Pose2(*guess[1]), guess[2], "imu"
        if isinstance(cur, Cloud):
            return self.cloud3d.factor(s, k, cur, prev, odo_rel, odo_cov, last_rel)
        cfg = self.cfg
        if self.matcher is None or cur is None or prev is None:
            return None
        if odo_rel is not None and odo_cov is not None:  # the guess and its covariance: the odometry or IMU ...
            init, init_cov = _vec(odo_rel), odo_cov
        else:  # ... else the motion model's (constant velocity from the last measured motion, random walk)
            mean, init_cov, _ = prior()
            init, in_graph = _vec(mean), ""
        c0 = time.perf_counter()
        ok, mp, mc = self.matcher(cur, prev, init, init_cov, in_graph)
        s.icp_ms = (time.perf_counter() - c0) * 1e3
        self.n += 1
        cov = proper_cov(np.asarray(mc, dtype=float), np.zeros(3)) if ok else None  # the match's own, as is
        verdict = screen_match(cfg, ok, mp, cov, init, odo_rel, odo_cov)
        if verdict is not None:
            self.failed += verdict == "failed"
            self.gated += verdict == "gated"
            return None
        s.add(self.space.between(F.X(k - 1), F.X(k), mp, cov, robust=cfg.icp_robust), "icp")
        return gtsam.Pose2(*mp), cov

    def close_loops(self, s: Step, k: int, pose_k: gtsam.Pose2, prev: gtsam.Pose2 | None,
                    prev_cov: NDArray[np.float64] | None, rel: gtsam.Pose2 | None,
                    step_cov: NDArray[np.float64] | None, anchor_cov: NDArray[np.float64], scan: Any,
                    oldest: int) -> None:
        """Keyframe ``k`` to the loop closer: its predicted pose and world covariance (propagated from
        the solver's marginal of ``k-1``, ``prev_cov``, when online, else from the closer's own chain;
        keyframe 0's is the anchor's), its scan; ``oldest``: the oldest keyframe still in the solver."""
        from .loops import propagate

        if k == 0 or prev is None or rel is None or step_cov is None:
            cov_w = anchor_cov
        else:
            base = prev_cov if prev_cov is not None else self._loop_cov
            cov_w = propagate(base if base is not None else np.zeros((3, 3)), _vec(prev), rel, step_cov)
        self._loop_cov = cov_w
        xy = self.loops.points(scan) if isinstance(scan, Scan) else None  # 2D scans only (not 3D clouds)
        self.loops.step(s, k, pose_k, cov_w, rel, step_cov, xy, oldest)

    def info(self) -> dict[str, Any]:
        return {"icp_pairs": self.n, "icp_failed": self.failed, "icp_gated": self.gated,
                "icp": self.matcher is not None, **({"icp_deskew_sweep_s": self.sweep_s} if self.sweep_s else {})}


def _vec(p: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([p.x(), p.y(), p.theta()])


def proper_cov(cov: NDArray[np.float64], floor: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """A symmetric positive-definite covariance: ``cov`` symmetrised plus ``diag(floor^2)``; ``None``
    when it is not finite or not positive semi-definite (beyond rounding)."""
    c = np.asarray(cov, dtype=float)
    if c.shape != (3, 3) or not np.all(np.isfinite(c)):
        return None
    c = 0.5 * (c + c.T)
    ev = np.linalg.eigvalsh(c)
    if ev[0] < -1e-9 * max(1.0, ev[-1]):
        return None
    return c + np.diag(np.square(floor))
