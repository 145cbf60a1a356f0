"""Dead reckoning from the ship's log and rate-of-turn sensor (odometry records).

The simplest baseline: integrate ``v`` and ``w`` with the unicycle model (the beacon paper's
motion model, eq. 3), starting at the log's pose prior, else the first truth pose, else the origin.
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry import wrap_angle
from ..log import NavLog, Odometry
from ..trajectory import Trajectory
from . import EstimatorSpec, OnEstimate, RunResult


def unicycle_step(pose: np.ndarray, v: float, w: float, dt: float) -> np.ndarray:
    """Exact integration of constant (v, w) over dt (straight line when w ~ 0)."""
    x, y, th = pose
    if abs(w) < 1e-9:
        return np.array([x + v * dt * np.cos(th), y + v * dt * np.sin(th), th])
    th2 = th + w * dt
    r = v / w
    return np.array([x + r * (np.sin(th2) - np.sin(th)), y - r * (np.cos(th2) - np.cos(th)),
                     wrap_angle(th2)])


def start_pose(log: NavLog) -> tuple[np.ndarray, str]:
    """Initial pose and where it came from (``pose_prior``, ``truth`` or ``origin``)."""
    prior = log.pose_prior()
    if prior is not None:
        return np.array([prior.x, prior.y, prior.yaw]), "pose_prior"
    for r in log.records:
        if r.kind == "truth":
            return np.array([r.x, r.y, r.yaw]), "truth"
    return np.zeros(3), "origin"


def run_dead_reckoning(log: NavLog, *, on_estimate: OnEstimate | None = None) -> RunResult:
    odo = [r for r in log.records if isinstance(r, Odometry)]
    pose, anchor = start_pose(log)
    t = [odo[0].t]
    poses = [pose]
    step_ms = []
    if on_estimate is not None:
        on_estimate(t[0], pose, None)
    for prev, cur in zip(odo[:-1], odo[1:], strict=True):
        t0 = time.perf_counter()
        pose = unicycle_step(pose, prev.v, prev.w, cur.t - prev.t)
        step_ms.append((time.perf_counter() - t0) * 1e3)
        t.append(cur.t)
        poses.append(pose)
        if on_estimate is not None:
            on_estimate(cur.t, pose, None)
    traj = Trajectory(np.array(t), np.array(poses), name="dead-reckoning")
    return RunResult(traj, traj, np.array(step_ms), info={"anchor": anchor})


def _unmet(log: NavLog) -> str | None:
    return None if len(log.of("odometry")) >= 2 else "needs at least two odometry records"


def _inputs(log: NavLog, options: dict) -> set[str]:
    return {"odometry", "pose_prior"}  # (the first truth pose without a prior: info["anchor"])


ESTIMATORS = {
    "dead-reckoning": EstimatorSpec(run_dead_reckoning, _unmet, "odometry (SOG + ROT) integration", "odometry",
                                    _inputs),
}
