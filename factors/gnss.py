"""GNSS fix -> a position factor on a pose key, robust by default (multipath jumps).

At the body origin a native ``PoseTranslationPrior2D``. With a lever arm ``a`` (the antenna's
offset in the body frame) the fix measures ``t + R(yaw) a``: GTSAM has no native Pose2 factor for
that (``GPSFactorArm`` is Pose3's, used by :func:`factors.imu.gnss3_factor`), so it is the small
``CustomFactor`` :func:`antenna_error` with its analytic Jacobian (tests/test_mounts.py checks it
against numerical differentiation).
"""

from __future__ import annotations

import math
from functools import partial

import gtsam
import numpy as np
from numpy.typing import NDArray

from .robust import robustify


def antenna_position(pose: gtsam.Pose2, arm: tuple[float, float]) -> NDArray[np.float64]:
    """World position ``t + R(yaw) a`` of a point at ``arm`` [m] in the body frame of ``pose``."""
    c, s = math.cos(pose.theta()), math.sin(pose.theta())
    return np.array([pose.x() + c * arm[0] - s * arm[1], pose.y() + s * arm[0] + c * arm[1]])


def antenna_error(z: NDArray[np.float64], arm: tuple[float, float], this: gtsam.CustomFactor,
                  values: gtsam.Values, H: list[NDArray[np.float64]] | None) -> NDArray[np.float64]:
    """``t + R(yaw) a - z`` and, in ``H[0]``, its 2x3 Jacobian in Pose2's body tangent (vx, vy, w):
    ``[R(yaw), R(yaw) (-a_y, a_x)]``."""
    pose = values.atPose2(this.keys()[0])
    if H is not None:
        c, s = math.cos(pose.theta()), math.sin(pose.theta())
        R = np.array([[c, -s], [s, c]])
        H[0] = np.column_stack([R, R @ np.array([-arm[1], arm[0]])])
    return antenna_position(pose, arm) - z


def gnss_factor(
    key: int, x: float, y: float, sigma: float, *, robust: str | None = "huber", k: float | None = None,
    arm: tuple[float, float] | None = None,
) -> gtsam.NonlinearFactor:
    """Position fix ``(x, y)`` [m] of the antenna at ``arm`` (body frame, m; ``None``/zero: the body
    origin) with isotropic ``sigma`` [m], wrapped in a robust kernel."""
    noise = robustify(gtsam.noiseModel.Isotropic.Sigma(2, float(sigma)), robust, k)
    z = np.array([x, y], dtype=float)
    if arm is None or (arm[0] == 0.0 and arm[1] == 0.0):
        return gtsam.PoseTranslationPrior2D(key, z, noise)
    return gtsam.CustomFactor(noise, [key], partial(antenna_error, z, (float(arm[0]), float(arm[1]))))
