"""Relative-pose factors: weighted-ICP matches and odometry, both ``BetweenFactorPose2``.

Covariances are in GTSAM's Pose2 tangent space at the measured relative pose (x, y, theta of
the right perturbation ``T * Exp(d)``), which is what ``BetweenFactorPose2`` whitens.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .robust import robustify


def icp_between(
    k0: int, k1: int, pose: ArrayLike, cov: ArrayLike, *, robust: str | None = None, k: float | None = None
) -> gtsam.BetweenFactorPose2:
    """ICP relative pose ``pose = (x, y, theta)`` (prev -> current) with its full 3x3 covariance."""
    cov = np.asarray(cov, dtype=float).reshape(3, 3)
    cov = 0.5 * (cov + cov.T)
    noise = robustify(gtsam.noiseModel.Gaussian.Covariance(cov), robust, k)
    p = np.asarray(pose, dtype=float)
    return gtsam.BetweenFactorPose2(k0, k1, gtsam.Pose2(p[0], p[1], p[2]), noise)


def odometry_increment(
    v: float,
    w: float,
    dt: float,
    sigma_v: float,
    sigma_w: float,
    *,
    lateral: float = 0.05,
    floor: float = 1e-4,
) -> tuple[gtsam.Pose2, NDArray[np.float64]]:
    """Relative pose and tangent covariance of constant (v, w) over ``dt``.

    The beacon paper's motion model (eq. 3) integrated exactly over the step (an arc; eq. 3's
    Euler step is its first-order form), with the speed/ROT errors (eqs. 4-5) propagated through
    its Jacobian ``J = d(x, y, theta)/d(v, w)``: ``Sigma = J diag(sigma_v^2, sigma_w^2) J^T``.
    The two inputs leave a rank-2 covariance, so a lateral (sway/current) term of
    ``lateral * |v| dt`` [m] and an isotropic ``floor`` are added.
    """
    phi = w * dt
    if abs(phi) < 1e-6:
        x, y = v * dt * (1.0 - phi * phi / 6.0), v * dt * phi / 2.0
        jv = (dt * (1.0 - phi * phi / 6.0), dt * phi / 2.0)
        jw = (-v * dt * dt * phi / 3.0, v * dt * dt / 2.0)
    else:
        s, c = math.sin(phi), math.cos(phi)
        x, y = v * s / w, v * (1.0 - c) / w
        jv = (s / w, (1.0 - c) / w)
        jw = (v * (phi * c - s) / w**2, v * (phi * s - (1.0 - c)) / w**2)
    # J = d(x, y, theta)/d(v, w) rotated into the tangent at the end (R(-phi) on x, y): M J
    c, s = math.cos(phi), math.sin(phi)
    mj = np.array(
        [
            [c * jv[0] + s * jv[1], c * jw[0] + s * jw[1]],
            [-s * jv[0] + c * jv[1], -s * jw[0] + c * jw[1]],
            [0.0, dt],
        ]
    )
    cov = (mj * (sigma_v**2, sigma_w**2)) @ mj.T  # M J diag(sigma_v^2, sigma_w^2) J^T M^T
    cov[1, 1] += (lateral * abs(v) * dt) ** 2
    cov[np.diag_indices(3)] += floor**2
    return gtsam.Pose2(x, y, phi), cov


def compose_with_cov(
    a: gtsam.Pose2, cov_a: NDArray[np.float64], b: gtsam.Pose2, cov_b: NDArray[np.float64]
) -> tuple[gtsam.Pose2, NDArray[np.float64]]:
    """``a * b`` and its tangent covariance ``Ad(b^-1) cov_a Ad(b^-1)^T + cov_b`` (independent errors)."""
    A = b.inverse().AdjointMap()
    return a.compose(b), A @ cov_a @ A.T + cov_b


def odometry_between(k0: int, k1: int, delta: gtsam.Pose2, cov: ArrayLike) -> gtsam.BetweenFactorPose2:
    """Odometry increment (from :func:`odometry_increment`/:func:`compose_with_cov`) as a factor."""
    cov = np.asarray(cov, dtype=float)
    return gtsam.BetweenFactorPose2(k0, k1, delta, gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T)))
