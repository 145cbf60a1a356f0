"""Dead reckoning on the compass and the speed log, from the last GNSS fix: the navigator's baseline.

The position advances at the speed through water (``water_speed``) along the compass heading
(``heading``), with no water current (it cannot be known without GNSS); every GNSS fix (when
``gnss_reset``) puts the position back on the fix. Between fixes the estimate is what a sailor's
paper chart would give, and under ``--holdout-gnss`` it is the yardstick the graph must beat.
The position covariance is the last fix's plus the growth of an unknown current (``current_sigma``
per axis) and of the speed and heading errors since then.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..config import option
from ..log import NavLog
from ..result import OnEstimate, RunResult
from ..trajectory import Trajectory
from .base import BatchEstimator

#: a heading or speed older than this [s] is not used (the position then stays, its covariance grows)
STALE_S = 10.0


def run_water_dead_reckoning(log: NavLog, *, on_estimate: OnEstimate | None = None, gnss_reset: bool = True,
                             current_sigma: float = 0.3, heading_sigma: float = math.radians(3.0),
                             speed_sigma: float = 0.1) -> RunResult:
    """``gnss_reset``: put the position on every GNSS fix (False: from the first fix only).
    ``current_sigma``: the unknown water current's 1-sigma per axis [m/s], the covariance's growth.
    ``heading_sigma``: the compass's 1-sigma [rad] when a record gives none. ``speed_sigma``: the
    speed log's 1-sigma [m/s] when a record gives none."""
    fix0 = next((r for r in log.records if r.kind == "gnss"), None)
    if fix0 is None:
        raise ValueError("water dead reckoning needs a GNSS fix to start from")
    pos = np.array([fix0.x, fix0.y])
    var = fix0.sigma ** 2
    yaw = spd = None
    t_yaw = t_spd = -math.inf
    s_yaw, s_spd = heading_sigma, speed_sigma
    t_prev = fix0.t
    ts, poses, covs, step_ms = [], [], [], []
    resets = 0
    for r in log.records:
        if r.t < fix0.t or r.kind not in ("heading", "water_speed", "gnss"):
            continue
        c0 = time.perf_counter()
        dt = r.t - t_prev
        if dt > 0:
            if yaw is not None and spd is not None and r.t - t_yaw <= STALE_S and r.t - t_spd <= STALE_S:
                pos = pos + spd * dt * np.array([math.cos(yaw), math.sin(yaw)])
                var += (spd * dt * s_yaw) ** 2 + (dt * s_spd) ** 2
            var += (current_sigma * dt) ** 2
            t_prev = r.t
        if r.kind == "heading":
            yaw, t_yaw = float(r.yaw), r.t
            s_yaw = float(r.sigma) if math.isfinite(r.sigma) and r.sigma > 0 else heading_sigma
        elif r.kind == "water_speed":
            spd, t_spd = float(r.v), r.t
            s_spd = float(r.sigma_v) if math.isfinite(r.sigma_v) and r.sigma_v > 0 else speed_sigma
        elif gnss_reset or r is fix0:
            pos, var = np.array([r.x, r.y]), float(r.sigma) ** 2
            resets += r is not fix0
        pose = np.array([pos[0], pos[1], yaw if yaw is not None else 0.0])
        cov = np.diag([var, var, s_yaw ** 2])
        step_ms.append((time.perf_counter() - c0) * 1e3)
        if ts and r.t == ts[-1]:
            poses[-1], covs[-1] = pose, cov
            continue
        ts.append(r.t)
        poses.append(pose)
        covs.append(cov)
        if on_estimate is not None:
            on_estimate(r.t, pose, cov)
    traj = Trajectory(np.array(ts), np.array(poses), np.array(covs), name="water-dr")
    return RunResult(traj, traj, np.array(step_ms), info={"anchor": "gnss", "gnss_resets": resets})


def _unmet(log: NavLog) -> str | None:
    have = log.counts()
    missing = [k for k in ("heading", "water_speed", "gnss") if not have.get(k)]
    return f"needs {', '.join(missing)} records" if missing else None


def _inputs(log: NavLog, options: dict) -> list[str]:
    return ["heading", "water_speed", "gnss"]


@dataclass
class WaterDrConfig:
    """The ``water-dr`` estimator's options (:func:`run_water_dead_reckoning`)."""

    gnss_reset: bool = option(True, "put the position on every GNSS fix (false: from the first fix only)")
    current_sigma: float = option(0.3, "the unknown water current's 1-sigma per axis: the covariance's growth",
                                  unit="m/s")
    heading_sigma: float = option(math.radians(3.0), "the compass's 1-sigma when a record gives none", unit="rad")
    speed_sigma: float = option(0.1, "the speed log's 1-sigma when a record gives none", unit="m/s")


class WaterDr(BatchEstimator):
    """Dead reckoning on the compass and the speed log (:func:`run_water_dead_reckoning`)."""

    description = ("dead reckoning on compass heading and speed through water (no current), restarted at each "
                   "GNSS fix: the navigator's paper-chart baseline")
    kind = "odometry"
    Config = WaterDrConfig
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)
    batch = staticmethod(run_water_dead_reckoning)


ESTIMATORS = {"water-dr": WaterDr}
