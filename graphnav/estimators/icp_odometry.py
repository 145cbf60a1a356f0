"""Weighted-ICP dead reckoning: chain the scan matches from the start pose.

Scan ``k+1`` is matched to scan ``k`` (:func:`graphnav.scan.weighted_icp.match_points`; initial guess the
odometry increment with its covariance when the log has odometry, else constant velocity) and the
increment is composed onto the previous pose; the covariance is propagated to first order
(``P' = Ad P Ad^T + Q`` in the body frame, GTSAM's convention) and reported in the world frame
(the :class:`~graphnav.trajectory.Trajectory` convention).
The start pose is the log's pose prior, else the first truth pose, else the origin
(:func:`graphnav.estimators.dead_reckoning.start_pose`). Initial guesses come from
:class:`~graphnav.scan.motion_guess.MotionGuess` (never from a flagged match). A flagged match (``ok``
False: degenerate geometry, too few points or inliers, not converged, or beyond the odometry guess's
99.9 % bound) is bridged by the odometry increment with its
covariance when the log has odometry, else by the constant-velocity guess with a wide covariance,
and counted (``info["failed_matches"]``, ``info["bridged_odometry"]``, ``info["bridged_cv"]``). A match
flagged for degeneracy only, from an odometry guess, is chained as returned (the match across its weak
directions, the guess along them) with its covariance (the match's across, the odometry's along;
``info["constrained"]``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from ..config import option
from ..geometry import cov_to_world, se2_adjoint_inv, se2_compose
from ..log import NavLog, odometry_samples
from ..result import OnEstimate, RunResult
from ..scan import icp_cache
from ..scan.motion_guess import MotionGuess
from ..scan.weighted_icp import IcpConfig, scan_points
from ..trajectory import Trajectory
from .base import BatchEstimator
from .dead_reckoning import start_pose

_CONFIG_FIELDS = {f.name for f in fields(IcpConfig)}



def _to_world(pose: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Body-frame (right-perturbation) covariance -> the trajectory's world-frame (x, y, yaw)."""
    return cov_to_world(float(pose[2]), cov)


def run_icp_dr(log: NavLog, *, on_estimate: OnEstimate | None = None, variant: str = "HDL",
               init: str = "odometry", sigma_xy0: float = 0.0, sigma_yaw0: float = 0.0, guess_cov: bool = True,
               **options: Any) -> RunResult:
    """Options: ``variant`` (K, H, HM, HD, HDL), ``init`` ("odometry": the odometry increment when the log
    has odometry, else constant velocity; "cv" or "zero"; :class:`~graphnav.scan.motion_guess.MotionGuess`),
    any :class:`IcpConfig` field, ``guess_cov`` (False: the odometry guess goes without its covariance,
    so a match is not tested against it), and the start pose's 1-sigma (``sigma_xy0``, ``sigma_yaw0``;
    a pose prior's own sigmas win)."""
    unknown = set(options) - _CONFIG_FIELDS
    if unknown:
        raise ValueError(f"unknown icp-dr options: {', '.join(sorted(unknown))}")
    cfg = IcpConfig(variant=variant, **options)
    pose, anchor = start_pose(log)
    prior = log.pose_prior()
    t_anchor = None
    if prior is not None:
        sigma_xy0, sigma_yaw0 = prior.sigma_xy, prior.sigma_yaw
        t_anchor = prior.t
    elif anchor == "truth":
        t_anchor = log.of("truth")[0].t
    scans = log.of("scan")
    if t_anchor is not None:  # chain from the scan at the anchor's time (earlier scans have no pose)
        first = int(np.searchsorted([s.t for s in scans], t_anchor - 1e-6))
        scans = scans[min(first, len(scans) - 2):]
    cov = np.diag([sigma_xy0**2, sigma_xy0**2, sigma_yaw0**2])
    t = [scans[0].t]
    poses = [pose]
    covs = [_to_world(pose, cov)]
    if on_estimate is not None:
        on_estimate(scans[0].t, pose, _to_world(pose, cov))
    pts_prev = scan_points(scans[0], cfg)
    icp_ms = []
    bridged = {"odometry": 0, "cv": 0}
    constrained = 0
    guesser = MotionGuess(init, odometry_samples(log))
    for k in range(1, len(scans)):
        ta, tb = scans[k - 1].t, scans[k].t
        pts = scan_points(scans[k], cfg)
        guess = guesser.guess(ta, tb)
        t0 = time.perf_counter()
        res = icp_cache.match_points(pts, pts_prev, cfg, init=guess,  # shared in compare
                                     init_cov=guesser.cov if guess_cov else None)
        icp_ms.append((time.perf_counter() - t0) * 1e3)
        guesser.update(res, ta, tb)
        if res.ok:
            inc, q = res.pose, res.cov
        elif res.quality.get("inflated") and guesser.cov is not None:
            # degenerate only: the match across its weak directions, the odometry guess along them
            # (keep_constrained), with the covariance of each where it is taken from
            inc, q = res.pose, res.cov
            constrained += 1
        else:
            inc, q, how = guesser.bridge(ta, tb)
            bridged[how] += 1
        a = se2_adjoint_inv(inc)
        cov = a @ cov @ a.T + q
        pose = se2_compose(pose, inc)
        t.append(scans[k].t)
        poses.append(pose)
        covs.append(_to_world(pose, cov))
        if on_estimate is not None:
            on_estimate(scans[k].t, pose, covs[-1])
        pts_prev = pts
    traj = Trajectory(np.array(t), np.array(poses), np.array(covs), name="icp-dr")
    info = {"anchor": anchor, "variant": variant, "init": init, "failed_matches": sum(bridged.values()),
            "bridged_odometry": bridged["odometry"], "bridged_cv": bridged["cv"], "constrained": constrained,
            "matches": len(scans) - 1}
    return RunResult(traj, traj, np.zeros(0), np.array(icp_ms), info=info)


def _unmet(log: NavLog) -> str | None:
    return None if len(log.of("scan")) >= 2 else "needs at least two LiDAR scans"


def _inputs(log: NavLog, options: dict) -> set[str]:
    kinds = {"scan", "pose_prior"}
    if options.get("init", "odometry") == "odometry":
        kinds.add("odometry")  # the initial guess (and the bridge of a failed match)
    return kinds


@dataclass
class IcpDrConfig(IcpConfig):
    """The ``icp-dr`` estimator's options: its own and every :class:`IcpConfig` field."""

    group: ClassVar[str] = "icp-dr"
    init: str = option("odometry", "the initial guess: odometry (the odometry increment when the log has odometry, "
                       "else constant velocity), cv or zero (MotionGuess)")
    guess_cov: bool = option(True, "false: the odometry guess goes without its covariance, so a match is not tested "
                             "against it")
    sigma_xy0: float = option(0.0, "the start pose's 1-sigma in x and y (a pose prior's own sigmas win)", unit="m")
    sigma_yaw0: float = option(0.0, "the start pose's yaw 1-sigma (a pose prior's own sigmas win)", unit="rad")


class IcpDr(BatchEstimator):
    """Weighted-ICP scan-matching dead reckoning (:func:`run_icp_dr`)."""

    description = "weighted-ICP scan-matching dead reckoning"
    kind = "odometry"
    Config = IcpDrConfig
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)

    batch = staticmethod(run_icp_dr)


ESTIMATORS = {"icp-dr": IcpDr}
