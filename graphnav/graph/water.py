"""Speed through water, the water current and the speed log's scale in the Pose3 graph.

A speed log measures the hull's speed through the water along its axis; over ground the boat moves at
that plus the water current. With ``k`` the log's scale (the true speed per unit of reading: a paddle
wheel under-reads as it fouls, an uncalibrated log is 5-30 % off -- ``graphnav info``'s ``speed_log``
check, :func:`graphnav.evaluation.datacheck.speed_log_scale`), a reading ``v`` at keyframe ``a`` is

    ``z = v (cos yaw, sin yaw, 0) = (V(a) - W(a)) / k + noise``,

``V`` the velocity over ground, ``W`` the current, ``yaw`` the bow's direction; along the bow the log's
sigma, across it the leeway. Linearised about a scale ``k0``, a reading ``m`` (a vector along the bow) and
the bow ``yaw0`` (``dyaw`` the keyframe's turn from it, ``perp`` the bow turned 90 deg left), times ``k0``:

    ``V - W - m k - k0 v perp dyaw + k0 (m - z) = 0``, covariance ``k0^2 diag(sv, lee, SURFACE_V)^2`` along the bow:

linear in ``(V, W, k)`` and the pose's yaw, a native ``JacobianFactor`` in a ``LinearContainerFactor`` (the pose
about a level ``yaw0``: under a heel ``phi`` and a trim ``theta`` its yaw column errs by ~``phi theta / 2``),
exact at ``k = k0``, ``yaw = yaw0``. The yaw column is what lets the readings turn the heading: without it
(the bow a constant of the factor, the estimate's as the record came) they said nothing on the heading, and
online the compass bias wandered where the bows it had made put it (a synthetic boat turning 3 deg/s with
a 0.5 deg compass: 4-10 deg RMS online; with the column 0.6 deg, ``tests/graph/test_water_speed_online.py``).
Its ``k`` column is ``m``, and ``m`` must carry none of the readings' noise. On a straight leg at one
speed the scale and the current along the track are one unknown; a noisy ``k`` column tells them apart
by chance, information from nothing. On 900 s of a straight leg with readings of 0.05 m/s noise
(tests/graph/test_speed_log_scale.py), against 1.008 the priors alone give: ``m = z`` (``V - W = k z``,
the reading a regressor) shrinks ``k`` to 0.10 while the current takes the boat's speed; ``m`` from the
solution's ``V - W`` gives 0.82, the mean of the other readings within 5 or 30 s 1.22 or 1.17, within
:data:`NEIGHBOURS_S` 1.025. So ``m`` is that mean (the earlier readings as a record comes; both sides in
the closing step, :class:`graphnav.graph.solution.Closing`, which re-makes the factors about the
solution's bows and scale until they settle), along the bow: the turns, which tell the scale from the
current, turn ``m`` with the bow. At the settled ``k0`` the linearisation's error ``(k - k0)(m -
m_true)`` vanishes. Without a scale state the reading is taken as true (``k = 1``, no ``k`` column).

The current is a random walk per keyframe; the scale one variable per ``water.scale_segment_s`` of
readings, consecutive ones tied by the random walk ``water.scale_rw`` (a log's calibration holds over a
voyage: the segments keep one variable out of every clique). On a straight leg at one speed the scale
and the current along the track are one unknown: the prior ``water.scale_sigma`` holds the scale there,
the turns tell them apart.

**A zero reading is censored.** A paddle wheel stops turning below its stall speed and the log reads zero:
psaros33's never reads between 0 and 1.0 kn (0.51 m/s; 22-40 % of its readings are zero, drifting in a
current or moored in one included). Taken as ``V - W = 0`` to the log's sigma, those readings tied the
current to the boat's velocity at a berth and whenever it drifted, and the current and the compass bias
then took the difference once it sailed (psaros33-0004's online track 20-60 m off its withheld fixes). So
a zero reading says only that the water passes the hull slower than the stall ``s`` (the option
``water.stall_speed``, else the smallest non-zero reading so far; before one, a zero says nothing and is not
used: :mod:`graphnav.graph.speed_log`, the filters' rule too): ``V - W = 0`` with ``s / sqrt(3)`` (a uniform
on ``(-s, s)``) added to both sigmas, without the scale (a reading of nothing has no scale), and out of the
other readings' means ``m``. A log that reads fine speeds (plaka: 0.005 m/s) is the plain factor again.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

from factors import X
from factors.imu import V

from ..log import WaterSpeed
from .smoother_config import SmootherConfig
from .space import K, W
from .speed_log import ZeroReadings
from .step import Step

SURFACE_V = 0.1  # [m/s] the vertical of a water-speed factor (no vertical water velocity)
NEIGHBOURS_S = 300.0  # [s] a reading's linearisation point: the mean of the others within this (module docstring)


@dataclass(frozen=True)
class WaterRow:
    """A speed-through-water reading at ``t`` on keyframe ``a``: speed ``v`` along the bow [m/s], its sigma
    ``sv`` and the sigma across the bow ``lee`` (leeway); ``scale``: the key of the log's scale variable
    (``None``: the reading is taken as true). Its factor (:meth:`factor`) is linearised about the bow
    ``yaw``, the reading ``m`` (along it; ``None``: ``v``) and the scale ``k0`` (the module docstring)."""

    t: float
    a: int
    v: float
    sv: float
    lee: float
    yaw: float  # [rad] the bow's direction the factor is made with
    scale: int | None = None
    m: float | None = None
    k0: float = 1.0
    censored: bool = False  # a zero reading: below the log's stall speed (module docstring)

    def factor(self) -> gtsam.NonlinearFactor:
        """The reading's factor about the row's bow (and, with a scale, ``m`` and ``k0``): linear in ``(V, W,
        k)`` and in the keyframe's yaw, whose column ``-k0 v perp`` (the model's derivative at the reading, across
        the bow) lets the readings turn the heading (module docstring)."""
        c, sn = math.cos(self.yaw), math.sin(self.yaw)
        rot = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        bow = np.array([c, sn, 0.0])
        z = self.v * bow
        if self.censored:  # no direction, no scale: V - W = 0 within the stall
            cov = rot @ np.diag([self.sv**2, self.lee**2, SURFACE_V**2]) @ rot.T
            return gtsam.BetweenFactorVector(W(self.a), V(self.a), z, gtsam.noiseModel.Gaussian.Covariance(cov))
        k0 = self.k0 if self.scale is not None else 1.0
        m = (self.v if self.m is None else self.m) * bow
        # rows along the bow, across it, vertical, whitened by k0 times the reading's sigmas
        root = np.diag([1.0 / self.sv, 1.0 / self.lee, 1.0 / SURFACE_V]) @ rot.T / k0
        b = (k0 * root @ (z - m) if self.scale is not None else root @ z).reshape(3, 1)
        yaw_col = np.zeros((1, 6))  # the Pose3 tangent's rotation about z: the yaw (level linearisation point)
        yaw_col[0, 2] = -self.v / self.lee  # the across row of -root k0 v perp (root carries 1 / k0)
        parts = gtsam.GaussianFactorGraph()
        rows = [0, 2]  # along and vertical: (V, W[, k]); the k column is m, along the bow
        if self.scale is not None:
            parts.add(gtsam.JacobianFactor(V(self.a), root[rows], W(self.a), -root[rows], self.scale,
                                           -(root[rows] @ m).reshape(2, 1), b[rows], gtsam.noiseModel.Unit.Create(2)))
        else:
            parts.add(gtsam.JacobianFactor(V(self.a), root[rows], W(self.a), -root[rows], b[rows],
                                           gtsam.noiseModel.Unit.Create(2)))
        parts.add(gtsam.JacobianFactor(V(self.a), root[[1]], W(self.a), -root[[1]], X(self.a), yaw_col, b[[1]],
                                       gtsam.noiseModel.Unit.Create(1)))
        at = gtsam.Values()  # (V, W, k) about zero: A x - b is the linearised residual at any of them
        at.insert(V(self.a), np.zeros(3))
        at.insert(W(self.a), np.zeros(3))
        at.insert(X(self.a), gtsam.Pose3(gtsam.Rot3.Yaw(self.yaw), gtsam.Point3(0.0, 0.0, 0.0)))
        if self.scale is not None:
            at.insert(self.scale, np.zeros(1))
        return gtsam.LinearContainerFactor(gtsam.JacobianFactor(parts), at)

    def about(self, yaw: float, values: gtsam.Values, m: float | None) -> tuple[WaterRow, float]:
        """The row about a solution's bow ``yaw``, its scale in ``values`` and the reading ``m``; with the
        change of the scale."""
        if self.scale is None:
            return replace(self, yaw=yaw), 0.0
        k0 = clamp_scale(float(values.atVector(self.scale)[0]))
        return replace(self, yaw=yaw, m=m, k0=k0), abs(k0 - self.k0)


def neighbours(rows: list[WaterRow]) -> list[float | None]:
    """Per row the mean of the other rows' readings within :data:`NEIGHBOURS_S` either side (``None``: none)."""
    order = np.argsort([r.t for r in rows], kind="stable")
    t, v = np.array([rows[i].t for i in order]), np.array([rows[i].v for i in order])
    used = np.array([not rows[i].censored for i in order], dtype=float)  # (a censored reading is no speed)
    c, cn = np.concatenate([[0.0], np.cumsum(v * used)]), np.concatenate([[0.0], np.cumsum(used)])
    lo, hi = np.searchsorted(t, t - NEIGHBOURS_S), np.searchsorted(t, t + NEIGHBOURS_S, side="right")
    n, total = cn[hi] - cn[lo] - used, c[hi] - c[lo] - v * used
    out: list[float | None] = [None] * len(rows)
    for j, i in enumerate(order):
        out[i] = float(total[j] / n[j]) if n[j] > 0 else None
    return out


