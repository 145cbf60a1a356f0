"""Log records -> native GTSAM factors (no Python ``CustomFactor``).

One module per sensor: :mod:`factors.gnss` (``PoseTranslationPrior2D``), :mod:`factors.compass`
(``PoseRotationPrior2D`` or a bias-aware ``BetweenFactorPose2``), :mod:`factors.between`
(ICP and odometry ``BetweenFactorPose2``), :mod:`factors.beacon` (``BearingRangeFactor2D`` and
``PriorFactorPoint2``), :mod:`factors.prior` (``PriorFactorPose2``) and :mod:`factors.robust`
(Huber/Cauchy wrappers). Keys are plain GTSAM
symbols: ``X(k)`` poses, ``L(i)`` beacons, ``B(0)`` the compass bias frame.
"""

from __future__ import annotations

import gtsam

from .beacon import beacon_factor, beacon_prior, init_from_sighting, pose_from_two_beacons
from .between import compose_with_cov, icp_between, odometry_between, odometry_increment
from .compass import biased_compass_factor, compass_bias, compass_bias_prior, compass_factor
from .gnss import gnss_factor
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
    "L",
    "X",
    "beacon_factor",
    "beacon_prior",
    "biased_compass_factor",
    "compass_bias",
    "compass_bias_prior",
    "compass_factor",
    "compose_with_cov",
    "gnss_factor",
    "icp_between",
    "init_from_sighting",
    "odometry_between",
    "odometry_increment",
    "pose_from_two_beacons",
    "pose_prior",
    "robustify",
]
