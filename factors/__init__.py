"""Log records -> native GTSAM factors (one small Python ``CustomFactor``: a Pose2 GNSS fix with a lever arm).

One module per sensor: :mod:`factors.gnss` (``PoseTranslationPrior2D``), :mod:`factors.compass`
(``PoseRotationPrior2D`` or a bias-aware ``BetweenFactorPose2``), :mod:`factors.between`
(ICP and odometry ``BetweenFactorPose2``), :mod:`factors.imu` (``ImuFactor`` preintegration,
``GPSFactor``/``PoseRotationPrior3D`` on ``Pose3``), :mod:`factors.beacon` (``BearingRangeFactor2D``
and ``PriorFactorPoint2``), :mod:`factors.prior` (``PriorFactorPose2``) and :mod:`factors.robust`
(Huber/Cauchy wrappers). Keys are plain GTSAM symbols: ``X(k)`` poses, ``V(k)`` velocities,
``IB(k)`` IMU biases, ``L(i)`` beacons, ``B(0)`` the compass bias frame.
"""

from __future__ import annotations

import gtsam

from .beacon import beacon_factor, beacon_prior, init_from_sighting, pose_from_two_beacons
from .between import compose_with_cov, icp_between, odometry_between, odometry_increment
from .compass import biased_compass_factor, compass_bias, compass_bias_prior, compass_factor
from .gnss import antenna_position, gnss_factor
from .imu import (
    IB,
    V,
    bias_between,
    bias_prior,
    compass3_factor,
    gnss3_factor,
    imu_factor,
    planar_pose,
    pose_xy_yaw,
    preintegrate,
    preintegrate_arrays,
)
from .prior import pose_prior
from .robust import robustify


def X(k: int) -> int:
    """Key of pose ``k``."""
    return gtsam.symbol("x", k)


def L(i: int) -> int:
    """Key of beacon ``i``."""
    return gtsam.symbol("l", i)


def B(i: int = 0) -> int:
    """Key of the compass-bias frame."""
    return gtsam.symbol("b", i)


__all__ = [
    "B",
    "antenna_position",
    "IB",
    "L",
    "V",
    "X",
    "beacon_factor",
    "beacon_prior",
    "bias_between",
    "bias_prior",
    "biased_compass_factor",
    "compass_bias",
    "compass_bias_prior",
    "compass_factor",
    "compass3_factor",
    "compose_with_cov",
    "gnss3_factor",
    "gnss_factor",
    "imu_factor",
    "icp_between",
    "init_from_sighting",
    "odometry_between",
    "odometry_increment",
    "planar_pose",
    "pose_from_two_beacons",
    "pose_prior",
    "pose_xy_yaw",
    "preintegrate",
    "preintegrate_arrays",
    "robustify",
]
