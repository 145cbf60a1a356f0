"""How far a log's fixes wander from its own velocity: the position random walk of the vessel model,
estimated from the log.

A receiver's fixes and its speed and course over ground (or a speed log) are two views of one track,
and the vessel graph (``motion="vessel"``) joins them through the integrated velocity. Over a lag
``tau`` the difference between a pair of fixes and the velocity integrated between them,

    r = (p_j - p_i) - integral_{t_i}^{t_j} v dt,

has, per axis, ``E[r^2] = a + q tau``: ``a`` the fixes' white noise (both ends; whatever their stated
sigma) and ``q`` [m^2/s] whatever random walk separates the positions from the integrated velocity -- the
velocity's own errors and a receiver's position wandering (multipath, satellites coming and going).
The vessel model's integration noise was 1 mm/sqrt(s): a real boat's fixes
(psaros33-20140805-0020) wander from its SOG/COG by 0.44 m/sqrt(s), and the graph, trusting the
velocity, was over-confident (NEES 11-13 against the fixes; 1.5-2.0 with the estimate: docs/smoother.md,
"Where the NEES came from").

:func:`position_walk` fits ``a`` and ``q`` (non-negative least squares, each lag's variance a robust
median estimate: a jump of the fixes is a few pairs' outlier) to pairs of fixes at lags
:data:`LAGS`; ``q`` less the velocity records' own stated white noise (``sigma_v^2 dt`` per axis) is
the vessel model's position random walk (:class:`~graphnav.graph.imu_chain.ImuConfig`
``vessel_position_walk``). Only where the log has GNSS fixes and GNSS velocity records.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..log import NavLog, Record
from .chi2 import chi2_median

#: [s] the lags of the pairs of fixes: up to a minute (beyond it a velocity bias, not a walk, dominates)
LAGS = (1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 18.0, 25.0, 35.0, 45.0, 60.0)
MIN_PAIRS = 30  # pairs of a lag needed to use it
MAX_VELOCITY_GAP = 3.0  # [s] a pair is used only where the velocity records are at most this far apart
_MEDIAN_CHI2_1 = float(chi2_median(np.array([1.0]))[0])


def _integrated(tv: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """The velocity integrated (trapezoid) from ``tv[0]`` to each ``tv``."""
    steps = 0.5 * (v[1:] + v[:-1]) * np.diff(tv)[:, None]
    return np.vstack([np.zeros((1, v.shape[1])), np.cumsum(steps, axis=0)])


def lag_variances(tf: NDArray[np.float64], pf: NDArray[np.float64], tv: NDArray[np.float64],
                  v: NDArray[np.float64]) -> list[tuple[float, float, int]]:
    """Per lag of :data:`LAGS`: ``(lag, variance per axis, pairs)`` of ``r`` (module docstring), the
    variance a median estimate; fixes ``(tf, pf)``, velocities ``(tv, v)`` (times sorted)."""
    inside = (tf >= tv[0]) & (tf <= tv[-1])
    tf, pf = tf[inside], pf[inside]
    if len(tf) < 2:
        return []
    cum = _integrated(tv, v)
    D = np.c_[np.interp(tf, tv, cum[:, 0]), np.interp(tf, tv, cum[:, 1])]
    gaps = np.diff(tv) > MAX_VELOCITY_GAP  # a pair across a velocity gap is not used
    n_gaps = np.concatenate([[0], np.cumsum(gaps)])
    seg = n_gaps[np.clip(np.searchsorted(tv, tf, side="right") - 1, 0, len(tv) - 1)]
    out = []
    for lag in LAGS:
        j = np.searchsorted(tf, tf + lag)
        ok = j < len(tf)
        i = np.flatnonzero(ok)
        j = j[ok]
        keep = (np.abs(tf[j] - tf[i] - lag) <= 0.25 * lag + 1e-9) & (seg[i] == seg[j])
        i, j = i[keep], j[keep]
        if len(i) < MIN_PAIRS:
            continue
        r = (pf[j] - pf[i]) - (D[j] - D[i])
        out.append((lag, float(np.median(r.ravel() ** 2)) / _MEDIAN_CHI2_1, len(i)))
    return out


def fit_walk(rows: list[tuple[float, float, int]]) -> tuple[float, float] | None:
    """``(a, q)`` of ``variance = a + q lag`` (non-negative least squares, each lag weighted by the
    inverse standard deviation of its variance estimate, ``~ variance sqrt(2 / pairs)``)."""
    if len(rows) < 3:
        return None
    lag, var, n = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    w = np.sqrt(n / 2.0) / np.maximum(var, 1e-12)
    sol = nnls2(np.c_[np.ones_like(lag), lag] * w[:, None], var * w)
    return float(sol[0]), float(sol[1])


def nnls2(A: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``argmin |A x - b|`` over ``x >= 0`` for two columns (``scipy.optimize.nnls``'s answer to rounding,
    without importing ``scipy.optimize``, ~0.1 s): the least-squares solution when it is non-negative, else
    the better of the two one-column solutions clipped at 0 (the problem is convex: its minimum on the
    boundary is one of them). ``b`` is scaled to a unit maximum first (the costs compared are squares)."""
    s = float(np.abs(b).max()) if b.size else 0.0
    if s == 0.0 or not np.isfinite(s):
        return np.zeros(2) if s == 0.0 else np.linalg.lstsq(A, b, rcond=None)[0]
    return _nnls2(A, b / s) * s


