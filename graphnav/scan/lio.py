"""One step of the loosely coupled LiDAR-inertial filter shared by ``icp-dr`` and ``scan-to-map``.

The state is ``(pose at t0, IMU state at t0, increment t0 -> t1)`` (stochastic cloning, Roumeliotis &
Burdick 2002): the IMU's state is :class:`~graphnav.scan.imu_guess.ImuGuess`'s ``(vx, vy, b_g)``, the
increment its prediction ``J x + w``; the pose's errors are right perturbations, ``cross`` the pose's
covariance with the IMU's state. A LiDAR match measures either the increment (icp-dr: a scan against its
keyframe) or the composed pose (scan-to-map: a scan against the local map, in the map's frame); the update
corrects all three, then the pose at ``t1`` is the corrected pose composed with the corrected increment
and the IMU's state is carried to ``t1`` (:meth:`~graphnav.scan.imu_guess.ImuGuess.advance`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..geometry import se2_adjoint_inv, se2_between, se2_compose
from .imu_guess import ImuGuess

Meas = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]  # (z, covariance, weak)


def imu_tangent(imu: ImuGuess, t0: float, t1: float, inc: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The IMU guess's Jacobian by its state and its own noise over ``[t0, t1]``, in the increment's
    tangent space (right perturbation: ``xi_xy = R(-dyaw) d(dx, dy)``)."""
    jac, q = imu.predicted(t0, t1)
    c, s = np.cos(inc[2]), np.sin(inc[2])
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ jac, rot @ q @ rot.T


def _joint(imu: ImuGuess, t0: float, t1: float, pose_cov: NDArray[np.float64], cross: NDArray[np.float64],
           inc: NDArray[np.float64]) -> NDArray[np.float64]:
    """The (9, 9) covariance of ``(pose, IMU state, increment)`` before any match."""
    jac, q = imu_tangent(imu, t0, t1, inc)
    pxx = imu.P3
    big = np.zeros((9, 9))
    big[:3, :3], big[:3, 3:6], big[3:6, 3:6] = pose_cov, cross, pxx
    big[3:6, :3] = cross.T
    big[:6, 6:] = np.vstack([cross, pxx]) @ jac.T
    big[6:, :6] = big[:6, 6:].T
    big[6:, 6:] = jac @ pxx @ jac.T + q
    return big


def composed_cov(imu: ImuGuess, t0: float, t1: float, pose_cov: NDArray[np.float64], cross: NDArray[np.float64],
                 inc: NDArray[np.float64]) -> NDArray[np.float64]:
    """The covariance of ``pose (+) inc`` predicted by the IMU, no match heard (the increment shares the
    IMU's state with the pose)."""
    big = _joint(imu, t0, t1, pose_cov, cross, inc)
    m = np.hstack([se2_adjoint_inv(inc), np.zeros((3, 3)), np.eye(3)])
    cov = m @ big @ m.T
    return 0.5 * (cov + cov.T)


def lio_step(imu: ImuGuess, t0: float, t1: float, pose: NDArray[np.float64], pose_cov: NDArray[np.float64],
             cross: NDArray[np.float64], inc: NDArray[np.float64], meas: Meas | None, *, of_pose: bool = False,
             consider_xy: bool = False) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The pose at ``t1``, its covariance and its covariance with the IMU's state at ``t1``, from the pose at
    ``t0`` (``pose_cov``, ``cross``), the IMU's predicted increment ``inc`` and a match ``meas`` (``(z, r,
    weak)``: its estimate, covariance and the projector onto the directions it cannot see; None: the
    prediction stands) of the increment, or with ``of_pose`` of the composed pose ``pose (+) inc``.
    ``consider_xy``: the position at ``t0`` a consider state (Schmidt: not corrected, its covariance kept
    right by the Joseph form)."""
    big = _joint(imu, t0, t1, pose_cov, cross, inc)
    dx = None
    if meas is not None:
        z, r, weak = meas
        if weak is not None:
            r = r + 1e8 * (weak @ weak.T)
        h = np.hstack([se2_adjoint_inv(inc) if of_pose else np.zeros((3, 3)), np.zeros((3, 3)), np.eye(3)])
        bh = big @ h.T
        gain = bh @ np.linalg.inv(h @ bh + r)
        if consider_xy:
            gain[:2] = 0.0
        d = gain @ se2_between(se2_compose(pose, inc) if of_pose else inc, z)
        ikh = np.eye(9) - gain @ h  # Joseph form, right for any gain
        big = ikh @ big @ ikh.T + gain @ r @ gain.T
        pose, inc, dx = se2_compose(pose, d[:3]), se2_compose(inc, d[6:]), d[3:6]
    f, qx = imu.advance(t0, t1, dx, big[3:6, 3:6])
    m = np.zeros((6, 9))
    m[:3, :3], m[:3, 6:], m[3:, 3:6] = se2_adjoint_inv(inc), np.eye(3), f
    new = m @ big @ m.T
    new[3:, 3:] += qx
    return se2_compose(pose, inc), 0.5 * (new[:3, :3] + new[:3, :3].T), new[:3, 3:]
