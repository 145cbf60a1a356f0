"""Weighted-ICP dead reckoning: chain the scan matches from the start pose.

Scan ``k+1`` is matched to scan ``k`` (:func:`graphnav.scan.weighted_icp.match_points`; initial guess the
odometry increment with its covariance when the log has odometry, else the IMU's prediction with its
covariance when it has an IMU (:mod:`graphnav.scan.imu_guess`: LiDAR-inertial odometry), else
constant velocity) and the
increment is composed onto the previous pose; the covariance is propagated to first order
(``P' = Ad P Ad^T + Q`` in the body frame, GTSAM's convention) and reported in the world frame
(the :class:`~graphnav.trajectory.Trajectory` convention).
The start pose is the graph's anchor: the log's pose prior, else the first GNSS fix and compass
reading, ... (:func:`graphnav.estimators.start.log_start`). Initial guesses come from
:class:`~graphnav.scan.motion_guess.MotionGuess` (never from a flagged match). A flagged match (``ok``
False: degenerate geometry, too few points or inliers, not converged, or beyond the odometry guess's
99.9 % bound) is bridged by the odometry increment with its
covariance when the log has odometry, else by the IMU's prediction, else by the constant-velocity
guess with a wide covariance, and counted (``info["failed_matches"]``, ``info["bridged_odometry"]``,
``info["bridged_imu"]``, ``info["bridged_cv"]``). A match
flagged for degeneracy only, from an odometry guess, is chained as returned (the match across its weak
directions, the guess along them) with its covariance (the match's across, the odometry's along;
``info["constrained"]``).

LiDAR-inertial (an IMU, no odometry): each keyframe match enters by its own information
(:meth:`~graphnav.scan.weighted_icp.MatchResult.own`) where it agrees with the IMU's prediction, in one
filter over the keyframe's pose, the IMU's state (velocity and, with ``gyro_bias``, the gyro's bias) and
the increment (:meth:`_KeyframeChain._match_joint`; docs/weighted-icp.md "icp-dr: LiDAR-inertial").
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from ..config import option
from ..geometry import cov_to_world, se2_adjoint_inv, se2_compose
from ..log import NavLog, Scan, odometry_samples
from ..result import OnEstimate, RunResult
from ..scan import icp_cache
from ..scan.deskew import sweep_of
from ..scan.imu_guess import ImuGuess, fuse_se2, log_imu_guess
from ..scan.lio import imu_tangent, lio_step
from ..scan.motion_guess import MotionGuess
from ..scan.weighted_icp import IcpConfig, MatchResult, scan_points
from ..trajectory import Trajectory
from .base import BatchEstimator
from .gating import consistent
from .start import log_start

_CONFIG_FIELDS = {f.name for f in fields(IcpConfig)}



def _to_world(pose: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Body-frame (right-perturbation) covariance -> the trajectory's world-frame (x, y, yaw)."""
    return cov_to_world(float(pose[2]), cov)


