"""Range-bearing EKF-SLAM of the beacon paper's sections 3-5 (Marchel, Naus & Specht 2019), and a
mode of it that holds on real beacon data.

State [x, y, theta, x_1, y_1, ..., x_i, y_i]; motion eq. 3 with control (V, ROT); G eq. 19;
W eq. 22 (second column dg/dROT); R = W M W^T eq. 20-23; range-bearing measurement eq. 6 with
Jacobian H eq. 25; one beacon per correction (K is (3+2i) x 2, eq. 24); P0 eq. 14 (zero vessel
block unless the log has a pose prior, beacon variances ``p0_beacon`` = 1e6 m^2). Charted beacons
(``beacon_known`` records) start at their charted position with their charted variance. The
correction uses the Joseph form, so P stays symmetric and positive semidefinite to round-off
(``tests/estimators/test_ekf_slam.py`` runs it for 10,000 steps).

:class:`EkfSlam`'s keyword defaults are the paper's filter (a slot per beacon from the start, the
first sighting corrected against the ``p0_beacon`` prior, no gate): it is the reference the batched
search (:mod:`graphnav.beacons.layout`) is tested against, so those defaults do not change. The
``ekf-slam`` estimator (:func:`run_ekf_slam`) defaults to the real-log mode (chi-square gate,
textbook first sighting, slots added when first seen, first-estimates Jacobians, sensor-type
default sigmas as noise densities, an innovation-based motion-noise scale); ``paper=True`` gives
the paper's filter. docs/ekf.md compares the two on MRCLAM.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import option
from ..geometry import wrap_angle
from ..graph.chi2 import chi2_ppf
from ..log import BeaconObs, NavLog, Odometry
from ..result import OnEstimate, RunResult
from ..trajectory import Trajectory
from .base import BatchEstimator

PAPER_SIGMAS = {                              # the paper's section 7, per record (white noise)
    "sigma_v": 0.5,                           # m/s
    "sigma_rot": math.radians(0.1),           # rad/s
    "sigma_range": 0.5,                       # m
    "sigma_bearing": math.radians(0.5),       # rad
}
SENSOR_DEFAULTS = {                           # real logs without sigmas (see run_ekf_slam, docs/ekf.md)
    "sigma_v": 0.1,                           # m/s over 1 s (density): wheel or speed-log odometry
    "sigma_rot": math.radians(5.0),           # rad/s over 1 s: odometry/commanded turn rate, slip
    "sigma_range": 0.5,                       # m: the paper's radar/LiDAR value, generous for a camera
    "sigma_bearing": math.radians(2.0),       # rad: camera or radar bearing
}
DEFAULT_GATE = 0.999


class EkfSlam:
    """Dense EKF-SLAM over beacon slots (``n_beacons`` at the start, more by :meth:`add_beacon`).

    The keyword defaults are the paper's filter, which :mod:`graphnav.beacons.layout` is tested
    against: ``init="paper"`` gives an unseen slot its mean from the inverse observation and then
    runs the ordinary correction against its ``p0_beacon`` prior. ``init="inverse"`` is the
    textbook first sighting instead (:meth:`initialise`): the slot takes the inverse observation
    and its covariance from the pose covariance and the measurement covariance, and that
    measurement is spent on it. ``p0_cross="paper"`` fills every entry outside the vessel block of
    P0 with ``p0_beacon`` as eq. 14 is printed (an indefinite matrix: for studying the paper only;
    such a filter cannot add slots later).
    """

    def __init__(self, pose0: NDArray[np.float64], n_beacons: int = 0, *, pose_cov0: NDArray | None = None,
                 p0_beacon: float = 1e6, p0_cross: str = "zero", w_second: str = "rot",
                 init: str = "paper", fej: bool = False) -> None:
        if init not in ("paper", "inverse"):
            raise ValueError(f"init must be 'paper' or 'inverse', not {init!r}")
        n = 3 + 2 * n_beacons
        self.x = np.zeros(n)
        self.x[:3] = pose0
        self.P = np.zeros((n, n))
        if p0_cross == "paper":
            self.P[:] = p0_beacon
            self.P[:3, :3] = 0.0
        else:
            self.P[3:, 3:] = np.eye(n - 3) * p0_beacon
        if pose_cov0 is not None:
            self.P[:3, :3] = pose_cov0
        self.seen = np.zeros(n_beacons, dtype=bool)
        self.p0_beacon, self.p0_cross, self.w_second, self.init = p0_beacon, p0_cross, w_second, init
        self.last_nis = math.nan  # normalised innovation squared of the last correction (gated or not)
        self.fej = fej
        self.pose_pred = self.x[:3].copy()   # the pose predicted for the current time, before its corrections
        self.first: dict[int, NDArray[np.float64]] = {}  # each beacon's first estimate (FEJ)

    @property
    def n(self) -> int:
        return len(self.x)

    def add_beacon(self) -> int:
        """A new slot (mean 0, variance ``p0_beacon``, uncorrelated, unseen); returns its index.

        With zero cross terms an unseen slot never interacts with the rest of the state, so adding
        it at first sighting gives the same filter as having it from the start."""
        if self.p0_cross == "paper":
            raise ValueError("p0_cross='paper' couples every slot from the start: give n_beacons instead")
        n = self.n
        x = np.zeros(n + 2)
        x[:n] = self.x
        P = np.zeros((n + 2, n + 2))
        P[:n, :n] = self.P
        P[n:, n:] = np.eye(2) * self.p0_beacon
        self.x, self.P = x, P
        self.seen = np.append(self.seen, False)
        return len(self.seen) - 1

    def forget(self, j: int) -> None:
        """Slot ``j`` back to unseen: mean 0, variance ``p0_beacon``, no correlation (its next
        sighting initialises it again)."""
        b = 3 + 2 * j
        self.x[b:b + 2] = 0.0
        self.P[b:b + 2, :] = 0.0
        self.P[:, b:b + 2] = 0.0
        self.P[b:b + 2, b:b + 2] = np.eye(2) * self.p0_beacon
        self.seen[j] = False
        self.first.pop(j, None)

    def set_beacon(self, j: int, xy: tuple[float, float], var: float) -> None:
        """A charted beacon: mean ``xy``, variance ``var`` per axis, uncorrelated."""
        b = 3 + 2 * j
        self.x[b:b + 2] = xy
        self.P[b:b + 2, :] = 0.0
        self.P[:, b:b + 2] = 0.0
        self.P[b:b + 2, b:b + 2] = np.eye(2) * var
        self.seen[j] = True
        self.first[j] = np.array(xy, dtype=float)

    def predict(self, v: float, rot: float, dt: float, sigma_v: float, sigma_rot: float) -> None:
        """Eq. 18 (mean) and eq. 19-23 (covariance).

        G (eq. 19) is the identity outside the vessel block, so ``G P G^T`` is computed as the
        vessel rows and columns times the 3x3 block of G (the same product, without the n^3).
        With ``fej`` (first-estimates Jacobian, Huang, Mourikis & Roumeliotis 2008) G's heading
        column is ``(-(y_k+1|k - y_k|k-1), x_k+1|k - x_k|k-1)``: the displacement from the pose
        predicted for time k, not the corrected one, so that every Jacobian of one pose is taken
        at one estimate (the EKF then gains no spurious heading information)."""
        th = self.x[2]
        c, s = math.cos(th), math.sin(th)
        g = np.eye(3)                                        # eq. 19, vessel block
        g[0, 2] = -s * dt * v
        g[1, 2] = c * dt * v
        if self.fej:
            g[0, 2] = -(self.x[1] + v * dt * s - self.pose_pred[1])
            g[1, 2] = self.x[0] + v * dt * c - self.pose_pred[0]
        W = np.zeros((3, 2))                                 # eq. 22, vessel rows (the rest is 0)
        W[0, 0], W[1, 0] = c * dt, s * dt
        if self.w_second == "rot":
            W[2, 1] = dt
        else:                                                # eq. 22 as printed: dg/dtheta
            W[0, 1], W[1, 1], W[2, 1] = g[0, 2], g[1, 2], 1.0
        M = np.diag([sigma_v**2, sigma_rot**2])              # eq. 17
        self.x[0] += v * dt * c
        self.x[1] += v * dt * s
        self.x[2] = wrap_angle(th + rot * dt)
        self.pose_pred = self.x[:3].copy()
        P = self.P                                           # eq. 23
        P[:3, :] = g @ P[:3, :]
        P[:, :3] = P[:, :3] @ g.T
        P[:3, :3] += W @ M @ W.T

    def inverse_observation(self, z_range: float, z_bearing: float) -> tuple[NDArray, NDArray, NDArray]:
        """Beacon position ``g(x, z) = (x + r cos(theta + beta), y + r sin(theta + beta))`` and its
        Jacobians ``Gx`` (2x3, w.r.t. the pose) and ``Gz`` (2x2, w.r.t. range and bearing)."""
        a = self.x[2] + z_bearing
        c, s = math.cos(a), math.sin(a)
        xy = np.array([self.x[0] + z_range * c, self.x[1] + z_range * s])
        gx = np.array([[1.0, 0.0, -z_range * s], [0.0, 1.0, z_range * c]])
        gz = np.array([[c, -z_range * s], [s, z_range * c]])
        return xy, gx, gz

    def initialise(self, j: int, z_range: float, z_bearing: float, sigma_range: float,
                   sigma_bearing: float) -> None:
        """Textbook first sighting of slot ``j``: ``x_b = g(x, z)``,
        ``P_bb = Gx Pxx Gx^T + Gz Q Gz^T``, ``P_b: = Gx P_x:`` (cross terms with the pose and
        every other slot)."""
        b = 3 + 2 * j
        xy, gx, gz = self.inverse_observation(z_range, z_bearing)
        Q = np.diag([sigma_range**2, sigma_bearing**2])
        self.x[b:b + 2] = xy
        cross = gx @ self.P[:3, :]                           # Gx P_x: (2 x n)
        cross[:, b:b + 2] = 0.0
        self.P[b:b + 2, :] = cross
        self.P[:, b:b + 2] = cross.T
        self.P[b:b + 2, b:b + 2] = gx @ self.P[:3, :3] @ gx.T + gz @ Q @ gz.T
        self.seen[j] = True
        self.first[j] = xy.copy()

    def update(self, j: int, z_range: float, z_bearing: float, sigma_range: float, sigma_bearing: float,
               gate: float | None = None, iterations: int = 1) -> bool:
        """Eq. 24-27 for beacon slot ``j`` (an unseen slot is first initialised, see ``init``).

        ``gate``: chi-square probability (e.g. 0.999) above which the innovation is rejected: the
        squared Mahalanobis distance ``nu^T S^-1 nu`` with ``S = H P H^T + Q`` against
        ``chi2.ppf(gate, 2)``. A first sighting cannot be gated (nothing predicts it). A return
        with a range that is not positive or a non-finite value is rejected. ``iterations`` > 1
        relinearises h at the updated estimate (iterated EKF, Bell & Cathey 1993:
        ``x_i+1 = x^- + K_i (z - h(x_i) - H_i (x^- - x_i))``), the gate uses the first. Returns
        whether the measurement was used.
        """
        if not (z_range > 0.0 and math.isfinite(z_range) and math.isfinite(z_bearing)):
            return False
        b = 3 + 2 * j
        if not self.seen[j]:
            if self.init == "inverse":
                self.initialise(j, z_range, z_bearing, sigma_range, sigma_bearing)
                self.last_nis = math.nan
                return True
            a = z_bearing + self.x[2]
            self.x[b] = self.x[0] + z_range * math.cos(a)
            self.x[b + 1] = self.x[1] + z_range * math.sin(a)
            self.first[j] = self.x[b:b + 2].copy()
        Q = np.diag([sigma_range**2, sigma_bearing**2])      # eq. 16
        x_prior = self.x
        xi = x_prior
        for it in range(max(1, iterations)):
            dx, dy = xi[b] - xi[0], xi[b + 1] - xi[1]
            q = dx * dx + dy * dy
            r = math.sqrt(q)
            if r == 0.0:
                return False
            nu = np.array([z_range - r, wrap_angle(z_bearing - (math.atan2(dy, dx) - xi[2]))])
            if self.fej and j in self.first:                 # H at the predicted pose and first beacon estimate
                dx, dy = self.first[j][0] - self.pose_pred[0], self.first[j][1] - self.pose_pred[1]
                q = dx * dx + dy * dy
                r = math.sqrt(q)
                if r == 0.0:
                    return False
            H = np.zeros((2, self.n))                        # eq. 25
            H[0, [0, 1, b, b + 1]] = [-dx / r, -dy / r, dx / r, dy / r]
            H[1, [0, 1, 2, b, b + 1]] = [dy / q, -dx / q, -1.0, -dy / q, dx / q]
            S = H @ self.P @ H.T + Q
            if it == 0:
                self.last_nis = float(nu @ np.linalg.solve(S, nu))
                if gate is not None and self.seen[j] and self.last_nis > _gate_threshold(gate):
                    return False
            K = self.P @ H.T @ np.linalg.inv(S)              # eq. 24
            if it == 0:
                xi = x_prior + K @ nu                        # eq. 27
            else:
                d = x_prior - xi
                d[2] = wrap_angle(d[2])
                xi = x_prior + K @ (nu - H @ d)
        self.x = xi
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(self.n) - K @ H
        self.P = A @ self.P @ A.T + K @ Q @ K.T              # eq. 26 in Joseph form
        self.P = 0.5 * (self.P + self.P.T)
        self.seen[j] = True
        return True


@lru_cache(maxsize=32)
def _gate_threshold(gate: float) -> float:
    return float(chi2_ppf(gate, 2))


def _start(log: NavLog) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    prior = log.pose_prior()
    if prior is not None:
        cov = np.diag([prior.sigma_xy**2, prior.sigma_xy**2, prior.sigma_yaw**2])
        return np.array([prior.x, prior.y, prior.yaw]), cov, "pose_prior"
    for r in log.records:
        if r.kind == "truth":
            return np.array([r.x, r.y, r.yaw]), np.zeros((3, 3)), "truth"
    return np.zeros(3), np.zeros((3, 3)), "origin"


def _given(v: float) -> bool:
    return math.isfinite(v) and v > 0.0


class _NisScale:
    """Innovation-based scale of the motion noise (adaptive estimation from the innovation
    sequence, after Mohamed & Schwarz 1999, reduced to one scalar): over the last ``window``
    re-sightings, ``s = max(1, median(NIS) / median(chi2_2))``, each NIS capped at the gate
    threshold so a gross outlier counts as one large value, not as its size. The motion noise is
    multiplied by ``s``: a filter whose innovations are persistently larger than its covariance
    says (too little motion noise, so the gate starts rejecting good returns) widens its
    prediction until they agree again; it never shrinks the stated noise."""

    MEDIAN_CHI2_2 = 2.0 * math.log(2.0)  # median of chi-square with 2 dof

    def __init__(self, window: int, cap: float) -> None:
        self.buf: deque[float] = deque(maxlen=window)
        self.cap = cap
        self.scale = 1.0
        self.max_scale = 1.0

    def add(self, nis: float) -> None:
        if not math.isfinite(nis):
            return
        self.buf.append(min(nis, self.cap))
        if len(self.buf) == self.buf.maxlen:
            self.scale = max(1.0, float(np.median(self.buf)) / self.MEDIAN_CHI2_2)
            self.max_scale = max(self.max_scale, self.scale)


@dataclass
class _SlamSettings:
    """The options of :func:`run_ekf_slam` resolved for one mode (the defaults filled in)."""

    sv: float
    sw: float
    sr: float
    sb: float
    gate: float | None
    init: str
    adaptive: bool
    density: bool  # the default motion sigmas are noise densities (real-log mode)
    grow: bool  # slots added when a beacon is first seen (else one per beacon id from the start)
    reinit_after: int | None
    iterations: int
    window: int

    @classmethod
    def of(cls, *, paper: bool, sigma_v: float | None, sigma_rot: float | None, sigma_range: float | None,
           sigma_bearing: float | None, gate: float | None | str, init: str | None, adaptive: bool | None,
           reinit_after: int | None, p0_cross: str, iterations: int, window: int) -> _SlamSettings:
        defaults = PAPER_SIGMAS if paper else SENSOR_DEFAULTS
        if gate == "default":
            gate = None if paper else DEFAULT_GATE
        if gate is not None and not 0.0 < float(gate) < 1.0:
            raise ValueError(f"gate must be a probability in (0, 1) or None, not {gate!r}")
        return cls(sv=defaults["sigma_v"] if sigma_v is None else sigma_v,
                   sw=defaults["sigma_rot"] if sigma_rot is None else sigma_rot,
                   sr=defaults["sigma_range"] if sigma_range is None else sigma_range,
                   sb=defaults["sigma_bearing"] if sigma_bearing is None else sigma_bearing,
                   gate=gate, init=init or ("paper" if paper else "inverse"),
                   adaptive=(not paper) if adaptive is None else adaptive, density=not paper,
                   grow=p0_cross != "paper" and not paper, reinit_after=None if paper else reinit_after,
                   iterations=iterations, window=window)


class _SlamRun:
    """One EKF-SLAM pass, record by record: :meth:`add` predicts to the record's time with the held
    control, then takes the odometry record as the new control or corrects with the sighting;
    :meth:`emit` reports the estimate of a time; :meth:`result` the run."""

    def __init__(self, f: EkfSlam, cfg: _SlamSettings, slot: dict[str, int], confirmed: dict[int, bool],
                 t0: float, on_estimate: OnEstimate | None) -> None:
        self.f, self.cfg, self.slot = f, cfg, slot
        self.confirmed = confirmed  # a beacon slot whose first sighting was confirmed by a re-sighting
        self.misses: dict[int, int] = {}
        self.nis = _NisScale(cfg.window, _gate_threshold(cfg.gate) if cfg.gate is not None else math.inf) \
            if cfg.adaptive else None
        self.t_cur = t0
        self.u: Odometry | None = None
        self.on_estimate = on_estimate
        self.ts: list[float] = []
        self.poses: list[NDArray[np.float64]] = []
        self.covs: list[NDArray[np.float64]] = []
        self.counts = {"updates": 0, "rejected": 0, "invalid": 0, "reinitialised": 0}
        self.defaulted: set[str] = set()

    def add(self, r: Odometry | BeaconObs) -> None:
        if r.t > self.t_cur:
            if self.u is not None:
                self._predict(self.u, r.t - self.t_cur)
            self.t_cur = r.t
        if isinstance(r, Odometry):
            self.u = r
            if not (_given(r.sigma_v) and _given(r.sigma_w)):
                self.defaulted.add("odometry")
        elif not (r.range > 0.0 and math.isfinite(r.range) and math.isfinite(r.bearing)):
            self.counts["invalid"] += 1
        else:
            self._sighting(r)

    def _predict(self, u: Odometry, dt: float) -> None:
        """Eq. 3 and 19-23 over ``dt`` with the control ``u``: its own sigmas as per-record white noise,
        else the defaults (noise densities in the real-log mode), times the innovation scale."""
        cfg = self.cfg
        k = self.nis.scale if self.nis is not None else 1.0
        if _given(u.sigma_v):
            a = u.sigma_v
        else:
            a = cfg.sv * math.sqrt(1.0 / dt) if cfg.density else cfg.sv
        if _given(u.sigma_w):
            c = u.sigma_w
        else:
            c = cfg.sw * math.sqrt(1.0 / dt) if cfg.density else cfg.sw
        self.f.predict(u.v, u.w, dt, a * math.sqrt(k), c * math.sqrt(k))

    def _sighting(self, r: BeaconObs) -> None:
        """Eq. 6, 24-27 for one sighting: gated, the adaptive scale fed, a never-confirmed beacon
        initialised again after ``reinit_after`` gated re-sightings in a row."""
        f, cfg = self.f, self.cfg
        if r.id not in self.slot:
            self.slot[r.id] = f.add_beacon()
        j = self.slot[r.id]
        if not (_given(r.sigma_range) and _given(r.sigma_bearing)):
            self.defaulted.add("beacon")
        zr = r.sigma_range if _given(r.sigma_range) else cfg.sr
        zb = r.sigma_bearing if _given(r.sigma_bearing) else cfg.sb
        resight = bool(f.seen[j])
        ok = f.update(j, r.range, r.bearing, zr, zb, cfg.gate, cfg.iterations)
        if self.nis is not None and resight:
            self.nis.add(f.last_nis)
        if resight and ok:
            self.confirmed[j], self.misses[j] = True, 0
        elif resight:
            self.misses[j] = self.misses.get(j, 0) + 1
            if cfg.reinit_after is not None and not self.confirmed.get(j, False) and \
                    self.misses[j] >= cfg.reinit_after:
                f.forget(j)
                ok = f.update(j, r.range, r.bearing, zr, zb, cfg.gate, cfg.iterations)
                self.misses[j] = 0
                self.counts["reinitialised"] += 1
        self.counts["updates"] += ok
        self.counts["rejected"] += not ok
        if ok and not np.all(np.isfinite(f.x[:3])):
            raise ValueError(f"ekf-slam diverged (non-finite state) at the beacon record of t = {r.t}")

    def emit(self, t: float) -> None:
        self.ts.append(t)
        self.poses.append(self.f.x[:3].copy())
        self.covs.append(self.f.P[:3, :3].copy())
        if self.on_estimate is not None:
            self.on_estimate(t, self.poses[-1], self.covs[-1])

    def result(self, step_ms: list[float], info: dict[str, Any]) -> RunResult:
        f, cfg = self.f, self.cfg
        traj = Trajectory(np.array(self.ts), np.array(self.poses), np.array(self.covs), name="ekf-slam")
        beacons = {i: f.x[3 + 2 * j: 5 + 2 * j].tolist() for i, j in self.slot.items() if f.seen[j]}
        info = {"anchor": info.pop("anchor"), "beacons": beacons, **self.counts, **info,
                "defaults_used": sorted(self.defaulted),
                "sigmas": {"sigma_v": cfg.sv, "sigma_rot": cfg.sw, "sigma_range": cfg.sr, "sigma_bearing": cfg.sb,
                           "density": cfg.density}}
        if self.nis is not None:
            info.update({"noise_scale_final": self.nis.scale, "noise_scale_max": self.nis.max_scale})
        return RunResult(traj, traj, np.array(step_ms), info=info)


def run_ekf_slam(log: NavLog, *, on_estimate: OnEstimate | None = None, paper: bool = False,
                 sigma_v: float | None = None, sigma_rot: float | None = None, sigma_range: float | None = None,
                 sigma_bearing: float | None = None, gate: float | None | str = "default",
                 init: str | None = None, adaptive: bool | None = None, window: int = 20,
                 iterations: int = 1, fej: bool | None = None, reinit_after: int | None = 3,
                 p0_beacon: float = 1e6, p0_cross: str = "zero", w_second: str = "rot",
                 use_known: bool = True) -> RunResult:
    """EKF-SLAM over a log with odometry (V, ROT) and beacon range/bearing records.

    Two modes (every option below can still be set on its own):

    * default, for real logs: chi-square gate ``gate`` = 0.999 on the Mahalanobis distance with
      ``S = H P H^T + Q``; textbook first sighting (``init="inverse"``: the beacon from the inverse
      observation with ``P_bb = Gx Pxx Gx^T + Gz Q Gz^T``, ``P_bx = Gx P_x:``); a beacon gets its
      slot when it is first seen; motion noise scaled up from the innovations (``adaptive``, see
      :class:`_NisScale`); the defaults for sigmas the log does not give are :data:`SENSOR_DEFAULTS`.
    * ``paper=True``: the beacon paper's filter exactly (what the layout study computes): no gate,
      ``init="paper"``, every beacon id in the log has a slot from the start, no adaptation, and the
      paper's section 7 sigmas (:data:`PAPER_SIGMAS`) as per-record white noise.

    Sigmas in the records win over the defaults and are per-record white noise (as the simulators
    draw them): the control's variance enters each prediction step as ``W M W^T`` (eq. 20-23).
    The default motion sigmas of the real-log mode are instead noise densities, given as the error
    of the speed (rate of turn) averaged over 1 s: the step variance is ``sigma^2 * 1 s * dt`` (so
    the error of the integrated distance or heading grows as ``sigma sqrt(t)`` whatever the
    odometry rate; as per-record white noise, 100 Hz odometry would average its own error away).
    The control of an odometry record is held until the next one (as dead reckoning); each record
    time with a new estimate is reported through ``on_estimate``. ``iterations`` > 1: iterated EKF
    corrections (:meth:`EkfSlam.update`). ``reinit_after``: a beacon whose first sighting was
    never confirmed (no re-sighting accepted yet) and whose next ``reinit_after`` re-sightings in a
    row are all gated out was most likely initialised from a gross outlier (a first sighting
    cannot be gated): it is forgotten and initialised again from the current sighting (``None``:
    never; off in the paper's mode).
    """
    cfg = _SlamSettings.of(paper=paper, sigma_v=sigma_v, sigma_rot=sigma_rot, sigma_range=sigma_range,
                           sigma_bearing=sigma_bearing, gate=gate, init=init, adaptive=adaptive,
                           reinit_after=reinit_after, p0_cross=p0_cross, iterations=iterations, window=window)
    known = {b.id for b in log.beacons_known} if use_known else set()
    slot: dict[str, int] = {}
    if not cfg.grow:  # the paper's eq. 14-15: a slot per beacon of the log from the start
        slot = {i: j for j, i in enumerate(sorted({r.id for r in log.of("beacon")} | known))}
    pose0, cov0, anchor = _start(log)
    fej = (not paper and iterations <= 1) if fej is None else fej
    if fej and iterations > 1:
        raise ValueError("fej and iterations > 1 exclude each other (the iterated update relinearises)")
    f = EkfSlam(pose0, len(slot), pose_cov0=cov0, p0_beacon=p0_beacon, p0_cross=p0_cross, w_second=w_second,
                init=cfg.init, fej=fej)
    if use_known:
        for kb in log.beacons_known:
            if kb.id not in slot:
                slot[kb.id] = f.add_beacon()
            f.set_beacon(slot[kb.id], (kb.x, kb.y), kb.sigma**2)
    recs = [r for r in log.records if isinstance(r, Odometry | BeaconObs)]
    if not recs:
        raise ValueError("ekf-slam needs odometry records")
    confirmed = {slot[kb.id]: True for kb in log.beacons_known} if use_known else {}
    run = _SlamRun(f, cfg, slot, confirmed, recs[0].t, on_estimate)
    step_ms = []
    for i, r in enumerate(recs):
        t0 = time.perf_counter()
        run.add(r)
        step_ms.append((time.perf_counter() - t0) * 1e3)
        if i + 1 == len(recs) or recs[i + 1].t > r.t:
            run.emit(r.t)
    return run.result(step_ms, {"anchor": anchor, "mode": "paper" if paper else "robust", "gate": cfg.gate,
                                "init": cfg.init, "fej": fej, "p0_beacon": p0_beacon, "p0_cross": p0_cross,
                                "w_second": w_second})


def _unmet(log: NavLog) -> str | None:
    if len(log.of("odometry")) < 2:
        return "needs odometry (speed + rate of turn) records"
    if not log.of("beacon"):
        return "needs beacon range/bearing records"
    return None


def _inputs(log: NavLog, options: dict) -> set[str]:
    kinds = {"odometry", "beacon", "pose_prior"}
    if options.get("use_known", True):
        kinds.add("beacon_known")
    return kinds


@dataclass
class EkfSlamConfig:
    """The ``ekf-slam`` estimator's options (:func:`run_ekf_slam`; null: the mode's default)."""

    paper: bool = option(False, "true: the beacon paper's filter exactly (no gate, its init and sigmas, a slot per "
                         "beacon)")
    sigma_v: float | None = option(None, "speed sigma when the record gives none (null: the mode's default)",
                                   unit="m/s")
    sigma_rot: float | None = option(None, "rate-of-turn sigma when the record gives none (null: the mode's "
                                     "default)", unit="rad/s")
    sigma_range: float | None = option(None, "range sigma when the record gives none (null: the mode's default)",
                                       unit="m")
    sigma_bearing: float | None = option(None, "bearing sigma when the record gives none (null: the mode's "
                                         "default)", unit="rad")
    gate: float | None | str = option("default", "chi-square probability of the gate on the Mahalanobis distance "
                                      "(default: 0.999, none with paper=true; null: no gate)")
    init: str | None = option(None, 'a beacon\'s first sighting: "inverse" (inverse observation, the default) or '
                              '"paper"')
    adaptive: bool | None = option(None, "motion noise scaled up from the innovations (null: on unless paper=true)")
    window: int = option(20, "innovations in the adaptive motion-noise scale's window")
    iterations: int = option(1, "iterations > 1: iterated EKF corrections")
    fej: bool | None = option(None, "first-estimates Jacobians (Huang et al. 2008; null: on unless paper=true)")
    reinit_after: int | None = option(3, "a beacon whose first sighting was never confirmed and whose next this "
                                      "many re-sightings are all gated out is initialised again (null: never)")
    p0_beacon: float = option(1e6, "a beacon's initial variance with init=paper (eq. 14)", unit="m^2")
    p0_cross: str = option("zero", 'initial cross covariances: "zero" (a valid P0) or "paper" (eq. 14 as printed)')
    w_second: str = option("rot", 'second column of W (eq. 22): "rot" = dg/dROT or "theta" as printed')
    use_known: bool = option(True, "false: ignore the log's charted beacons (map every beacon)")


class EkfSlamEstimator(BatchEstimator):
    """EKF-SLAM on odometry and beacon range/bearing records (:func:`run_ekf_slam`)."""

    description = ("range-bearing EKF-SLAM (beacon paper, eq. 3-27): gated, FEJ, for real logs; paper=true: the "
                   "paper's filter")
    Config = EkfSlamConfig
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)

    batch = staticmethod(run_ekf_slam)


ESTIMATORS = {"ekf-slam": EkfSlamEstimator}
