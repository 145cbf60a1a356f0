"""Noise the log does not give: a variance scale per sensor group, estimated from the residuals
of a batch solution (variance-component estimation, Förstner 1979; Koch, *Parameter Estimation
and Hypothesis Testing in Linear Models*, 1999, sec. 3.6.3).

For a Gauss-Markov model with groups of observations ``g`` whose covariances are known up to a
factor, ``Sigma_g = s_g Sigma_g0``, the iterated estimate is

    s_g <- s_g * (e_g^T W_g e_g) / r_g,        r_g = m_g - tr(A_g N^-1 A_g^T)

with ``e_g`` the residuals at the solution, ``W_g`` the current weights, ``m_g`` the group's
number of (effective) observations, ``A_g`` its whitened Jacobian rows and ``N = A^T A`` the
normal matrix of the whole problem: ``r_g`` is the group's redundancy (its share of the degrees of
freedom), so ``e^T W e / r`` is an unbiased variance factor. Each iteration rescales the group's
noise models by ``sqrt(s_g)`` and re-solves with Levenberg-Marquardt.

Here the linearised, whitened system comes from GTSAM (``linearize`` -> ``sparseJacobian_``; robust
kernels enter as their IRLS weights, so outliers count with the weight the solution gives them),
and the trace is estimated with Hutchinson's estimator (Rademacher probes, one sparse LU of
``N`` and one multi-column solve per iteration): the relative error of ``r_g`` is about
``sqrt(2 / (probes * tr))``, below 1 % for the hundreds of observations of a sensor group.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import gtsam
import numpy as np
import scipy.sparse as sp

from .builder import SCALABLE
from .solver import LmSettings, levenberg_marquardt

__all__ = ["SCALABLE", "estimate_scales", "gaussian", "group_statistics", "measured_residual", "scaled", "subgraph",
           "whitened_norm"]


def gaussian(f: gtsam.NonlinearFactor) -> gtsam.noiseModel.Base:
    """``f``'s noise model without its robust kernel (its Gaussian part)."""
    nm = f.noiseModel()
    return nm.noise() if hasattr(nm, "robust") else nm


def whitened_norm(f: gtsam.NonlinearFactor, values: gtsam.Values, *, robust: bool = True) -> float:
    """The factor's Mahalanobis residual norm (``robust=False``: of its Gaussian part)."""
    base = f.noiseModel() if robust else gaussian(f)
    e = f.unwhitenedError(values)
    return float(np.sqrt(base.squaredMahalanobisDistance(e)))


def subgraph(graph: gtsam.NonlinearFactorGraph, keep: Sequence[int]) -> gtsam.NonlinearFactorGraph:
    """The factors ``keep`` of ``graph``, in order."""
    out = gtsam.NonlinearFactorGraph()
    for i in keep:
        out.add(graph.at(i))
    return out


def scaled(f: gtsam.NonlinearFactor, s: float) -> gtsam.NonlinearFactor:
    """``f`` with its covariance multiplied by ``s`` (robust kernel kept)."""
    nm = f.noiseModel()
    robust = nm.robust() if hasattr(nm, "robust") else None
    base = nm.noise() if robust is not None else nm
    new = gtsam.noiseModel.Gaussian.SqrtInformation(np.asarray(base.R()) / np.sqrt(s))
    if robust is not None:
        new = gtsam.noiseModel.Robust.Create(robust, new)
    return f.cloneWithNewNoiseModel(new)


#: Pose3 rows (tangent order roll, pitch, yaw, x, y, z) that measure something, by group, where the factor
#: embeds a planar measurement in Pose3 (graphnav.graph.space): the rest are the graph's own pseudo-rows
#: (:data:`~graphnav.graph.space.LOOSE`, a compass's 1e-8 precisions) whose residuals are not sensor noise
PLANAR_ROWS = {"icp": [2, 3, 4], "odometry": [2, 3, 4], "motion": [2, 3, 4], "loop": [2, 3, 4], "compass": [2]}


