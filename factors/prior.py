"""Pose prior -> ``PriorFactorPose2``: the anchor of a graph (a start pose, or a re-anchored
window carrying its marginal covariance)."""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import ArrayLike


def pose_prior(key: int, pose: ArrayLike, cov: ArrayLike) -> gtsam.PriorFactorPose2:
    """Prior on pose ``key`` at ``pose = (x, y, theta)`` with covariance ``cov``: a 3-vector of
    sigmas (diagonal) or a full 3x3 matrix in GTSAM's Pose2 tangent space."""
    p = np.asarray(pose, dtype=float)
    c = np.asarray(cov, dtype=float)
    if c.shape == (3,):
        noise = gtsam.noiseModel.Diagonal.Sigmas(c)
    else:
        noise = gtsam.noiseModel.Gaussian.Covariance(0.5 * (c + c.T))
    return gtsam.PriorFactorPose2(key, gtsam.Pose2(p[0], p[1], p[2]), noise)
