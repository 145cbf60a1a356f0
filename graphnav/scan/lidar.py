"""2D LiDAR points and their error model (the weighted-ICP paper, section 2, eq. 5-10).

A return is ``(r, alpha)`` in the sensor frame (x forward, CCW angles). Its position error is an
ellipse with the long semi-axis ``a = sigma_alpha * r`` across the beam and the short semi-axis
``b = sigma_r`` along it (eq. 6-7); the Scanse Sweep figure is ``sigma_r = 0.004258 r``.
Pure numerics, no I/O.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..log import DEFAULT_MAX_RANGE

SIGMA_R_REL = 0.004258  # Scanse Sweep range error per metre of range (the paper, section 2)
SIGMA_ALPHA = np.radians(0.2)  # angular 1-sigma [rad]; the paper gives no figure (see docs/weighted-icp.md)


def polar_to_points(
    ranges: ArrayLike, angles: ArrayLike, *, min_range: float = 0.0, max_range: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Eq. 10: ``p = (r cos a, r sin a)`` for the valid returns.

    Missing returns (NaN, inf, ``<= 0``) are dropped, and so are ranges outside
    ``[min_range, max_range]`` (``max_range`` None: :data:`graphnav.log.DEFAULT_MAX_RANGE`, so no
    return is ever unbounded). Returns ``(points (N, 2), r (N,), alpha (N,))``.
    """
    r = np.asarray(ranges, dtype=float).ravel()
    a = np.asarray(angles, dtype=float).ravel()
    keep = valid_returns(r, a, min_range=min_range, max_range=max_range)
    r, a = r[keep], a[keep]
    return np.column_stack([r * np.cos(a), r * np.sin(a)]), r, a


def valid_returns(
    ranges: ArrayLike, angles: ArrayLike, *, min_range: float = 0.0, max_range: float | None = None
) -> NDArray[np.bool_]:
    """The beams :func:`polar_to_points` keeps: finite, ``> 0`` and within ``[min_range, max_range]``."""
    r = np.asarray(ranges, dtype=float).ravel()
    a = np.asarray(angles, dtype=float).ravel()
    if r.shape != a.shape:
        raise ValueError(f"ranges {r.shape} and angles {a.shape} differ in length")
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(r) & np.isfinite(a) & (r > 0.0) & (r >= min_range)
        keep &= r <= (DEFAULT_MAX_RANGE if max_range is None else max_range)
    return keep


def sigma_range(r: ArrayLike, sigma_r_rel: float = SIGMA_R_REL) -> NDArray[np.float64]:
    """Range 1-sigma ``sigma_r = sigma_r_rel * r`` (the Scanse Sweep model)."""
    return sigma_r_rel * np.asarray(r, dtype=float)


def ellipse_axes(
    r: ArrayLike, sigma_r_rel: float = SIGMA_R_REL, sigma_alpha: float = SIGMA_ALPHA
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eq. 6-7: semi-axes ``a = sigma_alpha r`` (across the beam), ``b = sigma_r`` (along it)."""
    r = np.asarray(r, dtype=float)
    return sigma_alpha * r, sigma_range(r, sigma_r_rel)


def mean_error(r: ArrayLike, sigma_r_rel: float = SIGMA_R_REL, sigma_alpha: float = SIGMA_ALPHA) -> NDArray:
    """Eq. 5: mean position error ``M = sqrt((sigma_alpha r)^2 + sigma_r^2)``."""
    a, b = ellipse_axes(r, sigma_r_rel, sigma_alpha)
    return np.sqrt(a * a + b * b)


def point_covariance(
    r: ArrayLike, alpha: ArrayLike, sigma_r_rel: float = SIGMA_R_REL, sigma_alpha: float = SIGMA_ALPHA
) -> NDArray[np.float64]:
    """Eq. 8: the (N, 2, 2) covariance of ``(x, y)``, with the ellipse's long axis at
    ``alpha_a = alpha + 90 deg`` (across the beam)."""
    a, b = ellipse_axes(r, sigma_r_rel, sigma_alpha)
    aa = np.asarray(alpha, dtype=float) + 0.5 * np.pi
    c, s = np.cos(aa), np.sin(aa)
    a2, b2 = a * a, b * b
    cov = np.empty(np.broadcast(a, aa).shape + (2, 2))
    cov[..., 0, 0] = a2 * c * c + b2 * s * s
    cov[..., 1, 1] = a2 * s * s + b2 * c * c
    cov[..., 0, 1] = cov[..., 1, 0] = (a2 - b2) * s * c
    return cov


def directional_error_sq(
    r: ArrayLike,
    alpha: ArrayLike,
    beta: ArrayLike,
    sigma_r_rel: float = SIGMA_R_REL,
    sigma_alpha: float = SIGMA_ALPHA,
) -> NDArray[np.float64]:
    """Eq. 9: ``sigma_beta^2 = S_beta cov S_beta^T`` with ``S_beta = [cos beta, sin beta]``.

    Evaluated in the closed form ``b^2 + (a^2 - b^2) sin^2(beta - alpha)`` (the printed
    expansion of eq. 9 has typos; this is ``S cov S^T`` of eq. 8 exactly, see tests).
    """
    a, b = ellipse_axes(r, sigma_r_rel, sigma_alpha)
    s = np.sin(np.asarray(beta, dtype=float) - np.asarray(alpha, dtype=float))
    return b * b + (a * a - b * b) * s * s


def directional_error_sq_vec(
    r: NDArray[np.float64],
    radial: NDArray[np.float64],
    direction: NDArray[np.float64],
    sigma_r_rel: float = SIGMA_R_REL,
    sigma_alpha: float = SIGMA_ALPHA,
) -> NDArray[np.float64]:
    """Eq. 9 for unit radial vectors ``radial`` (N, 2) and unit directions ``direction`` (N, 2)
    (no trigonometry: ``a^2 - (a^2 - b^2) (radial . direction)^2``). Used in the ICP hot loop."""
    a2 = (sigma_alpha * r) ** 2
    b2 = (sigma_r_rel * r) ** 2
    c = radial[:, 0] * direction[:, 0] + radial[:, 1] * direction[:, 1]
    return a2 - (a2 - b2) * c * c