def _measured(f: gtsam.NonlinearFactor, group: str, base: gtsam.noiseModel.Base | None = None) -> np.ndarray:
    """The rows of ``f`` that measure something (their residual is the sensor's noise): a GNSS fix's
    horizontal (its height is the sea surface's pseudo-measurement, z = 0), an embedded planar
    measurement's x, y, yaw (:data:`PLANAR_ROWS`), else every row with nonzero precision. ``base``:
    ``f``'s Gaussian noise model when the caller has it."""
    if base is None:
        base = gaussian(f)
    mask = (np.asarray(base.R()) != 0.0).any(axis=1)
    if isinstance(f, (gtsam.GPSFactor, gtsam.GPSFactorArm)):
        mask[2:] = False
    elif group in PLANAR_ROWS and isinstance(f, (gtsam.BetweenFactorPose3, gtsam.PriorFactorPose3)):
        keep = np.zeros_like(mask)
        keep[PLANAR_ROWS[group]] = True
        mask &= keep
    return mask


def measured_residual(f: gtsam.NonlinearFactor, values: gtsam.Values, group: str) -> np.ndarray:
    """``f``'s whitened residual (its Gaussian part, no robust weight) on the rows that measure
    something (:func:`_measured`)."""
    return _measured_rows(f, values, group)[1]


def _measured_rows(f: gtsam.NonlinearFactor, values: gtsam.Values, group: str) -> tuple[np.ndarray, np.ndarray]:
    """``f``'s rows that measure something (:func:`_measured`) and its whitened residual on them
    (:func:`measured_residual`)."""
    base = gaussian(f)
    mask = _measured(f, group, base)
    return mask, np.asarray(base.whiten(f.unwhitenedError(values)))[mask]


