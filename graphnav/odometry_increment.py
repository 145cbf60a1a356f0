"""Relative pose between two times from the log's odometry (SOG + ROT), with its covariance.

The beacon paper's unicycle motion model (eq. 3) integrated exactly over each odometry interval
(zero-order hold of the latest sample: an arc of constant ``v``, ``w``;
:func:`factors.between.odometry_increment`), the arcs composed with first-order covariance
propagation ``P' = Ad(inc^-1) P Ad(inc^-1)^T + Q`` in GTSAM's Pose2 tangent convention (the
same model as the smoother's odometry factors). Pure numerics, no I/O.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .geometry import se2_adjoint_inv, se2_compose
from .log import NavLog


def odometry_samples(log: NavLog, sigma_v: float = 0.1, sigma_w: float = math.radians(1.0)) -> NDArray[np.float64]:
    """The log's odometry records as an (N, 5) array ``t, v, w, sigma_v, sigma_w`` (the given
    sigmas where a record has none)."""
    rows = [[r.t, r.v, r.w, r.sigma_v if math.isfinite(r.sigma_v) else sigma_v,
             r.sigma_w if math.isfinite(r.sigma_w) else sigma_w] for r in log.of("odometry")]
    return np.array(rows, dtype=float).reshape(-1, 5)


def arc(v: float, w: float, dt: float, sigma_v: float, sigma_w: float,
        lateral: float = 0.05) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Relative pose ``(x, y, yaw)`` of constant ``(v, w)`` over ``dt`` and its tangent covariance
    (speed and ROT errors through the arc's Jacobian, plus a lateral ``lateral |v| dt`` term)."""
    from factors.between import odometry_increment

    d, cov = odometry_increment(v, w, dt, sigma_v, sigma_w, lateral=lateral)
    return np.array([d.x(), d.y(), d.theta()]), cov



def increment(samples: NDArray[np.float64], t0: float, t1: float, *,
              lateral: float = 0.05) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Pose at ``t1`` in the frame of the pose at ``t0`` from odometry ``samples`` (N, 5) (see
    :func:`odometry_samples`), and its covariance; ``None`` when no sample is at or before ``t1``
    or ``t1 < t0``. Before the first sample the first one is held."""
    if len(samples) == 0 or t1 < t0 or samples[0, 0] > t1:
        return None
    i = max(int(np.searchsorted(samples[:, 0], t0, side="right")) - 1, 0)
    pose, cov = np.zeros(3), np.zeros((3, 3))
    t = t0
    while t < t1 - 1e-12:
        t_next = samples[i + 1, 0] if i + 1 < len(samples) else math.inf
        te = min(t_next, t1)
        _, v, w, sv, sw = samples[i]
        d, q = arc(v, w, te - t, sv, sw, lateral)
        a = se2_adjoint_inv(d)
        cov = a @ cov @ a.T + q
        pose = se2_compose(pose, d)
        t = te
        if te >= t_next:
            i += 1
    return pose, cov
