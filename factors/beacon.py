"""Beacon range/bearing -> ``BearingRangeFactor2D`` to a Point2 beacon key; charted beacons get
a ``PriorFactorPoint2``; unknown beacons are initialised from their first sighting.

The measurement model is the beacon paper's (range and bearing from the bow, CCW positive).
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .robust import robustify


def beacon_factor(
    pose_key: int,
    point_key: int,
    range_: float,
    bearing: float,
    sigma_range: float,
    sigma_bearing: float,
    *,
    robust: str | None = None,
    k: float | None = None,
) -> gtsam.BearingRangeFactor2D:
    """Range [m] and bearing [rad] from pose ``pose_key`` to beacon ``point_key``."""
    noise = robustify(
        gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma_bearing, sigma_range], dtype=float)), robust, k
    )
    return gtsam.BearingRangeFactor2D(pose_key, point_key, gtsam.Rot2(float(bearing)), float(range_), noise)


def beacon_prior(point_key: int, x: float, y: float, sigma: float) -> gtsam.PriorFactorPoint2:
    """A charted beacon at ``(x, y)`` with ``sigma`` [m] per axis."""
    return gtsam.PriorFactorPoint2(
        point_key, np.array([x, y], dtype=float), gtsam.noiseModel.Isotropic.Sigma(2, float(sigma))
    )


def init_from_sighting(pose: ArrayLike, range_: float, bearing: float) -> NDArray[np.float64]:
    """World position of a beacon seen at ``range_``/``bearing`` from ``pose`` (x, y, yaw)."""
    x, y, th = np.asarray(pose, dtype=float)
    return np.array([x + range_ * np.cos(th + bearing), y + range_ * np.sin(th + bearing)])


def pose_from_two_beacons(
    p1: ArrayLike, rb1: tuple[float, float], p2: ArrayLike, rb2: tuple[float, float]
) -> NDArray[np.float64]:
    """Pose (x, y, yaw) from simultaneous range/bearing sightings of two charted beacons.

    The body-frame vector between the two sightings and the charted world vector differ by the
    yaw; the position follows from either sighting.
    """
    p1, p2 = np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)
    b1 = rb1[0] * np.array([np.cos(rb1[1]), np.sin(rb1[1])])
    b2 = rb2[0] * np.array([np.cos(rb2[1]), np.sin(rb2[1])])
    db, dw = b2 - b1, p2 - p1
    yaw = np.arctan2(dw[1], dw[0]) - np.arctan2(db[1], db[0])
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    pos = 0.5 * ((p1 - R @ b1) + (p2 - R @ b2))
    return np.array([pos[0], pos[1], gtsam.Rot2.fromAngle(float(yaw)).theta()])  # wrapped to [-pi, pi]