def group_statistics(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
                     which: Sequence[str], *, probes: int = 16, seed: int = 0) -> dict[str, dict[str, float]]:
    """Per group of ``which``: ``chi2`` (IRLS-weighted squared residuals), ``m`` (effective
    observations), ``redundancy`` (``m - tr(A_g N^-1 A_g^T)``, Hutchinson, on the IRLS-weighted
    Jacobian) and ``median_e2`` (median squared whitened residual, unweighted) at ``values``."""
    lin = graph.linearize(values)
    sj = np.asarray(lin.sparseJacobian_())
    rows, cols, vals = sj[0].astype(np.int64) - 1, sj[1].astype(np.int64) - 1, sj[2]
    # the last column is b (GTSAM's ordering of the graph's keys, then b); its index from the variables'
    # dimensions, not from the largest column present: at an exact solution b is all zero and absent
    n_cols = int(values.dim()) if lin.keys().size() == values.size() else (int(cols.max()) if cols.size else 0)
    is_b = cols == n_cols
    m_rows = int(rows.max()) + 1 if rows.size else 0
    b = np.zeros(m_rows)
    b[rows[is_b]] = vals[is_b]
    A = sp.csr_matrix((vals[~is_b], (rows[~is_b], cols[~is_b])), shape=(m_rows, n_cols))
    # rows of each factor: factors in order, each its noise model's dimension; each row's group as a code
    dims = [graph.at(i).dim() for i in range(graph.size())]
    starts = np.concatenate([[0], np.cumsum(dims)])
    code_of = {g: c for c, g in enumerate(dict.fromkeys(groups))}
    row_code = np.repeat(np.array([code_of[g] for g in groups], dtype=np.int64), dims)[:m_rows]
    measured = np.ones(int(starts[-1]), dtype=bool)  # rows of the groups asked about that measure something
    residuals: dict[str, list[np.ndarray]] = {g: [] for g in which}  # ... and their whitened residuals
    for i, g in enumerate(groups):
        if g in residuals:
            measured[starts[i]:starts[i + 1]], e = _measured_rows(graph.at(i), values, g)
            residuals[g].append(e)
    # zero-precision rows observe nothing; pseudo-rows (a fix's height, LOOSE) measure no sensor's noise
    active = (np.asarray(np.abs(A).sum(axis=1)).ravel() > 0) & measured[:m_rows]
    rows_of = {g: sel for g in which if (sel := np.flatnonzero((row_code == code_of.get(g, -1)) & active)).size}
    if not rows_of:  # none of the groups asked about has a row here: no factorisation
        return {}
    import scipy.sparse.linalg as spla  # (here: a run that scales no group never imports it, 0.01 s)

    N = (A.T @ A).tocsc()
    # N is symmetric positive definite: a symmetric ordering (minimum degree on N) and no pivoting. With
    # partial pivoting that ordering was lost and the factors filled 5x (psaros33 900 s: 1.75 s a factorisation);
    # COLAMD then took 0.13 s (2.7 M entries in L + U), this 0.09 s (1.0 M); a 5 Hz NMEA log's 18 000 columns
    # 0.20 -> 0.04 s (4.3 M -> 0.5 M). The trace estimate equal to 1e-11 relative, the residuals alike.
    lu = spla.splu(N + sp.identity(n_cols, format="csc") * 1e-12 * max(1.0, float(N.diagonal().max())),
                   permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    rng = np.random.default_rng(seed)
    out: dict[str, dict[str, float]] = {}
    for g, sel in rows_of.items():
        AZ = np.asarray(A[sel].T @ rng.choice([-1.0, 1.0], size=(sel.size, probes)))
        tr = float(np.einsum("ij,ij->", AZ, lu.solve(AZ))) / probes
        e = np.concatenate(residuals[g]) if residuals[g] else np.zeros(0)
        out[g] = {"chi2": float(b[sel] @ b[sel]), "m": float(sel.size), "redundancy": float(sel.size - tr),
                  "median_e2": float(np.median(e**2)) if e.size else float("nan")}
    return out


MEDIAN_CHI2_1 = 0.454936423119572  # median of a chi-square variable with one degree of freedom
#: the re-solves between two estimates stop at this relative decrease of the cost (the last solve, after the
#: final estimate, at the caller's tolerance): a median of squared residuals does not see the rest of a crawl
VCE_SOLVE_TOL = 1e-5


def estimate_scales(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
                    which: Sequence[str], iterations: int, lm: LmSettings | None = None,
                    *, robust: bool = True, min_redundancy: float = 5.0, bounds: tuple[float, float] = (1e-4, 1e4)
                    ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, dict[str, Any]]:
    """Iterated variance-component estimation (module docstring) for the groups ``which``;
    returns the rescaled graph, its solution and per group the total variance scale (the
    sigmas were multiplied by its square root), the last estimate and the redundancy.

    ``robust`` (default): the group's scale is ``median(e^2) / median(chi2_1) * m / r`` (the
    median squared whitened residual, each row's expectation ``s (1 - h_i)`` approximated by the
    group's mean ``s r / m``) instead of ``e^T W e / r``: real logs have outliers (MRCLAM's camera:
    1-2 % gross), which inflate the chi-square, and robust kernels, which deflate it."""
    if not which or iterations <= 0:  # nothing to scale (e.g. no group's sigmas defaulted): no statistics
        return graph, values, {}
    total = {g: 1.0 for g in which}
    report: dict[str, Any] = {}
    lm_vce = replace(lm, tol=max(lm.tol, VCE_SOLVE_TOL)) if lm else LmSettings(VCE_SOLVE_TOL, 100)
    for _ in range(max(iterations, 0)):
        stats = group_statistics(graph, values, groups, which)
        step = {}
        for g, st in stats.items():
            if st["redundancy"] < min_redundancy:
                continue
            if robust:
                est = st["median_e2"] / MEDIAN_CHI2_1 * st["m"] / st["redundancy"]
            else:
                est = st["chi2"] / st["redundancy"]
            s = float(np.clip(total[g] * est, *bounds)) / total[g]
            if abs(s - 1.0) > 0.02:
                step[g] = s
            report[g] = {"scale": total[g] * s, "sigma_factor": float(np.sqrt(total[g] * s)),
                         "last_estimate": est, "redundancy": st["redundancy"], "m": st["m"]}
        if not step:
            break
        new = gtsam.NonlinearFactorGraph()
        for i in range(graph.size()):
            f = graph.at(i)
            new.add(scaled(f, step[groups[i]]) if groups[i] in step else f)
        for g, s in step.items():
            total[g] *= s
        graph = new
        values, _ = levenberg_marquardt(graph, values, lm_vce)
    if report:
        values, _ = levenberg_marquardt(graph, values, lm)
    return graph, values, report
