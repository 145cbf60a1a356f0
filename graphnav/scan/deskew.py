"""De-skewing a 2D LiDAR sweep with the body's twist (pure numpy).

A rotating LiDAR takes its beams one after the other over the sweep: at 10 Hz a 360-beam scan spans
0.1 s, and a boat turning at 10 deg/s turns 1 deg in it, so a straight quay wall comes out bent. The
time convention is ROS ``sensor_msgs/LaserScan``'s: the scan's stamp is the time of its **first**
beam, beam ``i`` is taken at ``stamp + i * time_increment`` (index order is time order); here
``time_increment = sweep_s / N`` for a scan of ``N`` beams (``meta["lidar"]["sweep_s"]``,
docs/log-format.md; 0: every beam at the stamp, which is what every log stated until now).

:func:`deskew` moves each beam's point from the sensor frame at its own time into the sensor frame at
the stamp, assuming a constant body twist ``(vx, vy, wz)`` (body frame: [m/s, m/s, rad/s]) over the
sweep: the pose at ``tau`` after the stamp is ``Exp(tau * xi)`` (the exact SE(2) exponential), and a
point ``q`` seen then is ``Exp(tau * xi) q`` at the stamp. :func:`skew` is its exact inverse (what a
sweeping sensor sees of points given at the stamp; the simulator and the tests use it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: below this |theta| [rad] the SE(2) exponential's sin(t)/t and (1 - cos t)/t use their Taylor series
_SMALL = 1e-4


def sweep_of(log: Any) -> float:
    """A log's stated LiDAR sweep [s] (``meta["lidar"]["sweep_s"]``; 0 when not stated or not a finite number)."""
    lidar = getattr(log, "meta", {}).get("lidar")
    try:
        s = float(lidar.get("sweep_s", 0.0)) if isinstance(lidar, dict) else 0.0
    except (TypeError, ValueError):
        return 0.0
    return s if np.isfinite(s) else 0.0


def beam_times(n: int, sweep_s: float) -> NDArray[np.float64]:
    """Each of ``n`` beams' time after the scan's stamp [s]: ``i * sweep_s / n`` (ROS ``time_increment``
    ``= sweep_s / n``; a negative ``sweep_s`` means the beams were taken in reverse index order, the stamp
    being the first beam's still)."""
    if n <= 0:
        return np.zeros(0)
    return np.arange(n, dtype=float) * (float(sweep_s) / n)


def _v_coeffs(theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``sin(theta)/theta`` and ``(1 - cos(theta))/theta`` (series near 0), elementwise."""
    small = np.abs(theta) < _SMALL
    safe = np.where(small, 1.0, theta)
    t2 = theta * theta
    a = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(safe) / safe)
    b = np.where(small, theta * (0.5 - t2 / 24.0 + t2 * t2 / 720.0), (1.0 - np.cos(safe)) / safe)
    return a, b


def se2_exp(twist: ArrayLike, tau: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``Exp(tau * xi)`` for a twist ``xi = (vx, vy, wz)`` and times ``tau`` (M,): translations ``x``,
    ``y`` (M,) and rotations ``theta`` (M,) of the exact SE(2) exponential (a circular arc)."""
    vx, vy, wz = (float(c) for c in np.asarray(twist, dtype=float).ravel()[:3])
    tau = np.asarray(tau, dtype=float)
    theta = wz * tau
    a, b = _v_coeffs(theta)
    ux, uy = vx * tau, vy * tau
    return a * ux - b * uy, b * ux + a * uy, theta


def se2_log(pose: ArrayLike) -> NDArray[np.float64]:
    """``Log`` of an SE(2) pose ``(x, y, theta)`` (theta in (-pi, pi]): the twist ``(vx, vy, wz)`` that
    reaches it in unit time (``Exp(Log(p)) = p``)."""
    x, y, th = (float(c) for c in np.asarray(pose, dtype=float).ravel()[:3])
    th = float(np.arctan2(np.sin(th), np.cos(th)))
    a, b = (float(v) for v in _v_coeffs(np.array(th)))
    d = a * a + b * b  # V = [[a, -b], [b, a]], V^-1 = [[a, b], [-b, a]] / d
    return np.array([(a * x + b * y) / d, (-b * x + a * y) / d, th])


def twist_of(rel: ArrayLike, dt: float) -> NDArray[np.float64]:
    """The constant body twist that moves by ``rel = (x, y, theta)`` in ``dt`` seconds: ``Log(rel) / dt``."""
    if not dt > 0.0:
        raise ValueError(f"dt must be > 0, got {dt}")
    return se2_log(rel) / dt


def deskew(points: ArrayLike, times: ArrayLike, twist: ArrayLike) -> NDArray[np.float64]:
    """Points (M, 2), each seen in the sensor frame at its own ``times`` (M,) [s after the stamp], expressed
    in the sensor frame at the stamp: ``Exp(t_i * xi) p_i`` for the constant twist ``xi = (vx, vy, wz)``."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    tx, ty, th = se2_exp(twist, times)
    c, s = np.cos(th), np.sin(th)
    return np.column_stack([c * p[:, 0] - s * p[:, 1] + tx, s * p[:, 0] + c * p[:, 1] + ty])


def skew(points: ArrayLike, times: ArrayLike, twist: ArrayLike) -> NDArray[np.float64]:
    """The inverse of :func:`deskew`: points (M, 2) given in the sensor frame at the stamp, each as the
    sensor sees it at its own ``times`` (M,): ``Exp(t_i * xi)^-1 p_i``."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    tx, ty, th = se2_exp(twist, times)
    c, s = np.cos(th), np.sin(th)
    dx, dy = p[:, 0] - tx, p[:, 1] - ty
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy])


def deskew_polar(ranges: ArrayLike, angles: ArrayLike, sweep_s: float, twist: ArrayLike,
                 times: ArrayLike | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A scan's beams (``ranges``, ``angles``, all N of them, in index order) de-skewed: the ranges and
    angles of the points in the sensor frame at the stamp. Beam ``i`` is at ``i * sweep_s / N`` unless the
    record gives per-beam ``times`` (N,). Missing returns (NaN, inf) stay missing; the caller's range
    gates apply to the raw ranges (:func:`deskew_mask_points`)."""
    r = np.asarray(ranges, dtype=float).ravel()
    a = np.asarray(angles, dtype=float).ravel()
    tau = beam_times(r.size, sweep_s) if times is None else np.asarray(times, dtype=float).ravel()
    if not (r.shape == a.shape == tau.shape):
        raise ValueError(f"ranges {r.shape}, angles {a.shape} and times {tau.shape} differ in length")
    with np.errstate(invalid="ignore"):
        q = deskew(np.column_stack([r * np.cos(a), r * np.sin(a)]), tau, twist)
    return np.hypot(q[:, 0], q[:, 1]), np.arctan2(q[:, 1], q[:, 0])


def deskew_mask_points(points: NDArray[np.float64], keep: NDArray[np.bool_], sweep_s: float,
                       twist: ArrayLike) -> NDArray[np.float64]:
    """The kept points of a scan (``points`` (M, 2) = its beams where ``keep`` (N,) holds, in index order)
    de-skewed with beam ``i`` of N at ``i * sweep_s / N``."""
    tau = beam_times(keep.size, sweep_s)[keep]
    return deskew(points, tau, twist)
