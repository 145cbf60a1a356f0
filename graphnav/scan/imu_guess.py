"""The IMU's prediction of the motion between two scans, for LiDAR odometry without GNSS.

A planar strapdown propagation in the frame of the first scan: the yaw integrates the gyro's
``wz``, the velocity the body-frame specific force ``(ax, ay)`` rotated by that yaw, the position
the velocity (each ``imu`` record the mean over the interval since the previous one, held over it;
the acceleration at the mid-sample yaw). The velocity at the start is the state of a small Kalman
filter (2-D, body frame): predicted through each interval with the accelerometer's noise, and
corrected by each scan match, which measures the start velocity that explains the matched
displacement: ``v0 + (p_match - p_pred) / dt`` with the match's covariance over ``dt^2``.

The guess covariance (x, y, yaw of the increment) is the velocity's covariance times ``dt^2``,
the accelerometer's random walk ``q_a dt^3 / 3`` and the gyro's ``q_g dt`` plus its residual bias
``(b_g dt)^2``: the IMU's error model as the log states it (``meta["imu"]``), else a MEMS datasheet's
(:class:`graphnav.graph.imu_chain.ImuConfig`).
A 6-axis record is used as planar (``ax``, ``ay``, ``wz``): a surface vessel's roll and pitch are small.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import se2_between, se2_compose
from ..log import NavLog

# a MEMS IMU's datasheet order where the log states no model (as graphnav.graph.imu_chain.ImuConfig)
ACC_STD, GYRO_STD, HZ = 0.02, math.radians(0.05), 100.0
ACC_BIAS, GYRO_BIAS = 0.05, math.radians(0.1)
V0_SIGMA = 5.0  # [m/s] the start velocity's 1-sigma when the log states none


def strapdown_step(pos: NDArray[np.float64], vel: NDArray[np.float64], yaw: float, ax: float, ay: float,
                   wz: float, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """One planar strapdown step over ``dt`` of a sample held over it: the body-frame specific force
    ``(ax, ay)`` rotated by the mid-step yaw, position and velocity integrated exactly for that
    constant acceleration, the yaw by ``wz`` (the IMU dead reckoning's step and the guess's)."""
    mid = yaw + 0.5 * dt * wz
    c, s = np.cos(mid), np.sin(mid)
    acc = np.array([c * ax - s * ay, s * ax + c * ay])
    return pos + dt * vel + 0.5 * dt * dt * acc, vel + dt * acc, yaw + dt * wz


def fuse_se2(prior: NDArray[np.float64], p_cov: NDArray[np.float64], meas: NDArray[np.float64],
             m_cov: NDArray[np.float64], weak: NDArray[np.float64] | None = None
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two independent estimates of one SE(2) pose (or increment) combined by their information, the
    loosely coupled LiDAR-inertial update: ``prior (+) K xi``, ``xi`` the measurement in the prior's
    tangent space, ``K = P_p (P_p + P_m)^-1``, covariance ``(I - K) P_p``. ``weak``: the projector onto a
    degenerate measurement's weak directions (where it only repeats the prior): no information there."""
    r = np.asarray(m_cov, dtype=float)
    if weak is not None:
        w = np.asarray(weak, dtype=float)
        r = r + 1e8 * (w @ w.T)
    k = p_cov @ np.linalg.inv(p_cov + r)
    cov = (np.eye(3) - k) @ p_cov
    return se2_compose(prior, k @ se2_between(prior, meas)), 0.5 * (cov + cov.T)


def imu_samples(log: NavLog) -> NDArray[np.float64]:
    """The log's ``imu`` records as an (N, 4) array ``t, ax, ay, wz`` (time-ordered, unique)."""
    rows = np.array([[r.t, r.ax, r.ay, r.wz] for r in log.of("imu")], dtype=float).reshape(-1, 4)
    if len(rows):
        keep = np.concatenate([[True], np.diff(rows[:, 0]) > 0])
        rows = rows[keep & np.all(np.isfinite(rows), axis=1)]
    return rows