def _nnls2(A: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    if (x >= 0.0).all():
        return x
    best, cost = np.zeros(2), float(b @ b)
    for j in range(2):
        a = A[:, j]
        aa = float(a @ a)
        if aa > 0.0:
            c = np.zeros(2)
            c[j] = max(float(a @ b) / aa, 0.0)
            r = A @ c - b
            if float(r @ r) < cost:
                best, cost = c, float(r @ r)
    return best


def position_walk(log: NavLog) -> dict[str, Any] | None:
    """The vessel model's position random walk from ``log``'s fixes and GNSS velocity records
    (module docstring): ``{"walk": sqrt(q - sigma_v^2 dt) [m/sqrt(s)], "q", "a", "lags"}``, or
    ``None`` without enough of both."""
    fixes, vel = log.of("gnss"), log.of("gnss_velocity")
    if len(fixes) < 2 * MIN_PAIRS or len(vel) < 2 * MIN_PAIRS:
        return None
    tf = np.array([r.t for r in fixes])
    pf = np.array([[r.x, r.y] for r in fixes])
    tv = np.array([r.t for r in vel])
    v = np.array([[r.vx, r.vy] for r in vel])
    fo, vo = np.argsort(tf, kind="stable"), np.argsort(tv, kind="stable")
    rows = lag_variances(tf[fo], pf[fo], tv[vo], v[vo])
    fit = fit_walk(rows)
    if fit is None:
        return None
    a, q = fit
    sig = np.array([r.sigma for r in vel])
    dt = float(np.median(np.diff(tv[vo]))) if len(tv) > 1 else 1.0
    stated = float(np.median(sig[np.isfinite(sig)]) ** 2 * dt) if np.isfinite(sig).any() else 0.0
    return {"walk": math.sqrt(max(q - stated, 0.0)), "q": q, "a": a, "velocity_q": stated,
            "lags": [[lag, var, n] for lag, var, n in rows]}


#: [s] the vessel graph's position walk is estimated again this often (the longest lag of its fit)
WALK_EVERY_S = max(LAGS)
#: [s] ... from the fixes and GNSS velocities of this last stretch of stream (30 of its longest lags; memory bound)
WALK_WINDOW_S = 30 * max(LAGS)


class WalkTracker:
    """The vessel model's position random walk, estimated live (the graph's in live mode, the vessel EKF's
    online): :func:`position_walk` on the fixes and GNSS velocity records of the last :data:`WALK_WINDOW_S`,
    tried each time the stream's stretch has doubled, then every :data:`WALK_EVERY_S` of stream time
    (:func:`position_walk` gives nothing before it has enough pairs of fixes at three lags).
    ``add(rec)`` returns a new estimate when one was made."""

    def __init__(self) -> None:
        self.recs: deque[Record] = deque()
        self.t_first: float | None = None
        self.next_t = -math.inf
        self.updates = 0
        self.last: dict[str, Any] | None = None

    def add(self, rec: Record) -> dict[str, Any] | None:
        if rec.kind not in ("gnss", "gnss_velocity"):
            return None
        self.recs.append(rec)
        t = float(rec.t)
        while self.recs and self.recs[0].t < t - WALK_WINDOW_S:
            self.recs.popleft()
        if self.t_first is None:
            self.t_first = t
        if t < self.next_t:
            return None
        self.next_t = t + min(WALK_EVERY_S, max(t - self.t_first, 1.0))  # as the stretch doubles, then every 60 s
        walk = position_walk(NavLog.from_unsorted(self.recs))
        if walk is None:
            return None
        self.updates += 1
        self.last = {"walk": walk["walk"], "t": t, "window_s": t - float(self.recs[0].t), "updates": self.updates}
        return walk
