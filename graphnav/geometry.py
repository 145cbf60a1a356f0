"""Angles and SE(2) poses: the project's conventions in code.

Conventions (stated once, see docs/conventions.md): SI units, angles in radians,
yaw counter-clockwise from +x (east) of a local metric frame (x east, y north).
Nautical headings (degrees clockwise from north) exist only at the edges.
A pose is ``(x, y, yaw)``; arrays of poses have shape ``(N, 3)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

TWO_PI = 2.0 * np.pi


def wrap_angle(a: ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angles to [-pi, pi) (the one angle wrap of the project; scalars take a math fast path)."""
    if isinstance(a, (float, int)):
        return (a + math.pi) % (2.0 * math.pi) - math.pi
    w = (np.asarray(a, dtype=float) + np.pi) % TWO_PI - np.pi
    return float(w) if np.ndim(w) == 0 else w


def cov_to_world(yaw: float, cov: ArrayLike) -> NDArray[np.float64]:
    """A body-frame (x, y, yaw) covariance -> the world frame: ``R cov R^T`` with ``R = diag(R(yaw), 1)``.

    GTSAM's ``Pose2`` marginals are in the body tangent (right perturbation); this is the one
    place the project rotates a planar covariance to the world (x, y, yaw) axes.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return r @ np.asarray(cov, dtype=float) @ r.T


def yaw_to_heading_deg(yaw: ArrayLike) -> NDArray[np.float64] | float:
    """Yaw (rad, CCW from east) -> nautical heading (deg, clockwise from north, [0, 360))."""
    h = np.mod(90.0 - np.degrees(np.asarray(yaw, dtype=float)), 360.0)
    return float(h) if np.ndim(h) == 0 else h


def heading_deg_to_yaw(heading_deg: ArrayLike) -> NDArray[np.float64] | float:
    """Nautical heading (deg, clockwise from north) -> yaw (rad, CCW from east, wrapped)."""
    return wrap_angle(np.radians(90.0 - np.asarray(heading_deg, dtype=float)))


def rot2(theta: float) -> NDArray[np.float64]:
    """2x2 rotation matrix."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def se2_compose(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """a ⊕ b for poses (x, y, yaw); broadcasts over leading dimensions."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == b.shape == (3,):  # one pose each: the same arithmetic on floats (~10x less overhead)
        ax, ay, at = a.tolist()
        bx, by, bt = b.tolist()
        c, s = math.cos(at), math.sin(at)
        return np.array([ax + c * bx - s * by, ay + s * bx + c * by, wrap_angle(at + bt)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def se2_inverse(a: ArrayLike) -> NDArray[np.float64]:
    """⊖a for poses (x, y, yaw)."""
    a = np.asarray(a, dtype=float)
    if a.shape == (3,):
        ax, ay, at = a.tolist()
        c, s = math.cos(at), math.sin(at)
        return np.array([-c * ax - s * ay, s * ax - c * ay, wrap_angle(-at)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def se2_between(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """⊖a ⊕ b: pose of b expressed in the frame of a."""
    return se2_compose(se2_inverse(a), b)


def se2_matrix(p: ArrayLike) -> NDArray[np.float64]:
    """Homogeneous 3x3 matrix of a pose."""
    x, y, th = np.asarray(p, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def se2_from_matrix(m: ArrayLike) -> NDArray[np.float64]:
    """Pose (x, y, yaw) of a homogeneous 3x3 (or the x-y block of a 4x4) matrix."""
    m = np.asarray(m, dtype=float)
    if m.shape == (4, 4):
        return np.array([m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])])
    return np.array([m[0, 2], m[1, 2], np.arctan2(m[1, 0], m[0, 0])])


def se2_adjoint_inv(inc: ArrayLike) -> NDArray[np.float64]:
    """``Ad(inc^-1)`` of a Pose2 ``(x, y, yaw)`` (GTSAM's ``Pose2(inc).inverse().AdjointMap()``):
    the Jacobian that carries a tangent-space covariance across a composed increment,
    ``P' = Ad(inc^-1) P Ad(inc^-1)^T + Q``."""
    x, y, th = np.asarray(inc, dtype=float)
    c, s = np.cos(th), np.sin(th)
    rt = np.array([[c, s], [-s, c]])
    ti = -rt @ np.array([x, y])
    a = np.eye(3)
    a[:2, :2] = rt
    a[:2, 2] = [ti[1], -ti[0]]
    return a


def accumulate(increments: ArrayLike, start: ArrayLike = (0.0, 0.0, 0.0)) -> NDArray[np.float64]:
    """Chain relative poses: returns (N+1, 3) absolute poses starting at ``start``."""
    inc = np.asarray(increments, dtype=float).reshape(-1, 3)
    out = np.empty((len(inc) + 1, 3))
    out[0] = start
    for i, d in enumerate(inc):
        out[i + 1] = se2_compose(out[i], d)
    return out


# -- odometry (SOG + ROT) increments with their covariance
#
# The beacon paper's unicycle motion model (eq. 3) integrated exactly over each odometry interval
# (zero-order hold of the latest sample: an arc of constant ``v``, ``w``;
# :func:`factors.between.odometry_increment`), the arcs composed with first-order covariance
# propagation ``P' = Ad(inc^-1) P Ad(inc^-1)^T + Q`` in GTSAM's Pose2 tangent convention (the
# same model as the smoother's odometry factors). The samples come from
# :func:`graphnav.log.odometry_samples`.


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
    :func:`graphnav.log.odometry_samples`), and its covariance; ``None`` when no sample is at or
    before ``t1`` or ``t1 < t0``. Before the first sample the first one is held.

    The sigmas are per sample (each sample's error independent). An optional sixth column marks
    rows whose sigmas are noise densities [per sqrt(s)] instead: over an arc of ``dt`` they count
    as ``sigma / sqrt(dt)``, so the integrated variance is ``sigma^2 dt`` whatever the sample rate."""
    if len(samples) == 0 or t1 < t0 or samples[0, 0] > t1:
        return None
    i = max(int(np.searchsorted(samples[:, 0], t0, side="right")) - 1, 0)
    pose, cov = np.zeros(3), np.zeros((3, 3))
    t = t0
    while t < t1 - 1e-12:
        t_next = samples[i + 1, 0] if i + 1 < len(samples) else math.inf
        te = min(t_next, t1)
        _, v, w, sv, sw = samples[i, :5]
        if samples.shape[1] > 5 and samples[i, 5] and te - t > 0:
            sv, sw = sv / math.sqrt(te - t), sw / math.sqrt(te - t)
        d, q = arc(v, w, te - t, sv, sw, lateral)
        a = se2_adjoint_inv(d)
        cov = a @ cov @ a.T + q
        pose = se2_compose(pose, d)
        t = te
        if te >= t_next:
            i += 1
    return pose, cov
