"""Dead reckoning from the ship's log and rate-of-turn sensor (odometry records), else from the IMU.

The simplest baseline: integrate ``v`` and ``w`` with the unicycle model (the beacon paper's
motion model, eq. 3), starting where the graph's anchor does (:mod:`graphnav.estimators.start`: the log's
pose prior, else the first GNSS fix and compass reading, ...).
A log without odometry but with an IMU (a USV's) is dead-reckoned from the IMU alone: planar
strapdown integration of the body-frame specific force and yaw rate (each record the mean over the
interval since the previous one), from the same start pose and ``meta["initial_velocity"]`` (zero
when the log does not know it).
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry import wrap_angle
from ..log import Imu, NavLog, Odometry
from ..result import OnEstimate, RunResult
from ..scan.imu_guess import strapdown_step
from ..trajectory import Trajectory
from .base import BatchEstimator
from .start import start_pose


def unicycle_step(pose: np.ndarray, v: float, w: float, dt: float) -> np.ndarray:
    """Exact integration of constant (v, w) over dt (straight line when w ~ 0)."""
    x, y, th = pose
    if abs(w) < 1e-9:
        return np.array([x + v * dt * np.cos(th), y + v * dt * np.sin(th), th])
    th2 = th + w * dt
    r = v / w
    return np.array([x + r * (np.sin(th2) - np.sin(th)), y - r * (np.cos(th2) - np.cos(th)),
                     wrap_angle(th2)])


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


def imu_dead_reckoning(log: NavLog, *, on_estimate: OnEstimate | None = None) -> RunResult:
    """Planar strapdown dead reckoning on the log's ``imu`` records (the module docstring)."""
    imu = [r for r in log.records if isinstance(r, Imu)]
    pose, anchor = start_pose(log)
    prior = log.pose_prior()
    t_prev = prior.t if prior is not None and prior.t < imu[0].t else imu[0].t
    v0 = log.meta.get("initial_velocity") if isinstance(log.meta, dict) else None
    vel = np.array(v0, dtype=float) if v0 is not None else np.zeros(2)
    pos, th = pose[:2].copy(), float(pose[2])
    t, poses, step_ms = [t_prev], [pose], []
    if on_estimate is not None:
        on_estimate(t_prev, pose, None)
    for r in imu:
        dt = r.t - t_prev
        if dt <= 0:
            continue
        t0 = time.perf_counter()
        pos, vel, th = strapdown_step(pos, vel, th, r.ax, r.ay, r.wz, dt)
        step_ms.append((time.perf_counter() - t0) * 1e3)
        t_prev = r.t
        pose = np.array([pos[0], pos[1], wrap_angle(th)])
        t.append(r.t)
        poses.append(pose)
        if on_estimate is not None:
            on_estimate(r.t, pose, None)
    traj = Trajectory(np.array(t), np.array(poses), name="dead-reckoning")
    return RunResult(traj, traj, np.array(step_ms),
                     info={"anchor": anchor, "motion": "imu", "initial_velocity": "meta" if v0 is not None else "zero"})


def run_any_dead_reckoning(log: NavLog, *, on_estimate: OnEstimate | None = None) -> RunResult:
    """Odometry dead reckoning when the log has odometry, else the IMU's."""
    if len(log.of("odometry")) < 2 and len(log.of("imu")) >= 2:
        return imu_dead_reckoning(log, on_estimate=on_estimate)
    return run_dead_reckoning(log, on_estimate=on_estimate)


def _unmet(log: NavLog) -> str | None:
    ok = len(log.of("odometry")) >= 2 or len(log.of("imu")) >= 2
    return None if ok else "needs at least two odometry (or IMU) records"


def _inputs(log: NavLog, options: dict) -> set[str]:
    motion = "imu" if len(log.of("odometry")) < 2 and len(log.of("imu")) >= 2 else "odometry"
    return {motion, "pose_prior"}  # (the first truth pose without a prior: info["anchor"])


class DeadReckoning(BatchEstimator):
    """Odometry dead reckoning when the log has odometry, else the IMU's (:func:`run_any_dead_reckoning`);
    no options."""

    description = "odometry (SOG + ROT) integration, else the IMU's (planar strapdown)"
    kind = "odometry"
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)

    batch = staticmethod(run_any_dead_reckoning)


ESTIMATORS = {"dead-reckoning": DeadReckoning}
