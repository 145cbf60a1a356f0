"""Degeneracy of a 2D registration by eigen-analysis of its point-to-line information.

A match constrains the pose only across the lines (walls) it sees: each pair contributes
``j = n^T [R, J (p - t)]`` (Censi's point-to-line Jacobian with respect to the right perturbation
``pose ∘ Exp(xi)``, GTSAM's Pose2 tangent space, order x, y, theta), with the rotation column
divided by the source cloud's RMS radius ``L`` so that all three coordinates are metres and the
eigenvalues are comparable (unit-free condition number). ``info = sum f j j^T`` (``f`` the line's
flatness) says which directions the geometry constrains; the match's covariance
(:mod:`graphnav.scan.covariance`) says how well: an eigenvector ``v_i`` of ``info`` is *weak* when
the covariance's 1-sigma along it exceeds ``max_sigma`` or when ``lambda_max / lambda_i >
max_condition`` (a single straight quay, a corridor, nearly empty water).

Pure numerics; used by :mod:`graphnav.scan.covariance` (every ICP match) and the scan-to-map estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..geometry import se2_between, se2_compose
from ._kdtree import cKDTree


@dataclass
class Degeneracy:
    """Eigen-analysis of a point-to-line information matrix (scaled coordinates x, y, L theta).

    ``weak`` marks the eigenvectors (columns of ``vectors``) that the geometry does not constrain.
    """

    condition: float
    sigmas: NDArray[np.float64]  # predicted 1-sigma along each eigenvector [m], ascending eigenvalues
    vectors: NDArray[np.float64]  # (3, 3) unit eigenvectors as columns, scaled coordinates
    weak: NDArray[np.bool_]
    radius: float  # L [m]
    _proj: NDArray[np.float64] | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def degenerate(self) -> bool:
        return bool(self.weak.any())

    @property
    def sigma_weak(self) -> float:
        """Predicted 1-sigma along the weakest direction [m]."""
        return float(self.sigmas[0])

    @property
    def weakest(self) -> NDArray[np.float64]:
        """The weakest direction as a tangent vector ``(x, y, theta)`` (x, y unit-free share, theta
        in rad per metre of the scaled vector)."""
        return self.vectors[:, 0] * np.array([1.0, 1.0, 1.0 / self.radius])

    def projector(self) -> NDArray[np.float64]:
        """``P`` (3, 3) in unscaled tangent coordinates: ``P xi`` is the part of ``xi`` along the
        weak directions."""
        if self._proj is None:  # (asked up to five times per match: computed once, handed out as copies)
            v = self.vectors[:, self.weak]
            s = np.diag([1.0, 1.0, 1.0 / self.radius])
            self._proj = s @ v @ v.T @ np.linalg.inv(s)
        return self._proj.copy()

    def inflation(self, sigma: float) -> NDArray[np.float64]:
        """Covariance (3, 3, unscaled tangent coordinates) of 1-sigma ``sigma`` [m] along every weak
        direction (rotation: ``sigma / L`` rad)."""
        v = self.vectors[:, self.weak] * np.array([1.0, 1.0, 1.0 / self.radius])[:, None]
        return sigma**2 * v @ v.T


def rms_radius(xy: NDArray[np.float64]) -> float:
    """RMS distance of the points from their centroid (1.0 for an empty or single-point cloud)."""
    if len(xy) < 2:
        return 1.0
    return float(np.sqrt(np.mean(np.sum((xy - xy.mean(0)) ** 2, 1)))) or 1.0


def line_rows(p: NDArray[np.float64], t: NDArray[np.float64], rot: NDArray[np.float64],
              normals: NDArray[np.float64], radius: float) -> NDArray[np.float64]:
    """Point-to-line Jacobian rows ``n^T [R, J (p - t)]`` (N, 3) of target-frame points ``p`` of a
    source at ``(t, rot)`` against target normals, rotation column divided by ``radius``."""
    jp = p - t
    rows = np.empty((len(p), 3))
    rows[:, :2] = normals @ rot
    rows[:, 2] = (normals[:, 1] * jp[:, 0] - normals[:, 0] * jp[:, 1]) / radius
    return rows


def analyse(info: NDArray[np.float64], radius: float, cov: NDArray[np.float64], *,
            max_condition: float = 200.0, max_sigma: float = np.inf,
            prior_cov: NDArray[np.float64] | None = None) -> Degeneracy:
    """Weak directions of ``info`` (3, 3, scaled coordinates x, y, ``radius`` theta) given the
    match's covariance ``cov`` (3, 3, unscaled tangent coordinates; non-finite: every direction
    is weak): the 1-sigma along each eigenvector is ``sqrt(v^T T cov T v)``, ``T = diag(1, 1, L)``.
    With ``prior_cov`` (the initial guess's covariance, same convention) a direction is also weak
    where the match knows it less well than the guess does."""
    return analyse_both(info, radius, cov, max_condition=max_condition, max_sigma=max_sigma,
                        prior_cov=prior_cov)[0]


def analyse_both(info: NDArray[np.float64], radius: float, cov: NDArray[np.float64], *,
                 max_condition: float = 200.0, max_sigma: float = np.inf,
                 prior_cov: NDArray[np.float64] | None = None) -> tuple[Degeneracy, Degeneracy]:
    """:func:`analyse` with ``prior_cov`` and without it (the geometry's own weak directions), from one
    eigen-decomposition of ``info``: the second is the first without the "known better" rule."""
    ev, vec = np.linalg.eigh(0.5 * (info + info.T))
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
    var = np.full(3, np.inf)
    finite = bool(np.isfinite(cov).all())
    tm = np.diag([1.0, 1.0, float(radius)])
    if finite:
        var = np.einsum("ji,jk,ki->i", vec, tm @ cov @ tm, vec)
    sig = np.sqrt(np.maximum(var, 0.0))
    weak = ~(ev > 0) | (ev * max_condition < ev[-1]) | (sig > max_sigma)
    if not finite:
        weak[:] = True
    geo = Degeneracy(cond, sig, vec, weak, float(radius))
    return with_prior(geo, var, prior_cov), geo


def with_prior(geo: Degeneracy, var: NDArray[np.float64], prior_cov: NDArray[np.float64] | None) -> Degeneracy:
    """``geo`` (the geometry's own weak directions) with the directions where the match knows less than its
    guess also weak: the match's variance ``var`` along each eigenvector (scaled coordinates; inf when its
    covariance is not finite) above the guess's ``prior_cov`` there. ``geo`` itself without a finite prior or
    with a non-finite ``var``."""
    if prior_cov is None or not np.isfinite(var).all() or not np.isfinite(prior_cov).all():
        return geo
    tm = np.diag([1.0, 1.0, geo.radius])
    known = var > np.einsum("ji,jk,ki->i", geo.vectors, tm @ np.asarray(prior_cov, dtype=float) @ tm, geo.vectors)
    return Degeneracy(geo.condition, geo.sigmas, geo.vectors, geo.weak | known, geo.radius)


def keep_constrained(pose: NDArray[np.float64], guess: NDArray[np.float64],
                     deg: Degeneracy) -> NDArray[np.float64]:
    """``pose`` with its component along the weak directions replaced by the ``guess``'s (first
    order in the tangent space of ``pose``): the geometry says nothing there, the guess does."""
    if not deg.weak.any():
        return pose
    xi = se2_between(pose, guess)
    return se2_compose(pose, deg.projector() @ xi)


@dataclass
class LinePairs:
    """Point-to-line pairs of a registered scan against target lines (:func:`line_information`)."""

    info: NDArray[np.float64]  # (3, 3) sum f j j^T, rotation scaled by ``radius``
    s2: float  # flatness-weighted residual variance along the normals [m^2] (NaN: too few pairs)
    radius: float  # L [m]
    rows: NDArray[np.float64]  # (N, 3) unscaled rows n^T [R, J (p - t)]
    res: NDArray[np.float64]  # (N,) residuals along the normals [m]
    flat: NDArray[np.float64]  # (N,) flatness of the target lines


def line_information(src_xy: NDArray[np.float64], pose: NDArray[np.float64], tgt_xy: NDArray[np.float64],
                     tgt_normals: NDArray[np.float64], tgt_flat: NDArray[np.float64], tree: cKDTree,
                     inlier_dist: float) -> LinePairs:
    """Point-to-line pairs of body-frame source points registered at ``pose`` against target points
    with normals and flatness (``tree``: a k-d tree of ``tgt_xy``): pairs with the nearest target
    point within ``inlier_dist``, weighted by flatness (NaN flatness counts as 0)."""
    radius = rms_radius(src_xy)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])
    p = src_xy @ rot.T + pose[:2]
    d, idx = tree.query(p, distance_upper_bound=inlier_dist)
    ok = np.isfinite(d)
    if not ok.any():
        return LinePairs(np.zeros((3, 3)), float("nan"), radius, np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    p, idx = p[ok], idx[ok]
    n = tgt_normals[idx]
    f = np.nan_to_num(tgt_flat[idx])
    rows = line_rows(p, pose[:2], rot, n, 1.0)
    scaled = rows * np.array([1.0, 1.0, 1.0 / radius])
    info = (scaled * f[:, None]).T @ scaled
    rn = np.einsum("ij,ij->i", p - tgt_xy[idx], n)
    return LinePairs(info, residual_var(p - tgt_xy[idx], n, f), radius, rows, rn, f)


def residual_var(e: NDArray[np.float64], normals: NDArray[np.float64], f: NDArray[np.float64]) -> float:
    """``s2``: the variance of the pair residuals ``e`` (N, 2) along the target ``normals``,
    weighted by ``f`` (flatness, 0 for pairs left out), 3 degrees of freedom taken (NaN when the
    weights sum to 3 or less)."""
    rn = np.einsum("ij,ij->i", e, normals)
    sf = float(f.sum())
    return float(np.sum(f * rn * rn) / (sf - 3.0)) if sf > 3.0 else float("nan")


def flatness(evals: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(l1 - l0) / (l1 + l0)`` of ascending 2D eigenvalues (N, 2): 1 on a line, 0 for a blob or
    undefined (NaN eigenvalues)."""
    tr = evals[:, 0] + evals[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = (evals[:, 1] - evals[:, 0]) / tr
    return np.where(np.isfinite(f) & (tr > 0), f, 0.0)
