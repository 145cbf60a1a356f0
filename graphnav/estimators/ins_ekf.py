"""The ``ekf``'s IMU motion (``motion="imu"``): a loosely coupled planar INS/GNSS EKF.

State ``[x, y, yaw, v_x, v_y]`` (navigation-frame velocity), optionally ``+ [b_ax, b_ay, b_g]``
(IMU biases, random walks), ``+ [c_x, c_y]`` (the water current, a random walk), ``+ [k]`` (the speed log's
scale, right after the current, with it only: the speed through water along the bow is ``k`` x the log's
reading; prior 1, a slow random walk) and ``+ [b_c]`` (the compass bias [rad], always last: the compass reads
``yaw + b_c``; a random walk, the graph's compass-bias model,
:class:`graphnav.graph.smoother_config.CompassConfig`, ``bias_drift_deg``). The same
model as the UKFs (:mod:`graphnav.estimators.ukf`), linearised: with ``a = R(yaw) (f - b_a)``::

    p += T v + T^2/2 a;  v += T a;  yaw += T (w_z - b_g)

Process noise from the IMU's white noise as a density (per-sample sigma ``s`` at rate ``hz``:
``s^2 / hz`` per second), bias and current random walks. Measurements: GNSS position (H picks x, y),
compass (yaw), GNSS velocity (v_x, v_y) and speed through water ``s`` as the graph's water model,
``R(yaw)^T (v - c) = (s, 0)`` (along the bow the record's sigma, across it the leeway), each through
:class:`PoseEkf`'s gated Joseph update. With the scale state the along-bow row is the reading
``s = (v - c) . e_yaw / k`` (the true speed along the bow is ``k s``), its sigma the record's: the measurement
side, where the log's noise is. Its Jacobian is the exact derivative at the estimate (``e_yaw / k`` on the
velocity and current, ``-(v - c) . e_yaw / k^2`` on ``k``; tests/estimators/test_log_scale.py checks it against
finite differences); the curvature in ``1/k`` is second order in the scale's error (a 10 % error: 1 % of
the speed). The state-side form ``(v - c) . e_yaw - k s = 0`` is linear in ``k``, but it makes the noisy
reading a regressor: with the current as the intercept, a filter (R fixed at each step) regresses the speed
along the bow on the reading, and on a straight leg at a steady speed, where the reading varies by its noise
only, ``k`` is attenuated toward 0 (errors in variables): on the simulated harbour (420 s, k = 1) it fell to
0.13 in the EKF and 0.12 in the UKF, the current taking the speed; ``1/k`` holds 1. A zero reading (a stalled
log) is censored (:meth:`InsEkf.update_water_zero`, :mod:`graphnav.graph.speed_log`).

Without an IMU (``motion="vessel"``, :meth:`InsEkf.predict_vessel`) the same state moves as the graph's
vessel model (:class:`graphnav.graph.imu_chain.ImuConfig`, ``vessel_*``): the velocity a random walk
driven by white-noise acceleration of density ``q_a``, the position its integral plus a random walk
``q_p`` of its own, the heading a random walk apart from the course (density ``q_y``, larger below
steerage speed)::

    p += T v;   Q_pp = q_a T^3/3 + q_p T,  Q_pv = q_a T^2/2,  Q_vv = q_a T,  Q_yaw = q_y T

With a rate of turn (the graph's vessel model's gyro z, :class:`graphnav.graph.imu_chain.RotChain`) the heading
turns by its integral less the gyro bias state, ``Q_yaw`` the ROT's own variance over ``T``.

(the exact discretisation of the continuous white-noise-acceleration model, Bar-Shalom et al. 2001, 6.2.2).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle
from ..graph.speed_log import through_water_rows
from .pose_ekf import PoseEkf


class InsEkf(PoseEkf):
    """:class:`PoseEkf` with the IMU-driven state (module docstring); ``x[:3]`` is the pose as in PoseEkf."""

    def __init__(self, x0: NDArray[np.float64], P0: NDArray[np.float64], *, bias: bool, current: bool,
                 acc_density: float, gyro_density: float, acc_bias_rw: float = 0.0, gyro_bias_rw: float = 0.0,
                 current_rw: float = 0.0, compass_bias: bool = False, compass_bias_rw: float = 0.0,
                 log_scale: bool = False, log_scale_rw: float = 0.0, **kw) -> None:
        super().__init__(x0, P0, **kw)
        if log_scale and not current:
            raise ValueError("the speed log's scale state needs the current states")
        n = 5 + 3 * bias + 2 * current + log_scale + compass_bias
        if self.x.shape != (n,) or self.P.shape != (n, n):
            raise ValueError(f"state must have {n} entries")
        self.ib = 5 if bias else None
        self.ic = 5 + 3 * bias if current else None
        self.il = 7 + 3 * bias if log_scale else None  # the speed log's scale k, after the current
        self.ik = n - 1 if compass_bias else None  # the compass bias [rad], the last state
        self.qa, self.qg = acc_density ** 2, gyro_density ** 2
        self.qba, self.qbg, self.qc = acc_bias_rw ** 2, gyro_bias_rw ** 2, current_rw ** 2
        self.qk = compass_bias_rw ** 2  # [rad^2/s]
        self.ql = log_scale_rw ** 2  # [1/s]

    @property
    def has_speed(self) -> bool:
        return False

    def predict_imu(self, ax: float, ay: float, wz: float, T: float) -> None:
        """Propagate over ``T`` [s] with the specific force ``(ax, ay)`` and yaw rate ``wz`` held."""
        if T <= 0.0:
            return
        x, n, ib = self.x, len(self.x), self.ib
        if ib is not None:
            ax, ay, wz = ax - x[ib], ay - x[ib + 1], wz - x[ib + 2]
        th = x[2]
        c, s = math.cos(th), math.sin(th)
        anx, any_ = c * ax - s * ay, s * ax + c * ay
        h = 0.5 * T * T
        F = np.eye(n)
        F[0, 3] = F[1, 4] = T
        F[0, 2], F[1, 2] = -h * any_, h * anx
        F[3, 2], F[4, 2] = -T * any_, T * anx
        if ib is not None:
            dA = np.array([[-c, s], [-s, -c]])  # d a_n / d (b_ax, b_ay)
            F[0:2, ib:ib + 2] = h * dA
            F[3:5, ib:ib + 2] = T * dA
            F[2, ib + 2] = -T
        Q = np.zeros((n, n))
        for i in (0, 1):
            Q[i, i] = self.qa * T ** 3 / 3
            Q[i, i + 3] = Q[i + 3, i] = self.qa * T * T / 2
            Q[i + 3, i + 3] = self.qa * T
        Q[2, 2] = self.qg * T
        if ib is not None:
            Q[ib, ib] = Q[ib + 1, ib + 1] = self.qba * T
            Q[ib + 2, ib + 2] = self.qbg * T
        if self.ic is not None:
            Q[self.ic, self.ic] = Q[self.ic + 1, self.ic + 1] = self.qc * T
        if self.il is not None:
            Q[self.il, self.il] = self.ql * T
        if self.ik is not None:
            Q[self.ik, self.ik] = self.qk * T
        x[0] += T * x[3] + h * anx
        x[1] += T * x[4] + h * any_
        x[3] += T * anx
        x[4] += T * any_
        x[2] = wrap_angle(th + T * wz)
        self.P = F @ self.P @ F.T + Q

    def predict_vessel(self, T: float, *, accel_density: float, yaw_density: float,
                       position_walk: float = 0.0, rot: tuple[float, float] | None = None) -> None:
        """Propagate over ``T`` [s] without an IMU (module docstring): constant velocity, the heading held;
        densities in [m/s^2/sqrt(s)], [rad/s/sqrt(s)] and [m/sqrt(s)]. ``rot``: a rate of turn's integral
        over ``T`` [rad] and its variance [rad^2] (:meth:`graphnav.graph.imu_chain.RotChain.interval`): the
        heading turns by it, less ``T`` x the gyro bias state, with that variance instead of ``yaw_density``'s."""
        if T <= 0.0:
            return
        x, n = self.x, len(self.x)
        F = np.eye(n)
        F[0, 3] = F[1, 4] = T
        if rot is not None and self.ib is not None:
            F[2, self.ib + 2] = -T
        qa = accel_density ** 2
        Q = np.zeros((n, n))
        for i in (0, 1):
            Q[i, i] = qa * T ** 3 / 3 + position_walk ** 2 * T
            Q[i, i + 3] = Q[i + 3, i] = qa * T * T / 2
            Q[i + 3, i + 3] = qa * T
        Q[2, 2] = yaw_density ** 2 * T if rot is None else rot[1]
        if self.ib is not None:
            Q[self.ib, self.ib] = Q[self.ib + 1, self.ib + 1] = self.qba * T
            Q[self.ib + 2, self.ib + 2] = self.qbg * T
        if self.ic is not None:
            Q[self.ic, self.ic] = Q[self.ic + 1, self.ic + 1] = self.qc * T
        if self.il is not None:
            Q[self.il, self.il] = self.ql * T
        if self.ik is not None:
            Q[self.ik, self.ik] = self.qk * T
        x[0] += T * x[3]
        x[1] += T * x[4]
        if rot is not None:
            x[2] = wrap_angle(x[2] + rot[0] - (T * x[self.ib + 2] if self.ib is not None else 0.0))
        self.P = F @ self.P @ F.T + Q

    def update_heading(self, yaw: float, sigma: float, t: float | None = None) -> bool:
        """Compass heading: ``yaw + b_c`` with the compass-bias state, else ``yaw`` (:class:`PoseEkf`); a
        re-initialisation restarts the yaw at the reading less the bias (the bias kept)."""
        ik = self.ik
        if ik is None:
            return super().update_heading(yaw, sigma, t)
        H = np.zeros((1, len(self.x)))
        H[0, 2] = H[0, ik] = 1.0
        nu = np.array([wrap_angle(yaw - self.x[2] - self.x[ik])])
        return self._update("heading", nu, H, np.array([[sigma ** 2]]), t, angle=True, reinit_idx=[2])

    def speed_through_water(self) -> float:
        """``|v - c|`` [m/s] (``|v|`` without the current states)."""
        x, ic = self.x, self.ic
        return math.hypot(x[3] - x[ic], x[4] - x[ic + 1]) if ic is not None else math.hypot(x[3], x[4])

    def update_velocity(self, v: tuple[float, float], sigma: float, t: float | None = None) -> bool:
        """GNSS velocity over ground (east, north) [m/s]."""
        H = np.zeros((2, len(self.x)))
        H[0, 3] = H[1, 4] = 1.0
        return self._update("gnss_velocity", np.asarray(v, dtype=float) - self.x[3:5], H, np.eye(2) * sigma ** 2, t)

    def update_sog(self, v: float, sigma: float, t: float | None = None) -> bool:
        """Speed over ground ``|v|`` (an odometry record's speed: a Doppler log / SOG); skipped
        (False) below 0.2 m/s, where its direction is undefined."""
        vx, vy = self.x[3], self.x[4]
        h = math.hypot(vx, vy)
        if h < 0.2 or abs(v) < 0.2:
            return False
        H = np.zeros((1, len(self.x)))
        H[0, 3], H[0, 4] = vx / h, vy / h
        return self._update("speed", np.array([abs(v) - h]), H, np.array([[sigma ** 2]]), t, reinit=False)

    def update_water_speed(self, v: float, sigma: float, t: float | None = None, *, leeway: float) -> bool:
        """Speed through water ``v`` along the bow (needs the current states), the graph's water model
        (:meth:`graphnav.graph.measurements.Measurements.water_speed`): the velocity through the water
        ``v - c`` is ``v (cos yaw, sin yaw)``, ``sigma`` along the bow and ``leeway`` [m/s] across it.
        With the scale state ``k`` the log reads ``(v - c) . e_yaw / k`` (module docstring)."""
        if self.ic is None:
            raise ValueError("a water-speed update needs the current states")
        ic, il, x = self.ic, self.il, self.x
        c, s = math.cos(x[2]), math.sin(x[2])
        ux, uy = x[3] - x[ic], x[4] - x[ic + 1]
        H = np.zeros((2, len(x)))  # (along, across) the bow: rows of R(yaw)^T (u - v e_yaw)
        H[0, 3], H[0, 4], H[1, 3], H[1, 4] = c, s, -s, c
        H[:, ic:ic + 2] = -H[:, 3:5]
        H[0, 2], H[1, 2] = -ux * s + uy * c, -ux * c - uy * s
        along = ux * c + uy * s
        if il is not None:  # the log reads (u . e_yaw) / k: the along row divided by k, and its k column
            k = x[il]
            H[0, :] /= k
            H[0, il] = -along / (k * k)
            along /= k
        nu = np.array([v - along, -(-ux * s + uy * c)])
        return self._update("water_speed", nu, H, np.diag([sigma ** 2, leeway ** 2]), t, reinit=False)

    def update_water_zero(self, sigma: float, across: float, t: float | None = None) -> bool:
        """A zero reading of a stalled log (:mod:`graphnav.graph.speed_log`): the velocity through the water
        ``R(yaw)^T (v - c) = (0, 0)``, ``sigma`` along the bow and ``across`` it (each with the stall's spread),
        linear in ``(v, c)``: the scale state's column zero (a reading of nothing has no scale), the heading's too
        (the bow only orients the sigmas)."""
        if self.ic is None:
            raise ValueError("a water-speed update needs the current states")
        H = through_water_rows(len(self.x), float(self.x[2]), 3, self.ic)
        nu = -H @ self.x
        return self._update("water_speed_zero", nu, H, np.diag([sigma ** 2, across ** 2]), t, reinit=False)
