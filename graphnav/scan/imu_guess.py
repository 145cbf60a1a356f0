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

With ``gyro_bias=True`` the gyro's residual bias is a state of the filter instead of white noise
(textbook loosely coupled LiDAR-inertial odometry): the state is ``(vx, vy, b_g)``, the prediction
integrates ``wz - b_g``, the guess's covariance is ``J P J^T + Q`` (``J`` the increment's Jacobian with
respect to the state: ``dt`` on the velocity, ``-dt`` and the position's share on the bias) and each
match, ``z = inc(x) + w`` with covariance the match's plus ``Q``, corrects all three. The bias starts
at zero (the log's records are calibrated) with the stated residual's 1-sigma and walks with the
stated ``gyro_bias_rw`` (else :class:`~graphnav.graph.imu_chain.ImuConfig`'s).
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
GYRO_BIAS_RW = math.radians(1e-3)  # [rad/s/sqrt(s)] (graphnav.graph.imu_chain.ImuConfig.bias_rw_gyro_deg)


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
                 v0: NDArray[np.float64] | None = None, yaw0: float = 0.0, *, gyro_bias: bool = False) -> None:
        self.s = samples
        m = model if isinstance(model, dict) else {}
        hz = float(m.get("hz") or HZ)
        acc, gyro = float(m.get("acc_std", ACC_STD)), float(m.get("gyro_std", GYRO_STD))
        self.q_acc, self.q_gyro = acc * acc / hz, gyro * gyro / hz  # continuous densities
        self.b_acc = float(m.get("acc_bias_sigma", ACC_BIAS))
        self.b_gyro = float(m.get("gyro_bias_sigma", GYRO_BIAS))
        self.q_bias = float(m.get("gyro_bias_rw") or GYRO_BIAS_RW) ** 2  # [rad^2/s^3] the bias's walk
        self.gyro_bias = gyro_bias  # the bias a state (else white noise of b_gyro per interval)
        self.bg = 0.0  # [rad/s] the gyro bias estimate (stays 0 without gyro_bias)
        if v0 is not None:  # a world-frame start velocity (meta["initial_velocity"]) in the body frame
            c, s = math.cos(yaw0), math.sin(yaw0)
            self.v = np.array([c * v0[0] + s * v0[1], -s * v0[0] + c * v0[1]])
            sv = 0.2
        else:
            self.v = np.zeros(2)
            sv = V0_SIGMA
        # the state's covariance: (vx, vy, b_g); the bias block is 0 and unused without gyro_bias
        self.P3 = np.diag([sv * sv, sv * sv, self.b_gyro**2 if gyro_bias else 0.0])
        self._rows: list[list[float]] | None = None  # the samples as Python floats (the bias's scalar loop)
        self._pred: tuple[float, float, NDArray[np.float64], NDArray[np.float64], float,
                          NDArray[np.float64], NDArray[np.float64]] | None = None
        self.last: tuple[float, float, NDArray[np.float64], NDArray[np.float64]] | None = None  # newest guess

    @property
    def P(self) -> NDArray[np.float64]:
        """The start velocity's covariance (2, 2)."""
        return self.P3[:2, :2]

    def __bool__(self) -> bool:
        return len(self.s) >= 2

    def _integrate(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float,
                                                         NDArray[np.float64], NDArray[np.float64]]:
        """Position and velocity change (frame of ``t0``, start velocity zero) and yaw over ``[t0, t1]``
        with the rate ``wz - bg``, and the derivatives of the position and velocity change by ``bg``."""
        t = self.s[:, 0]
        i = int(np.searchsorted(t, t0, side="right"))
        if self.gyro_bias:
            return self._integrate_bias(t0, t1, i)
        p, dv, th = np.zeros(2), np.zeros(2), 0.0
        lo = t0
        while lo < t1 - 1e-12:
            row = self.s[min(i, len(t) - 1)]
            hi = min(t[i], t1) if i < len(t) else t1
            dt = hi - lo
            if dt > 0:
                p, dv, th = strapdown_step(p, dv, th, row[1], row[2], row[3], dt)
            lo = hi
            i += 1
        return p, dv, th, np.zeros(2), np.zeros(2)

    def _integrate_bias(self, t0: float, t1: float, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                      float, NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`_integrate` with the bias: :func:`strapdown_step` in scalars, with the derivatives by ``bg``
        (the mid-step yaw moves by minus the mid-step time, and the specific force turns with it)."""
        if self._rows is None:
            self._rows = self.s.tolist()
        rows, n, bg = self._rows, len(self._rows), self.bg
        px = py = vx = vy = th = dpx = dpy = dvx = dvy = 0.0
        lo = t0
        while lo < t1 - 1e-12:
            row = rows[min(i, n - 1)]
            hi = min(rows[i][0], t1) if i < n else t1
            dt = hi - lo
            if dt > 0:
                wz = row[3] - bg
                mid = th + 0.5 * dt * wz
                c, s = math.cos(mid), math.sin(mid)
                ax, ay = c * row[1] - s * row[2], s * row[1] + c * row[2]
                k = -(lo - t0 + 0.5 * dt)  # d mid / d bg
                dax, day = -ay * k, ax * k
                h = 0.5 * dt * dt
                px, py = px + dt * vx + h * ax, py + dt * vy + h * ay
                vx, vy = vx + dt * ax, vy + dt * ay
                dpx, dpy = dpx + dt * dvx + h * dax, dpy + dt * dvy + h * day
                dvx, dvy = dvx + dt * dax, dvy + dt * day
                th += dt * wz
            lo = hi
            i += 1
        return np.array([px, py]), np.array([vx, vy]), th, np.array([dpx, dpy]), np.array([dvx, dvy])

    def _jacobian(self, dt: float, dp_db: NDArray[np.float64]) -> NDArray[np.float64]:
        """``d inc / d (vx, vy, b_g)`` (3, 3)."""
        return np.array([[dt, 0.0, dp_db[0]], [0.0, dt, dp_db[1]], [0.0, 0.0, -dt]])

    def _noise(self, dt: float) -> NDArray[np.float64]:
        """The increment's own noise over ``dt`` (white: not a state)."""
        q = np.zeros((3, 3))
        q[0, 0] = q[1, 1] = self.q_acc * dt**3 / 3 + (0.5 * self.b_acc * dt * dt) ** 2
        q[2, 2] = self.q_gyro * dt + (0.0 if self.gyro_bias else (self.b_gyro * dt) ** 2)
        return q

    def guess(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The predicted increment and its covariance."""
        dt = max(t1 - t0, 0.0)
        p, dv, th, dp_db, dv_db = self._integrate(t0, t1)
        inc = np.array([p[0] + self.v[0] * dt, p[1] + self.v[1] * dt, th])
        jac = self._jacobian(dt, dp_db)
        cov = jac @ self.P3 @ jac.T + self._noise(dt)
        cov = 0.5 * (cov + cov.T)
        self._pred = (t0, t1, inc, dv, th, dp_db, dv_db)
        self.last = (t0, t1, inc, cov)
        return inc, cov

    def predicted(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(J, Q)`` of the guess over ``[t0, t1]``: the increment's Jacobian by the state ``(vx, vy, b_g)``
        and its own (white) noise, the guess's covariance being ``J P J^T + Q``."""
        if self._pred is None or self._pred[:2] != (t0, t1):
            self.guess(t0, t1)
        assert self._pred is not None
        dt = max(t1 - t0, 0.0)
        return self._jacobian(dt, self._pred[5]), self._noise(dt)

    def update(self, t0: float, t1: float, pose: NDArray[np.float64] | None,
               cov: NDArray[np.float64] | None, weak: NDArray[np.float64] | None = None) -> None:
        """Close the interval: correct the state (start velocity; with ``gyro_bias`` the bias) by the
        match ``pose`` (``None``: no match, the prediction stands; ``weak``, the projector onto a
        degenerate match's weak directions: those are not measured), then carry it to ``t1`` (its
        frame) with the accelerometer's noise and the bias's walk (:meth:`advance`)."""
        if self._pred is None or self._pred[:2] != (t0, t1):
            self.guess(t0, t1)
        assert self._pred is not None
        _, _, inc, dv, th, dp_db, dv_db = self._pred
        dt = t1 - t0
        measured = pose is not None and cov is not None and dt > 1e-6 and np.all(np.isfinite(pose))
        if measured and not self.gyro_bias:
            z = self.v + (np.asarray(pose[:2], dtype=float) - inc[:2]) / dt  # the start velocity the match implies
            R = np.asarray(cov, dtype=float)[:2, :2] / (dt * dt) + np.eye(2) * self.q_acc * dt / 3
            if weak is not None:  # the weak directions carry the guess itself: not a measurement
                R = R + 1e8 * np.asarray(weak, dtype=float)[:2, :2]
            K = self.P @ np.linalg.inv(self.P + R)
            self.v = self.v + K @ (z - self.v)
            self.P3[:2, :2] = (np.eye(2) - K) @ self.P
        elif measured and np.all(np.isfinite(cov)):  # z = inc(x) + w: the match measures (vx, vy, b_g)
            jac = self._jacobian(dt, dp_db)
            r = np.asarray(cov, dtype=float) + self._noise(dt)
            if weak is not None:
                w = np.asarray(weak, dtype=float)
                r = r + 1e8 * (w @ w.T)
            e = np.asarray(pose, dtype=float) - inc
            e[2] = math.remainder(e[2], 2.0 * math.pi)
            gain = self.P3 @ jac.T @ np.linalg.inv(jac @ self.P3 @ jac.T + r)
            self.advance(t0, t1, gain @ e, (np.eye(3) - gain @ jac) @ self.P3)
            return
        self.advance(t0, t1)

    def advance(self, t0: float, t1: float, dx: NDArray[np.float64] | None = None,
                cov: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Close the interval ``[t0, t1]`` with the state's correction ``dx`` (vx, vy, b_g; None: none) and
        its covariance after it (``cov``; None: unchanged), and carry the state to ``t1`` (its frame).
        Returns ``(F, Q)``: the state at ``t1`` is ``F x + q``, ``q ~ N(0, Q)``."""
        if self._pred is None or self._pred[:2] != (t0, t1):
            self.guess(t0, t1)
        assert self._pred is not None
        _, _, inc, dv, th, dp_db, dv_db = self._pred
        dt = t1 - t0
        if cov is not None:
            self.P3 = np.asarray(cov, dtype=float).copy()
        if dx is not None:
            self.v = self.v + dx[:2]
            if self.gyro_bias:
                self.bg += float(dx[2])  # and the interval re-integrated with it, to first order
                dv = dv + dv_db * dx[2]
                th = th - dt * dx[2]
        c, s = math.cos(th), math.sin(th)
        rot_t = np.array([[c, s], [-s, c]])  # frame of t0 -> frame of t1
        f = np.eye(3)  # d (v1, b) / d (v0, b)
        f[:2, :2] = rot_t
        if self.gyro_bias:  # v1 = R(-th(b)) (v0 + dv(b)): th moves by -dt per unit bias
            drot = np.array([[-s, c], [-c, -s]])  # d rot_t / d th
            f[:2, 2] = rot_t @ dv_db + drot @ (self.v + dv) * -dt
        self.v = rot_t @ (self.v + dv)
        q = np.diag([self.q_acc * dt + (self.b_acc * dt) ** 2] * 2 + [self.q_bias * dt if self.gyro_bias else 0.0])
        self.P3 = f @ self.P3 @ f.T + q
        self.P3 = 0.5 * (self.P3 + self.P3.T)
        self._pred = None
        return f, q


def log_imu_guess(log: NavLog, yaw0: float, *, gyro_bias: bool = False) -> ImuGuess | None:
    """The IMU's prediction on ``log`` (None without two IMU records): its ``meta["imu"]`` model and
    ``meta["initial_velocity"]`` (world frame, over ground), taken into the body frame of the start
    pose's yaw ``yaw0`` -- the frame the odometry starts in; ``gyro_bias``: the gyro's bias a state."""
    meta = log.meta if isinstance(log.meta, dict) else {}
    v0 = meta.get("initial_velocity")
    guess = ImuGuess(imu_samples(log), meta.get("imu"), None if v0 is None else np.asarray(v0, dtype=float)[:2],
                     float(yaw0), gyro_bias=gyro_bias)
    return guess if guess else None
