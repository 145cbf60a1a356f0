"""Compass heading -> yaw factor on a pose key.

Two forms, both native:

* :func:`compass_factor` — ``PoseRotationPrior2D`` (Rot2 handles the wrap-around).
* :func:`biased_compass_factor` — for a compass with an unknown constant bias ``b``
  (``yaw_meas = yaw + b``): a ``BetweenFactorPose2`` from a bias frame ``B`` to the pose with
  infinite sigma on x/y and ``sigma`` on yaw, so its only residual is
  ``yaw - theta_B - yaw_meas``; hence ``theta_B = -b``. ``B`` gets a tight prior at the origin
  in x/y and a ``sigma_bias`` prior on its angle (:func:`compass_bias_prior`). The bias is
  observable whenever the motion measured in the body frame (ICP, odometry) is compared with
  positions in the world frame (GNSS, beacons).
"""

from __future__ import annotations

import gtsam
import numpy as np

from .robust import robustify


def compass_factor(
    key: int, yaw: float, sigma: float, *, robust: str | None = None, k: float | None = None
) -> gtsam.PoseRotationPrior2D:
    """Yaw prior ``yaw`` [rad] with ``sigma`` [rad]."""
    noise = robustify(gtsam.noiseModel.Isotropic.Sigma(1, float(sigma)), robust, k)
    return gtsam.PoseRotationPrior2D(key, gtsam.Rot2(float(yaw)), noise)


def biased_compass_factor(
    bias_key: int, key: int, yaw: float, sigma: float, *, robust: str | None = None, k: float | None = None
) -> gtsam.BetweenFactorPose2:
    """Yaw measurement through the bias frame ``bias_key`` (see the module docstring)."""
    noise = gtsam.noiseModel.Diagonal.Precisions(np.array([0.0, 0.0, 1.0 / float(sigma) ** 2]))
    return gtsam.BetweenFactorPose2(
        bias_key, key, gtsam.Pose2(0.0, 0.0, float(yaw)), robustify(noise, robust, k)
    )


def compass_bias_prior(bias_key: int, sigma_bias: float, *, mean: float = 0.0) -> gtsam.PriorFactorPose2:
    """Prior on the bias frame: x/y pinned at 0 (1 mm), angle ``-mean`` with ``sigma_bias`` [rad]."""
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 1e-3, float(sigma_bias)]))
    return gtsam.PriorFactorPose2(bias_key, gtsam.Pose2(0.0, 0.0, -float(mean)), noise)


def compass_bias(bias_frame: gtsam.Pose2) -> float:
    """The compass bias ``b`` [rad] (``yaw_meas - yaw``) held by an estimated bias frame."""
    return -bias_frame.theta()