def clamp_scale(k: float) -> float:
    """A scale estimate as a linearisation point: within [0.2, 5] (a log reading 5x off is broken)."""
    return min(max(k, 0.2), 5.0)


class Water:
    """The water-speed readings and the states they bring: the current ``W(j)`` from the first reading's
    keyframe on, the log's scale ``K(i)`` (:mod:`graphnav.graph.water`). ``kf_t``: the builder's keyframe
    times; ``log_yaw``: the speed log's mounting yaw [rad]."""

    def __init__(self, cfg: SmootherConfig, kf_t: list[float], defaulted: set[str], counts: dict[str, int],
                 log_yaw: float = 0.0) -> None:
        self.cfg, self.kf_t, self.defaulted, self.counts, self.log_yaw = cfg, kf_t, defaulted, counts, log_yaw
        #: the readings, in the order of their factors (the closing step re-aims them)
        self.rows: list[WaterRow] = []
        self.current: tuple[int, int] | None = None  # the current's W(j): (first, newest) keyframe
        self.current_guess = np.zeros(3)  # the newest estimate of it (the navigator keeps it up to date)
        self.scale_key: int | None = None  # the newest scale variable
        self.scale_guess = np.ones(1)
        self.scales: list[tuple[int, float]] = []  # (key, first reading's time) of each scale variable
        self.recent: deque[tuple[float, float]] = deque()  # the readings (t, v) of the last NEIGHBOURS_S
        self.recent_sum = 0.0
        self.zeros = ZeroReadings(cfg.water.stall_speed)  # a stalled log's zero readings (graph.speed_log)

    def reading(self, s: Step, a: int, yaw: float, r: WaterSpeed) -> None:
        """Speed through water ``r.v`` along the bow at keyframe ``a`` (``yaw``: its estimate). A log mounted
        at ``log_yaw`` from the bow reads ``v cos(log_yaw)`` of a flow along the bow: its reading is divided
        by that; its lever arm (``omega x r`` in a turn) is not modelled."""
        cfg = self.cfg.water
        if self.current is None:  # the first water speed starts the current: W(a) with its prior
            self.current = (a, a)
            s.values.insert(W(a), np.zeros(3))
            s.stamps[W(a)] = self.kf_t[a]
            sc = cfg.current_sigma
            s.add(gtsam.PriorFactorVector(W(a), np.zeros(3), gtsam.noiseModel.Diagonal.Sigmas(
                np.array([sc, sc, 1e-3]))), "current")
        if a < self.current[0]:
            self.counts["ignored"] += 1
            return
        sv = r.sigma_v if math.isfinite(r.sigma_v) else cfg.speed_sigma
        if not math.isfinite(r.sigma_v):
            self.defaulted.add("water_speed")
        v = r.v
        if self.log_yaw:
            v, sv = v / math.cos(self.log_yaw), sv / abs(math.cos(self.log_yaw))
        how = self.zeros.see(v)
        if how != "plain":
            if how == "censored":
                self._censored(s, a, sv, yaw, r.t)
            return
        while self.recent and r.t - self.recent[0][0] > NEIGHBOURS_S:
            self.recent_sum -= self.recent.popleft()[1]
        m = self.recent_sum / len(self.recent) if self.recent else None
        self.recent.append((r.t, v))
        self.recent_sum += v
        row = WaterRow(r.t, a, v, sv, cfg.leeway_sigma(v), yaw, self._scale(s), m,
                       clamp_scale(float(self.scale_guess[0])))
        self.rows.append(row)
        s.add(row.factor(), "water_speed")

    def _censored(self, s: Step, a: int, sv: float, yaw: float, t: float) -> None:
        """A zero reading at keyframe ``a``: ``V - W = 0`` within the stall speed (module docstring)."""
        along, across = self.zeros.sigmas(sv, self.cfg.water.leeway_sigma(0.0))
        row = WaterRow(t, a, 0.0, along, across, yaw, censored=True)
        self.rows.append(row)
        s.add(row.factor(), "water_speed")

    def _scale(self, s: Step) -> int | None:
        """The scale variable a reading at ``s.t`` takes: the first with its prior, a new one once the
        newest has taken ``scale_segment_s`` of readings (tied to it by the random walk ``scale_rw``)."""
        cfg = self.cfg.water
        if cfg.scale_sigma is None:
            return None
        seg = cfg.scale_segment_s
        if self.scale_key is not None and (seg is None or s.t - self.scales[-1][1] < seg):
            return self.scale_key
        new = K(len(self.scales))
        s.values.insert(new, self.scale_guess)
        s.stamps[new] = s.t
        if self.scale_key is None:
            s.add(gtsam.PriorFactorVector(new, np.ones(1), gtsam.noiseModel.Isotropic.Sigma(1, cfg.scale_sigma)),
                  "log_scale")
        else:
            sig = cfg.scale_rw * math.sqrt(max(s.t - self.scales[-1][1], 1e-9))
            s.add(gtsam.BetweenFactorVector(self.scale_key, new, np.zeros(1),
                                            gtsam.noiseModel.Isotropic.Sigma(1, sig)), "log_scale")
        self.scale_key = new
        self.scales.append((new, s.t))
        return new

    def step(self, s: Step, k: int) -> None:
        """The current's variables up to keyframe ``k`` -- a random walk ``current_rw`` between consecutive
        keyframes (a tidal current turns over hours) -- and the newest scale variable kept in use."""
        if self.scale_key is not None:
            s.stamps[self.scale_key] = s.t
        if self.current is None:
            return
        first, last = self.current
        for j in range(last + 1, k + 1):
            dt = max(self.kf_t[j] - self.kf_t[j - 1], 1e-9)
            sig = self.cfg.water.current_rw * math.sqrt(dt)
            s.values.insert(W(j), self.current_guess)
            s.stamps[W(j)] = self.kf_t[j]
            s.add(gtsam.BetweenFactorVector(W(j - 1), W(j), np.zeros(3), gtsam.noiseModel.Diagonal.Sigmas(
                np.array([sig, sig, 1e-3]))), "current")
        self.current = (first, max(last, k))

    def keys(self, k: int) -> list[int]:
        """The newest current (when it is keyframe ``k``'s) and scale variables: what a re-anchored
        smoother carries and what the navigator reads back as the next variables' guesses."""
        keys = [W(k)] if self.current is not None and self.current[1] == k else []
        return keys + ([self.scale_key] if self.scale_key is not None else [])

    def observe(self, key: int, value: NDArray[np.float64]) -> None:
        """The solver's newest estimate of one of :meth:`keys` (the next variables' initial value)."""
        if key == self.scale_key:
            self.scale_guess = value
        else:
            self.current_guess = value

    def report(self, values: gtsam.Values, t: NDArray[np.float64]) -> dict[str, Any]:
        """The current [m/s] (east, north) in a solution (keyframe times ``t``): at the end, its mean and its
        series (at most ~1000 samples); the speed log's scale at the end and each variable's (from its
        first reading's time)."""
        out: dict[str, Any] = {}
        out.update(self.zeros.info())
        ks = [(key, t0) for key, t0 in self.scales if values.exists(key)]
        if ks:
            out["log_scale_final"] = float(values.atVector(ks[-1][0])[0])  # (the filters' key)
            out["log_scale_series"] = [[t0, float(values.atVector(key)[0])] for key, t0 in ks]
        if self.current is None:
            return out
        js = [j for j in range(self.current[0], self.current[1] + 1) if values.exists(W(j))]
        ws = np.array([np.asarray(values.atVector(W(j)))[:2] for j in js]).reshape(-1, 2)
        if not len(js):
            return out
        every = max(1, len(js) // 1000)  # the series: at most ~1000 samples
        out["water_current"] = {"vx": float(ws[-1, 0]), "vy": float(ws[-1, 1]),
                                "mean_vx": float(ws[:, 0].mean()), "mean_vy": float(ws[:, 1].mean()),
                                "series": [[float(t[j]), float(w[0]), float(w[1])]
                                           for j, w in list(zip(js, ws, strict=True))[::every]]}
        return out