class ImuGuess:
    """Increment ``(dx, dy, dyaw)`` over ``[t0, t1]`` from the IMU (see the module docstring)."""

    def __init__(self, samples: NDArray[np.float64], model: dict[str, Any] | None = None,
                 v0: NDArray[np.float64] | None = None, yaw0: float = 0.0) -> None:
        self.s = samples
        m = model if isinstance(model, dict) else {}
        hz = float(m.get("hz") or HZ)
        acc, gyro = float(m.get("acc_std", ACC_STD)), float(m.get("gyro_std", GYRO_STD))
        self.q_acc, self.q_gyro = acc * acc / hz, gyro * gyro / hz  # continuous densities
        self.b_acc = float(m.get("acc_bias_sigma", ACC_BIAS))
        self.b_gyro = float(m.get("gyro_bias_sigma", GYRO_BIAS))
        if v0 is not None:  # a world-frame start velocity (meta["initial_velocity"]) in the body frame
            c, s = math.cos(yaw0), math.sin(yaw0)
            self.v = np.array([c * v0[0] + s * v0[1], -s * v0[0] + c * v0[1]])
            self.P = np.eye(2) * 0.2**2
        else:
            self.v = np.zeros(2)
            self.P = np.eye(2) * V0_SIGMA**2
        self._pred: tuple[float, float, NDArray[np.float64], NDArray[np.float64], float] | None = None
        self.last: tuple[float, float, NDArray[np.float64], NDArray[np.float64]] | None = None  # newest guess

    def __bool__(self) -> bool:
        return len(self.s) >= 2

    def _integrate(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """Position and velocity change (frame of ``t0``, start velocity zero) and yaw over ``[t0, t1]``."""
        t = self.s[:, 0]
        p, dv, th = np.zeros(2), np.zeros(2), 0.0
        i = int(np.searchsorted(t, t0, side="right"))
        lo = t0
        while lo < t1 - 1e-12:
            row = self.s[min(i, len(t) - 1)]
            hi = min(t[i], t1) if i < len(t) else t1
            dt = hi - lo
            if dt > 0:
                p, dv, th = strapdown_step(p, dv, th, row[1], row[2], row[3], dt)
            lo = hi
            i += 1
        return p, dv, th

    def guess(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The predicted increment and its covariance."""
        dt = max(t1 - t0, 0.0)
        p, dv, th = self._integrate(t0, t1)
        inc = np.array([p[0] + self.v[0] * dt, p[1] + self.v[1] * dt, th])
        cov = np.zeros((3, 3))
        cov[:2, :2] = self.P * dt * dt + np.eye(2) * (self.q_acc * dt**3 / 3 + (0.5 * self.b_acc * dt * dt) ** 2)
        cov[2, 2] = self.q_gyro * dt + (self.b_gyro * dt) ** 2
        self._pred = (t0, t1, inc, dv, th)
        self.last = (t0, t1, inc, cov)
        return inc, cov

    def update(self, t0: float, t1: float, pose: NDArray[np.float64] | None,
               cov: NDArray[np.float64] | None, weak: NDArray[np.float64] | None = None) -> None:
        """Close the interval: correct the start velocity by the match ``pose`` (``None``: no match,
        the prediction stands; ``weak``, the projector onto a degenerate match's weak directions:
        those are not measured), then carry it to ``t1`` (its frame) with the accelerometer's noise."""
        if self._pred is None or self._pred[:2] != (t0, t1):
            self.guess(t0, t1)
        assert self._pred is not None
        _, _, inc, dv, th = self._pred
        dt = t1 - t0
        if pose is not None and cov is not None and dt > 1e-6 and np.all(np.isfinite(pose)):
            z = self.v + (np.asarray(pose[:2], dtype=float) - inc[:2]) / dt  # the start velocity the match implies
            R = np.asarray(cov, dtype=float)[:2, :2] / (dt * dt) + np.eye(2) * self.q_acc * dt / 3
            if weak is not None:  # the weak directions carry the guess itself: not a measurement
                R = R + 1e8 * np.asarray(weak, dtype=float)[:2, :2]
            K = self.P @ np.linalg.inv(self.P + R)
            self.v = self.v + K @ (z - self.v)
            self.P = (np.eye(2) - K) @ self.P
        c, s = math.cos(th), math.sin(th)
        rot_t = np.array([[c, s], [-s, c]])  # frame of t0 -> frame of t1
        self.v = rot_t @ (self.v + dv)
        self.P = rot_t @ self.P @ rot_t.T + np.eye(2) * (self.q_acc * dt + (self.b_acc * dt) ** 2)
        self.P = 0.5 * (self.P + self.P.T)
        self._pred = None


def log_imu_guess(log: NavLog, yaw0: float) -> ImuGuess | None:
    """The IMU's prediction on ``log`` (None without two IMU records): its ``meta["imu"]`` model and
    ``meta["initial_velocity"]`` (world frame, over ground), taken into the body frame of the start
    pose's yaw ``yaw0`` -- the frame the odometry starts in."""
    meta = log.meta if isinstance(log.meta, dict) else {}
    v0 = meta.get("initial_velocity")
    guess = ImuGuess(imu_samples(log), meta.get("imu"), None if v0 is None else np.asarray(v0, dtype=float)[:2],
                     float(yaw0))
    return guess if guess else None