class _KeyframeChain:
    """icp-dr's chain: each scan matched against the newest keyframe (the match, the guess along the
    directions it cannot see, or the bridge when it fails), its pose and covariance composed onto the
    keyframe's. With the IMU's guess (``lio``), LiDAR-inertial keyframes: a scan's pose is the
    keyframe's composed with the IMU's prediction, and a scan is matched (and becomes the keyframe) once
    the predicted motion from the keyframe reaches ``keyframe_dist`` or ``keyframe_angle_deg`` (a pair
    0.1 s apart measures the motion less well than the IMU does; over a metre the match carries the
    information)."""

    def __init__(self, cfg: IcpConfig, guesser: MotionGuess, scan0: Scan, pose: np.ndarray, cov: np.ndarray, *,
                 guess_cov: bool, keyframe_dist: float, keyframe_angle_deg: float, sweep_s: float = 0.0) -> None:
        self.cfg, self.guesser, self.guess_cov = cfg, guesser, guess_cov
        self.sweep_s = sweep_s  # [s] the LiDAR's sweep: each matched scan de-skewed with its guess's twist
        self.lio = guesser.imu is not None and guesser.odometry is None and guesser.mode in ("odometry", "imu")
        self.keyframe_dist, self.keyframe_angle = keyframe_dist, np.radians(keyframe_angle_deg)
        self.kf_t, self.kf_pose, self.kf_cov, self.kf_pts = scan0.t, pose, cov, scan_points(scan0, cfg)
        # with the gyro's bias a state: one filter over the keyframe's pose and the IMU's state (vx, vy, b_g),
        # kf_cross their covariance (the pose's right perturbation x the state)
        self.joint = self.lio and bool(getattr(guesser.imu, "gyro_bias", False))
        self.kf_cross = np.zeros((3, 3))
        self.icp_ms: list[float] = []
        self.bridged = {"odometry": 0, "imu": 0, "cv": 0}
        self.constrained = 0
        self.inconsistent = 0  # LiDAR-inertial: matches whose own estimate disagrees with the IMU's prediction
        self.matches = 0

    def step(self, scan: Scan, last: bool) -> tuple[np.ndarray, np.ndarray]:
        """The pose and covariance (body frame) of ``scan``; ``last``: the log's last scan (matched)."""
        ta, tb = self.kf_t, scan.t
        guess = self.guesser.guess(ta, tb)
        pts = None
        if self.lio and not last and guess is not None and not (
                np.hypot(guess[0], guess[1]) >= self.keyframe_dist or abs(guess[2]) >= self.keyframe_angle):
            inc, q = guess, self.guesser.cov
            a = se2_adjoint_inv(inc)
            cov = a @ self.kf_cov @ a.T + q
            if self.joint:  # the increment shares the IMU's state with the keyframe's pose
                assert self.guesser.imu is not None
                jac, _ = imu_tangent(self.guesser.imu, ta, tb, inc)
                x = a @ self.kf_cross @ jac.T
                cov = cov + x + x.T
            return se2_compose(self.kf_pose, inc), cov
        pts = self._points(scan, guess, tb - ta)
        if self.joint and guess is not None and self.guesser.cov is not None:
            pose, cov = self._match_joint(pts, ta, tb, guess)
        else:
            inc, q = self._match(pts, ta, tb, guess)
            a = se2_adjoint_inv(inc)
            cov = a @ self.kf_cov @ a.T + q
            pose = se2_compose(self.kf_pose, inc)
        self.kf_t, self.kf_pose, self.kf_cov, self.kf_pts = tb, pose, cov, pts
        return pose, cov

    def _match_joint(self, pts: np.ndarray, ta: float, tb: float, guess: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """LiDAR-inertial keyframe with the gyro's bias a state (stochastic cloning, Roumeliotis & Burdick
        2002): the state ``(keyframe pose, IMU state, increment)``, the increment predicted by the IMU
        (``J x + w``), the match measures the increment; the update corrects all three (the keyframe's
        heading too: a better bias says how far the heading has drifted), then the new keyframe's pose
        is the corrected pose composed with the corrected increment and the IMU's state is carried to it."""
        guesser, imu = self.guesser, self.guesser.imu
        assert imu is not None and guesser.cov is not None
        res, own = self._matched(pts, ta, tb, guess)
        guesser.update(res, ta, tb, imu=False)
        if own is None:
            _, _, how = guesser.bridge(ta, tb)  # the IMU's prediction: the prior stands
            self.bridged[how] += 1
        elif not res.ok:
            self.constrained += 1
        pose, cov, self.kf_cross = lio_step(imu, ta, tb, self.kf_pose, self.kf_cov, self.kf_cross, guess, own,
                                            consider_xy=True)  # the track does not jump back
        return pose, cov

    def _points(self, scan: Scan, guess: np.ndarray | None, dt: float) -> np.ndarray:
        """The scan's points; with a sweep, de-skewed to its stamp with the guess's constant twist since the
        keyframe (the keyframe's own points were de-skewed when it was matched)."""
        if not self.sweep_s or guess is None or not dt > 0.0 or not np.all(np.isfinite(guess)):
            return scan_points(scan, self.cfg)
        from ..scan.deskew import twist_of

        return scan_points(scan, self.cfg, sweep_s=self.sweep_s, twist=twist_of(guess, dt))

    def _matched(self, pts: np.ndarray, ta: float, tb: float, guess: np.ndarray | None
                 ) -> tuple[MatchResult, tuple[np.ndarray, np.ndarray, np.ndarray | None] | None]:
        """The match of the scan at ``tb`` to the keyframe at ``ta`` and, LiDAR-inertial, what a fusion by
        information takes from it (:meth:`~graphnav.scan.weighted_icp.MatchResult.own`; None: nothing)."""
        guesser = self.guesser
        t0 = time.perf_counter()
        res = icp_cache.match_points(pts, self.kf_pts, self.cfg, init=guess,  # shared in compare
                                     init_cov=guesser.cov if self.guess_cov else None)
        self.icp_ms.append((time.perf_counter() - t0) * 1e3)
        self.matches += 1
        own = None
        if self.lio and guess is not None and guesser.cov is not None and (res.ok or res.quality.get("inflated")):
            # LiDAR-inertial: fused by information, the match's own estimate and covariance, deaf only where
            # its geometry is (not where the IMU knows better: then its yaw, and the gyro's bias, would never
            # be heard); it must agree with the IMU's prediction where it is heard
            own = res.own()
            if not consistent(guess, guesser.cov, *own):
                own = None
                self.inconsistent += 1
                res = replace(res, ok=False, quality={**res.quality, "inflated": False})
        return res, own

    def _match(self, pts: np.ndarray, ta: float, tb: float, guess: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The increment from the keyframe at ``ta`` to the scan at ``tb`` and its covariance."""
        guesser = self.guesser
        res, own = self._matched(pts, ta, tb, guess)
        guesser.update(res, ta, tb)
        if res.ok:
            inc, q = res.pose, res.cov
        elif res.quality.get("inflated") and guesser.cov is not None:
            # degenerate only: the match across its weak directions, the odometry guess along them
            # (keep_constrained), with the covariance of each where it is taken from
            inc, q = res.pose, res.cov
            self.constrained += 1
        else:
            inc, q, how = guesser.bridge(ta, tb)
            self.bridged[how] += 1
        if own is not None:
            assert guess is not None and guesser.cov is not None
            inc, q = fuse_se2(guess, guesser.cov, *own)
        return inc, q

    def info(self) -> dict[str, Any]:
        b = self.bridged
        out = {"failed_matches": sum(b.values()), "bridged_odometry": b["odometry"], "bridged_imu": b["imu"],
               "bridged_cv": b["cv"], "constrained": self.constrained, "matches": self.matches,
               "inconsistent_with_imu": self.inconsistent,
               "guess": _guess_source(self.guesser)}
        imu = self.guesser.imu
        if self.joint and imu is not None:  # the gyro's bias at the end and its 1-sigma [deg/s]
            out["gyro_bias_dps"] = float(np.degrees(imu.bg))
            out["gyro_bias_sigma_dps"] = float(np.degrees(np.sqrt(imu.P3[2, 2])))
        return out


def _first_scans(log: NavLog, sigma_xy0: float, sigma_yaw0: float) -> tuple[np.ndarray, str, np.ndarray, list[Scan]]:
    """The start pose (:func:`graphnav.estimators.start.log_start`), where it came from, its covariance
    (the anchor's own sigmas win unless it is only a frame) and the scans from the one at the anchor's
    time (earlier scans have no pose)."""
    start = log_start(log)
    if not start.is_frame:
        sigma_xy0, sigma_yaw0 = float(start.sigmas[0]), float(start.sigmas[2])
    scans = log.of("scan")
    if np.isfinite(start.t):
        first = int(np.searchsorted([s.t for s in scans], start.t - 1e-6))
        scans = scans[min(first, len(scans) - 2):]
    return start.pose, start.name, np.diag([sigma_xy0**2, sigma_xy0**2, sigma_yaw0**2]), scans


def run_icp_dr(log: NavLog, *, on_estimate: OnEstimate | None = None, variant: str = "HDL",
               init: str = "odometry", sigma_xy0: float = 0.0, sigma_yaw0: float = 0.0, guess_cov: bool = True,
               keyframe_dist: float = 1.0, keyframe_angle_deg: float = 10.0, deskew: bool = True,
               gyro_bias: bool = True, **options: Any) -> RunResult:
    """Options: ``variant`` (K, H, HM, HD, HDL), ``init`` ("odometry": the odometry increment when the log
    has odometry, else the IMU's prediction when it has an IMU, else constant velocity; "imu", "cv" or
    "zero"; :class:`~graphnav.scan.motion_guess.MotionGuess`),
    any :class:`IcpConfig` field, ``guess_cov`` (False: the odometry guess goes without its covariance,
    so a match is not tested against it), the start pose's 1-sigma (``sigma_xy0``, ``sigma_yaw0``;
    the anchor's own sigmas win: a pose prior's, the first GNSS fix's, ...), and with the IMU's guess the
    keyframe rule (``keyframe_dist`` [m], ``keyframe_angle_deg``: the scan-to-map baseline's); ``deskew``: each
    matched scan de-skewed with its guess's twist when the log states the LiDAR's sweep
    (``meta["lidar"]["sweep_s"]``); ``gyro_bias``: with the IMU's guess, the gyro's bias a state of its filter,
    estimated from the matches (false: white noise of the stated residual bias per interval)."""
    unknown = set(options) - _CONFIG_FIELDS
    if unknown:
        raise ValueError(f"unknown icp-dr options: {', '.join(sorted(unknown))}")
    cfg = IcpConfig(variant=variant, **options)
    pose, anchor, cov, scans = _first_scans(log, sigma_xy0, sigma_yaw0)
    guesser = MotionGuess(init, odometry_samples(log),
                          _imu_guess(log, pose, gyro_bias) if init in ("odometry", "imu") else None)
    chain = _KeyframeChain(cfg, guesser, scans[0], pose, cov, guess_cov=guess_cov, keyframe_dist=keyframe_dist,
                           keyframe_angle_deg=keyframe_angle_deg, sweep_s=sweep_of(log) if deskew else 0.0)
    t, poses, covs = [scans[0].t], [pose], [_to_world(pose, cov)]
    if on_estimate is not None:
        on_estimate(scans[0].t, pose, covs[0])
    for k in range(1, len(scans)):
        pose, cov = chain.step(scans[k], k == len(scans) - 1)
        t.append(scans[k].t)
        poses.append(pose)
        covs.append(_to_world(pose, cov))
        if on_estimate is not None:
            on_estimate(scans[k].t, pose, covs[-1])
    traj = Trajectory(np.array(t), np.array(poses), np.array(covs), name="icp-dr")
    info = {"anchor": anchor, "variant": variant, "init": init, **chain.info()}
    return RunResult(traj, traj, np.zeros(0), np.array(chain.icp_ms), info=info)


def _imu_guess(log: NavLog, pose: np.ndarray, gyro_bias: bool) -> ImuGuess | None:
    """The IMU's prediction for a log without odometry (the log's IMU model and start velocity)."""
    return None if len(log.of("odometry")) >= 2 else log_imu_guess(log, float(pose[2]), gyro_bias=gyro_bias)


def _guess_source(g: MotionGuess) -> str:
    if g.mode in ("odometry", "imu"):
        return "odometry" if g.odometry is not None else "imu" if g.imu is not None else "cv"
    return g.mode


def _unmet(log: NavLog) -> str | None:
    return None if len(log.of("scan")) >= 2 else "needs at least two LiDAR scans"


def _inputs(log: NavLog, options: dict) -> set[str]:
    kinds = {"scan", "pose_prior"}
    if options.get("init", "odometry") in ("odometry", "imu"):  # the initial guess (and the bridge of a failed match)
        kinds.add("odometry" if len(log.of("odometry")) >= 2 else "imu" if len(log.of("imu")) >= 2 else "scan")
    return kinds


@dataclass
class IcpDrConfig(IcpConfig):
    """The ``icp-dr`` estimator's options: its own and every :class:`IcpConfig` field."""

    group: ClassVar[str] = "icp-dr"
    init: str = option("odometry", "the initial guess: odometry (the odometry increment when the log has odometry, "
                       "else the IMU's prediction when it has an IMU, else constant velocity), imu, cv or zero")
    guess_cov: bool = option(True, "false: the odometry guess goes without its covariance, so a match is not tested "
                             "against it")
    sigma_xy0: float = option(0.0, "the start pose's 1-sigma in x and y (the anchor's own sigmas win: a pose "
                              "prior's, the first GNSS fix's, ...)", unit="m")
    sigma_yaw0: float = option(0.0, "the start pose's yaw 1-sigma (the anchor's own sigmas win)", unit="rad")
    keyframe_dist: float = option(1.0, "with the IMU's guess: a scan becomes a keyframe after the vessel moved "
                                  "this far (the scan-to-map baseline's rule)", unit="m")
    keyframe_angle_deg: float = option(10.0, "with the IMU's guess: ... or turned this much", unit="deg")
    deskew: bool = option(True, "de-skew each matched scan with its guess's twist when the log states the LiDAR's "
                          "sweep (meta lidar sweep_s > 0)")
    gyro_bias: bool = option(True, "with the IMU's guess: the gyro's bias a state of its filter, estimated from the "
                             "matches (false: white noise of the stated residual bias per interval)")


class IcpDr(BatchEstimator):
    """Weighted-ICP scan-matching dead reckoning (:func:`run_icp_dr`)."""

    description = "weighted-ICP scan-matching dead reckoning"
    kind = "odometry"
    cost = 1  # a match per keyframe
    Config = IcpDrConfig
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)

    batch = staticmethod(run_icp_dr)


ESTIMATORS = {"icp-dr": IcpDr}
