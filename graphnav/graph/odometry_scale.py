"""The odometry's systematic error: a scale factor on its speed ``v`` and one on its turn rate ``w``,
estimated from the log in the closing step where the other sensors make them observable.

Wheel odometry with a wrong wheel radius or track, and commanded velocities (MRCLAM: the commanded
``w`` 7-13 %, ``v`` 5-10 % high against the motion capture), err by a factor, not by white noise: the
noise estimation (:mod:`graphnav.graph.noise`) then sees residuals correlated over the whole log and
a white-noise model cannot be honest about them. The textbook remedy (calibration of the odometry's
scale factors, e.g. Borenstein & Feng 1996; Kümmerle et al. 2011 as graph variables) estimates them
together with the trajectory. Here the two factors ``s = (s_v, s_w)`` are extra parameters of the
batch problem, solved by Gauss-Newton with the trajectory profiled out on GTSAM's linearised,
whitened system ``A dx + J ds = b`` (``J``: the odometry factors' whitened residuals' derivative
with respect to ``s``, by re-integrating each interval's samples with ``s_v v, s_w w``):

    ds = S^-1 (J^T b - J^T A N^-1 A^T b),     S = J^T J - J^T A N^-1 A^T J,     N = A^T A

(solved as the augmented normal equations); ``S^-1`` is ``s``'s covariance in the graph's own
weights. The odometry factors are rebuilt with the rescaled samples (their noise models kept) and
Levenberg-Marquardt re-solves; a few steps converge. A factor whose standard deviation is above
``max_sigma`` is not observable in this log (odometry alone, a robot that never turns) and stays 1.
No Python factor enters the solver: the scales are estimated between solves, outside the
incremental hot loop. Off by default (``-O odometry_scale=true``): on MRCLAM the scales come out as
the motion capture says but the smoothed track gets no more honest (docs/smoother.md, "MRCLAM").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .solver import LmSettings, levenberg_marquardt

Vec = NDArray[np.float64]
#: keyframe k's odometry interval: the samples ``t, v, w`` it was integrated from, ``t0``, ``t1``
Interval = tuple[Vec, float, float]

STEP_H = 1e-4  # finite-difference step of the scales
MAX_SIGMA = 0.05  # a scale with a larger standard deviation is not observable in the log: left at 1
BOUNDS = (0.5, 2.0)  # a factor outside is no calibration error but a wrong unit or a broken log


def mean_increment(samples: Vec, t0: float, t1: float, sv: float = 1.0, sw: float = 1.0) -> Vec:
    """The pose ``(x, y, yaw)`` at ``t1`` in the frame of ``t0`` from the samples ``t, v, w`` with
    ``v`` times ``sv`` and ``w`` times ``sw``: the mean of :func:`graphnav.geometry.increment` (each
    sample held until the next, each piece an exact arc), vectorised."""
    ts = samples[:, 0]
    inner = ts[(ts > t0) & (ts < t1)]
    bounds = np.concatenate([[t0], inner, [t1]])
    dt = np.diff(bounds)
    idx = np.clip(np.searchsorted(ts, bounds[:-1], side="right") - 1, 0, None)
    v, w = sv * samples[idx, 1], sw * samples[idx, 2]
    th = w * dt
    small = np.abs(th) < 1e-6
    safe = np.where(small, 1.0, th)
    x = v * dt * np.where(small, 1.0 - th * th / 6.0, np.sin(safe) / safe)
    y = v * dt * np.where(small, th / 2.0, (1.0 - np.cos(safe)) / safe)
    h = np.concatenate([[0.0], np.cumsum(th)[:-1]])
    c, s = np.cos(h), np.sin(h)
    yaw = float(np.sum(th))
    return np.array([float(np.sum(c * x - s * y)), float(np.sum(s * x + c * y)),
                     math.atan2(math.sin(yaw), math.cos(yaw))])


def _rebuilt(f: gtsam.NonlinearFactor, space: Any, iv: Interval, s: Vec) -> gtsam.NonlinearFactor:
    """Odometry factor ``f`` with its interval re-integrated at scales ``s``, its noise model kept."""
    keys = f.keys()
    new = space.between(keys[0], keys[1], mean_increment(iv[0], iv[1], iv[2], s[0], s[1]), np.eye(3))
    return new.cloneWithNewNoiseModel(f.noiseModel())


def _system(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> tuple[sp.csr_matrix, Vec, Vec]:
    """GTSAM's linearised, whitened ``A``, ``b`` and the first row of every factor."""
    lin = graph.linearize(values)
    sj = np.asarray(lin.sparseJacobian_())
    rows, cols, vals = sj[0].astype(np.int64) - 1, sj[1].astype(np.int64) - 1, sj[2]
    # the last column is b, absent (all zero) at an exact solution: the variables' total dimension when the
    # values are the graph's, else the largest column
    n_cols = int(values.dim()) if values.size() == graph.keys().size() else (int(cols.max()) if cols.size else 0)
    is_b = cols == n_cols
    starts = np.concatenate([[0], np.cumsum([graph.at(i).dim() for i in range(graph.size())])]).astype(np.int64)
    m = int(starts[-1])
    b = np.zeros(m)
    b[rows[is_b]] = vals[is_b]
    A = sp.csr_matrix((vals[~is_b], (rows[~is_b], cols[~is_b])), shape=(m, n_cols))
    return A, b, starts


