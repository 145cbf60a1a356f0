"""The covariance of a scan match, derived from the match itself (the one place it is computed).

The matcher (:mod:`graphnav.scan._icp_fast`, ``report_sums``) hands the sums over its final pairs to
:func:`from_sums`, which returns the covariance of the between factor
``BetweenFactorPose2(prev, cur, Pose2(*pose), Gaussian.Covariance(cov))`` and the
degeneracy analysis (:mod:`graphnav.scan.degeneracy`). The scan-to-map estimator uses the same
sandwich (:func:`sandwich`) for its registrations. No consumer scales it afterwards.

Model. Each pair ``i`` has a residual ``r_i`` (point-to-line: the distance along the target
line's normal, ``d = 1``; point-to-point: the 2D difference, ``d = 2``) with the Jacobian
``J_i = d r_i / d xi`` for the right perturbation ``pose ∘ Exp(xi)`` (GTSAM's ``Pose2`` tangent
space, order x, y, theta). The error of a residual has two parts:

* **the LiDAR's noise**, ``k S_i``: ``S_i`` the pair's covariance from the range / beam-angle
  model (the weighted-ICP paper, eq. 5-8; identity for the unweighted variants), projected onto the
  residual, and ``k = sum r^T S^-1 r / (d n - 3)`` its scale estimated from the inlier residuals
  of this match (the residual variance factor of least squares);
* **what the scan cannot resolve**, ``(s_i^2 / 12) I_d``: returns are samples at the scan's
  angular step ``da``, so each stands for a stretch of surface ``s_i = r_i da`` wide (the spatial
  resolution at its range, :func:`resolution`), and structure finer than one sample — where along
  the surface the return fell, how the surface bends between two samples — is an error of up to
  half a sample either way. As uniform quantisation error it has the variance ``s^2 / 12``
  (Widrow & Kollar, *Quantization Noise*, 2008, ch. 4). It does not average out pair by pair: a
  target line is fitted to ``block`` neighbouring returns (``IcpConfig.normal_k``) and every
  source point matched onto that line shares its error, so the term enters with weight ``block``
  (a block of ``block`` fully correlated residuals; Bar-Shalom, Li & Kirubarajan, *Estimation
  with Applications to Tracking and Navigation*, 2001, sect. 3.7.4 for correlated measurement
  errors in least squares).

With the pair weights ``w_i`` of the matcher (the paper's ``G^-1/2`` and Huber, which are not
inverse variances) the covariance is the sandwich (Huber 1967; White 1980)::

    cov = H^-1 B H^-1,  H = sum w J^T J,  B = sum w^2 J^T (k S_i + block s_i^2 / 12 I) J

Measured against exact truth (the simulated harbour, ``benchmarks/icp_nees.py``) this is
consistent; the LiDAR term alone is 10-20x too confident in variance there and on every real log
(docs/weighted-icp.md, "Covariance").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import degeneracy

SAMPLING_VARIANCE = 1.0 / 12.0  # variance of a uniform error over one sample, in units of the sample width^2


def resolution(xy: NDArray[np.float64], half: int = 6) -> NDArray[np.float64]:
    """Spatial resolution of a scan at each of its points (sensor frame), ``r da`` [m]: the width of
    surface one return stands for, seen face-on. ``da`` is the scan's local angular step, the median
    of the ``2 half`` gaps between neighbouring bearings around the point (bearing order, circular):
    a LiDAR's beam spacing, robust to missing returns and to clouds that are not sampled evenly in
    angle."""
    n = len(xy)
    if n < 2:
        return np.zeros(n)
    a = np.arctan2(xy[:, 1], xy[:, 0])
    order = np.argsort(a, kind="stable")
    s = a[order]
    gaps = np.empty(n)
    gaps[:-1] = np.diff(s)
    gaps[-1] = s[0] + 2.0 * np.pi - s[-1]
    win = (np.arange(n)[:, None] + np.arange(-half, half)[None, :]) % n
    out = np.empty(n)
    out[order] = np.hypot(xy[order, 0], xy[order, 1]) * np.median(gaps[win], axis=1)
    return out


def sandwich(jac: NDArray, w: NDArray, err_cov: NDArray) -> NDArray[np.float64]:
    """``H^-1 B H^-1`` with ``H = sum w J^T J`` and ``B = sum w^2 J^T C J`` for Jacobians ``jac``
    (N, d, 3), weights ``w`` (N,) and residual error covariances ``err_cov`` (N, d, d); NaN when
    ``H`` is singular."""
    jw = jac * w[:, None, None]
    h = jw.reshape(-1, 3).T @ jac.reshape(-1, 3)
    if jac.shape[1] == 1:
        b = (jw[:, 0, :] * err_cov[:, 0, 0, None]).T @ jw[:, 0, :]
    else:
        b = jw.reshape(-1, 3).T @ np.matmul(err_cov, jw).reshape(-1, 3)
    try:
        hi = np.linalg.inv(h)
    except np.linalg.LinAlgError:
        return np.full((3, 3), np.nan)
    cov = hi @ b @ hi.T
    return 0.5 * (cov + cov.T)


@dataclass
class Between:
    """What :func:`from_sums` derives from a match."""

    cov: NDArray[np.float64]  # (3, 3) right-perturbation covariance, before any degeneracy inflation
    residual_scale: float  # k
    residual_rms: float  # weighted RMS of the residuals [m]
    inliers: int
    degeneracy: degeneracy.Degeneracy
    #: the geometry's own weak directions (without ``prior_cov``'s "known better" rule; ``degeneracy``
    #: itself when no ``prior_cov`` was given)
    geometry: degeneracy.Degeneracy


def from_sums(k: float, n_inl: int, h: NDArray, b_lidar: NDArray, b_sampling: NDArray, rms: float, info: NDArray,
              radius: float, *, max_condition: float, max_sigma: float,
              prior_cov: NDArray | None = None) -> Between:
    """The covariance ``H^-1 B H^-1`` of the module doc and the degeneracy analysis
    (:func:`graphnav.scan.degeneracy.analyse` of the point-to-line information ``info``), from the sums over
    the pairs accumulated in one pass by the matcher (:func:`graphnav.scan._icp_fast.report_sums`): ``H = sum
    w J^T J``, ``B = k b_lidar + b_sampling`` (``b_lidar = sum w^2 J^T S J``, ``b_sampling = sum w^2 (block
    s^2 / 12) J^T J``), ``k = sum r^T S^-1 r / (d n_inl - 3)`` over the inlier pairs."""
    cov = np.full((3, 3), np.nan)
    if np.isfinite(k):
        try:
            hi = np.linalg.inv(h)
        except np.linalg.LinAlgError:
            hi = None
        if hi is not None:
            cov = hi @ (k * b_lidar + b_sampling) @ hi.T
            cov = 0.5 * (cov + cov.T)
    deg, geo = degeneracy.analyse_both(info, radius, cov, max_condition=max_condition, max_sigma=max_sigma,
                                       prior_cov=prior_cov)
    return Between(cov, k, rms, n_inl, deg, geo)


def from_kernel(k: float, n_inl: int, rms: float, radius: float, algebra: tuple,
                prior_cov: NDArray | None = None) -> Between:
    """:func:`from_sums`, from the matcher's own evaluation of it (:func:`graphnav.scan._icp_fast.report_algebra`:
    ``(cov, var, sigmas, vectors, weak, condition, ...)``, the geometry's weak directions) and the guess's
    ``prior_cov`` (:func:`graphnav.scan.degeneracy.with_prior`)."""
    cov, var, sig, vec, weak, cond = algebra[:6]
    geo = degeneracy.Degeneracy(float(cond), sig, vec, weak, float(radius))
    return Between(cov, k, rms, n_inl, degeneracy.with_prior(geo, var, prior_cov), geo)
