"""The online estimates of a navigator as they come: the newest pose and its world covariance per
keyframe, the step times, and the speed over ground, course and yaw rate reported with each."""

from __future__ import annotations

import bisect
import math

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle
from ..trajectory import Trajectory

KEEP_TIMES = 10_000  # without history (live mode): the step times kept


class OnlineTrack:
    """Online estimates and timings. ``history=False`` (live mode, unbounded runs) keeps no
    trajectory and only the last :data:`KEEP_TIMES` step times: memory stays bounded."""

    def __init__(self, history: bool = True) -> None:
        self.history = history
        self.t: list[float] = []
        self.p: list[NDArray[np.float64]] = []
        self.c: list[NDArray[np.float64] | None] = []
        self.coasted: list[bool] = []  # per estimate: a prediction through a gap without records
        self.step_ms: list[float] = []
        self.step_cpu: list[float] = []
        self.icp_ms: list[float] = []
        self.prev: tuple[float | None, NDArray[np.float64] | None] = (None, None)

    def timing(self, ms: float, cpu_ms: float) -> None:
        """One online step's wall and CPU time [ms]."""
        self.step_ms.append(ms)
        self.step_cpu.append(cpu_ms)

    def add(self, t: float, vec: NDArray[np.float64], cov: NDArray[np.float64] | None, coasted: bool = False
            ) -> tuple[float | None, NDArray[np.float64] | None]:
        """The online estimate at ``t`` (``coasted``: a prediction through a gap); returns the previous
        one's time and pose. One older than the newest (live mode: a keyframe solved after the clock
        tick coasted past it) is put in its place in time."""
        prev = self.prev
        self.prev = (t, vec)
        if self.history:
            i = bisect.bisect_right(self.t, t)
            self.t.insert(i, t)
            self.p.insert(i, vec)
            self.c.insert(i, cov)
            self.coasted.insert(i, coasted)
        else:
            del self.step_ms[:-KEEP_TIMES], self.step_cpu[:-KEEP_TIMES], self.icp_ms[:-KEEP_TIMES]
        return prev

    def trajectory(self, name: str) -> Trajectory:
        cov = np.array(self.c) if self.c else None
        return Trajectory(np.array(self.t), np.array(self.p).reshape(-1, 3), cov, name=name,
                          meta={"coasted": np.array(self.coasted, dtype=bool)})


def differenced(t: float, p: NDArray[np.float64], prev_t: float | None, prev_p: NDArray[np.float64] | None
                ) -> tuple[float | None, float | None, float | None]:
    """Speed over ground, course and yaw rate differenced from the previous estimate (``None`` at the first)."""
    sog = cog = w = None
    if prev_t is not None and prev_p is not None and t > prev_t:
        dt = t - prev_t
        dx, dy = p[0] - prev_p[0], p[1] - prev_p[1]
        sog, cog = math.hypot(dx, dy) / dt, math.atan2(dy, dx)
        w = float(wrap_angle(p[2] - prev_p[2])) / dt
    return sog, cog, w


def kinematics(t: float, p: NDArray[np.float64], prev_t: float | None, prev_p: NDArray[np.float64] | None,
               velocity: NDArray[np.float64] | None, odometry: tuple[float, float] | None
               ) -> tuple[float | None, float | None, float | None]:
    """Speed over ground, course, yaw rate: from the ``velocity`` state when there is one (the Pose3
    graph; the yaw rate differenced); else from the latest ``odometry`` sample's speed and yaw rate when
    recent, else differenced from the previous estimate."""
    sog, cog, w = differenced(t, p, prev_t, prev_p)
    if velocity is not None:  # the velocity over ground is a state
        return math.hypot(velocity[0], velocity[1]), math.atan2(velocity[1], velocity[0]), w
    if odometry is not None:
        sog, w = abs(odometry[0]), odometry[1]
    return sog, cog, w