def gauss_newton_step(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, odo: dict[int, Interval],
                      space: Any, s: Vec, free: Sequence[int]) -> tuple[Vec, Vec]:
    """The profiled Gauss-Newton step of the scales ``free`` (0: ``s_v``, 1: ``s_w``) and their
    covariance ``S^-1`` (module docstring); ``odo``: factor index -> its interval."""
    import scipy.sparse.linalg as spla  # (here: a run that estimates no odometry scale never imports it)

    A, b, starts = _system(graph, values)
    J = np.zeros((A.shape[0], len(free)))
    for i, iv in odo.items():
        f = graph.at(i)
        b0 = f.linearize(values).jacobian()[1]
        for c, j in enumerate(free):
            sh = s.copy()
            sh[j] += STEP_H
            bh = _rebuilt(f, space, iv, sh).linearize(values).jacobian()[1]
            J[starts[i]:starts[i] + len(b0), c] = -(bh - b0) / STEP_H
    # the augmented normal equations [[N, A^T J], [J^T A, J^T J]] [dx; ds] = [A^T b; J^T b]: their inverse's
    # last block is S^-1; where the log does not observe s it is singular, and the tiny ridge makes it huge
    Js = sp.csr_matrix(J)
    M = sp.bmat([[A.T @ A, A.T @ Js], [Js.T @ A, Js.T @ Js]]).tocsc()
    n, q = A.shape[1], len(free)
    ridge = 1e-12 * max(1.0, float(M.diagonal().max()))
    try:
        lu = spla.splu(M + sp.identity(n + q, format="csc") * ridge, permc_spec="COLAMD")
    except RuntimeError:  # exactly singular
        return np.zeros(q), np.diag(np.full(q, np.inf))
    rhs = np.zeros((n + q, q + 1))
    rhs[n:, :q] = np.eye(q)
    rhs[:, q] = np.concatenate([A.T @ b, J.T @ b])
    X = lu.solve(rhs)
    cov = X[n:, :q]
    return X[n:, q], 0.5 * (cov + cov.T)


def estimate(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
             intervals: dict[tuple[int, int], Interval], space: Any, lm: LmSettings | None,
             *, iterations: int = 5, tol: float = 1e-4, max_sigma: float = MAX_SIGMA,
             ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, dict[str, Any] | None]:
    """The odometry's scale factors (module docstring): the graph with its odometry factors rescaled,
    its solution, and the report (``None`` without odometry intervals): ``v``, ``w`` (1 where not
    observable), their standard deviations ``sigma_v``, ``sigma_w`` and the Gauss-Newton ``steps``."""
    odo: dict[int, Interval] = {}
    for i, g in enumerate(groups):
        if g == "odometry":
            iv = intervals.get(tuple(graph.at(i).keys()))
            if iv is not None:
                odo[i] = iv
    if not odo:
        return graph, values, None
    s = np.ones(2)
    free = [0, 1]
    sig = np.full(2, np.inf)
    steps = 0
    for _ in range(iterations):
        ds, cov = gauss_newton_step(graph, values, odo, space, s, free)
        sd = dict(zip(free, np.sqrt(np.clip(np.diag(cov), 0.0, None)), strict=True))
        for j in free:
            sig[j] = float(sd[j])
        loose = [j for j in free if not sd[j] <= max_sigma]
        if loose:  # not observable: left where it is, the others estimated alone
            free = [j for j in free if j not in loose]
            if not free:
                break
            continue
        new_s = s.copy()
        new_s[free] = np.clip(s[free] + ds, *BOUNDS)
        done = float(np.max(np.abs(new_s - s))) < tol
        s = new_s
        new = gtsam.NonlinearFactorGraph()
        for i in range(graph.size()):
            new.add(_rebuilt(graph.at(i), space, odo[i], s) if i in odo else graph.at(i))
        graph = new
        values, _ = levenberg_marquardt(graph, values, lm)
        steps += 1
        if done:
            break
    return graph, values, {"v": float(s[0]), "w": float(s[1]), "sigma_v": _finite(sig[0]), "sigma_w": _finite(sig[1]),
                           "steps": steps, "factors": len(odo)}


def _finite(x: float) -> float | None:
    """``x``, or ``None`` where it was never estimated (JSON has no infinity)."""
    return float(x) if math.isfinite(x) else None
