"""Range-bearing EKF-SLAM exactly as the beacon paper's sections 3-5 (Marchel, Naus & Specht 2019).

State [x, y, theta, x_1, y_1, ..., x_i, y_i]; motion eq. 3 with control (V, ROT); G eq. 19;
W eq. 22 (second column dg/dROT); R = W M W^T eq. 20-23; range-bearing measurement eq. 6 with
Jacobian H eq. 25; one beacon per correction (K is (3+2i) x 2, eq. 24); P0 eq. 14 (zero vessel
block unless the log has a pose prior, beacon variances ``p0_beacon`` = 1e6 m^2).
Every beacon seen in the log has a slot from the start (eq. 14-15); its mean is set at first
sighting from the inverse observation. Charted beacons (``beacon_known`` records) start at their
charted position with their charted variance. The correction uses the Joseph form, so P stays
symmetric and positive semidefinite to round-off (``tests/estimators/test_ekf_slam.py`` runs it for 10,000 steps).

Matrices here are dense, written as the paper writes them: this class is also the reference the
batched search (:mod:`graphnav.beacons.layout`) is tested against.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from ..geometry import wrap_angle
from ..log import BeaconObs, NavLog, Odometry
from ..trajectory import Trajectory
from . import EstimatorSpec, OnEstimate, RunResult

DEFAULT_SIGMA_V = 0.5                       # m/s, paper section 7
DEFAULT_SIGMA_ROT = math.radians(0.1)       # rad/s
DEFAULT_SIGMA_RANGE = 0.5                   # m
DEFAULT_SIGMA_BEARING = math.radians(0.5)   # rad


class EkfSlam:
    """Dense EKF-SLAM over ``n_beacons`` beacon slots.

    ``p0_cross="paper"`` fills every entry outside the vessel block of P0 with ``p0_beacon`` as
    eq. 14 is printed (an indefinite matrix: for studying the paper only).
    """

    def __init__(self, pose0: NDArray[np.float64], n_beacons: int, *, pose_cov0: NDArray | None = None,
                 p0_beacon: float = 1e6, p0_cross: str = "zero", w_second: str = "rot") -> None:
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
        self.w_second = w_second

    @property
    def n(self) -> int:
        return len(self.x)

    def set_beacon(self, j: int, xy: tuple[float, float], var: float) -> None:
        """A charted beacon: mean ``xy``, variance ``var`` per axis, uncorrelated."""
        b = 3 + 2 * j
        self.x[b:b + 2] = xy
        self.P[b:b + 2, :] = 0.0
        self.P[:, b:b + 2] = 0.0
        self.P[b:b + 2, b:b + 2] = np.eye(2) * var
        self.seen[j] = True

    def predict(self, v: float, rot: float, dt: float, sigma_v: float, sigma_rot: float) -> None:
        """Eq. 18 (mean) and eq. 19-23 (covariance)."""
        th = self.x[2]
        c, s = math.cos(th), math.sin(th)
        G = np.eye(self.n)                                   # eq. 19
        G[0, 2] = -s * dt * v
        G[1, 2] = c * dt * v
        W = np.zeros((self.n, 2))                            # eq. 22
        W[0, 0], W[1, 0] = c * dt, s * dt
        if self.w_second == "rot":
            W[2, 1] = dt
        else:                                                # eq. 22 as printed: dg/dtheta
            W[0, 1], W[1, 1], W[2, 1] = G[0, 2], G[1, 2], 1.0
        M = np.diag([sigma_v**2, sigma_rot**2])              # eq. 17
        self.x[0] += v * dt * c
        self.x[1] += v * dt * s
        self.x[2] = wrap_angle(th + rot * dt)
        self.P = G @ self.P @ G.T + W @ M @ W.T              # eq. 23

    def update(self, j: int, z_range: float, z_bearing: float, sigma_range: float, sigma_bearing: float,
               gate: float | None = None) -> bool:
        """Eq. 24-27 for beacon slot ``j`` (initialised from this observation at first sighting).

        ``gate``: chi-square probability (e.g. 0.999) above which the innovation is rejected;
        returns whether the measurement was used.
        """
        b = 3 + 2 * j
        if not self.seen[j]:
            a = z_bearing + self.x[2]
            self.x[b] = self.x[0] + z_range * math.cos(a)
            self.x[b + 1] = self.x[1] + z_range * math.sin(a)
        dx, dy = self.x[b] - self.x[0], self.x[b + 1] - self.x[1]
        q = dx * dx + dy * dy
        r = math.sqrt(q)
        H = np.zeros((2, self.n))                            # eq. 25
        H[0, [0, 1, b, b + 1]] = [-dx / r, -dy / r, dx / r, dy / r]
        H[1, [0, 1, 2, b, b + 1]] = [dy / q, -dx / q, -1.0, -dy / q, dx / q]
        Q = np.diag([sigma_range**2, sigma_bearing**2])      # eq. 16
        nu = np.array([z_range - r, wrap_angle(z_bearing - (math.atan2(dy, dx) - self.x[2]))])
        S = H @ self.P @ H.T + Q
        if gate is not None and self.seen[j] and float(nu @ np.linalg.solve(S, nu)) > chi2.ppf(gate, 2):
            return False
        K = self.P @ H.T @ np.linalg.inv(S)                  # eq. 24
        self.x = self.x + K @ nu                             # eq. 27
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(self.n) - K @ H
        self.P = A @ self.P @ A.T + K @ Q @ K.T              # eq. 26 in Joseph form
        self.P = 0.5 * (self.P + self.P.T)
        self.seen[j] = True
        return True


def _start(log: NavLog) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    prior = log.pose_prior()
    if prior is not None:
        cov = np.diag([prior.sigma_xy**2, prior.sigma_xy**2, prior.sigma_yaw**2])
        return np.array([prior.x, prior.y, prior.yaw]), cov, "pose_prior"
    for r in log.records:
        if r.kind == "truth":
            return np.array([r.x, r.y, r.yaw]), np.zeros((3, 3)), "truth"
    return np.zeros(3), np.zeros((3, 3)), "origin"


def _sig(v: float, default: float) -> float:
    return default if not math.isfinite(v) else v


def run_ekf_slam(log: NavLog, *, on_estimate: OnEstimate | None = None, sigma_v: float = DEFAULT_SIGMA_V,
                 sigma_rot: float = DEFAULT_SIGMA_ROT, sigma_range: float = DEFAULT_SIGMA_RANGE,
                 sigma_bearing: float = DEFAULT_SIGMA_BEARING, p0_beacon: float = 1e6, p0_cross: str = "zero",
                 w_second: str = "rot", gate: float | None = None, use_known: bool = True) -> RunResult:
    """EKF-SLAM over a log with odometry (V, ROT) and beacon range/bearing records.

    Sigmas given in the records win over the defaults (paper section 7). The control of an
    odometry record is held until the next one (as dead reckoning); each record time with a new
    estimate is reported through ``on_estimate``.
    """
    known = {b.id for b in log.beacons_known} if use_known else set()
    ids = sorted({r.id for r in log.of("beacon")} | known)
    slot = {i: j for j, i in enumerate(ids)}
    pose0, cov0, anchor = _start(log)
    f = EkfSlam(pose0, len(ids), pose_cov0=cov0, p0_beacon=p0_beacon, p0_cross=p0_cross, w_second=w_second)
    if use_known:
        for kb in log.beacons_known:
            f.set_beacon(slot[kb.id], (kb.x, kb.y), kb.sigma**2)
    recs = [r for r in log.records if isinstance(r, Odometry | BeaconObs)]
    if not recs:
        raise ValueError("ekf-slam needs odometry records")
    t_cur = recs[0].t
    u: Odometry | None = None
    ts, poses, covs, step_ms = [], [], [], []
    used = rejected = 0

    def emit(t: float) -> None:
        ts.append(t)
        poses.append(f.x[:3].copy())
        covs.append(f.P[:3, :3].copy())
        if on_estimate is not None:
            on_estimate(t, poses[-1], covs[-1])

    for i, r in enumerate(recs):
        t0 = time.perf_counter()
        if r.t > t_cur:
            if u is not None:
                f.predict(u.v, u.w, r.t - t_cur, _sig(u.sigma_v, sigma_v), _sig(u.sigma_w, sigma_rot))
            t_cur = r.t
        if isinstance(r, Odometry):
            u = r
        else:
            ok = f.update(slot[r.id], r.range, r.bearing, _sig(r.sigma_range, sigma_range),
                          _sig(r.sigma_bearing, sigma_bearing), gate)
            used += ok
            rejected += not ok
        step_ms.append((time.perf_counter() - t0) * 1e3)
        if i + 1 == len(recs) or recs[i + 1].t > r.t:
            emit(r.t)
    traj = Trajectory(np.array(ts), np.array(poses), np.array(covs), name="ekf-slam")
    beacons = {i: f.x[3 + 2 * j: 5 + 2 * j].tolist() for i, j in slot.items() if f.seen[j]}
    info: dict[str, Any] = {"anchor": anchor, "beacons": beacons, "updates": used, "rejected": rejected,
                            "p0_beacon": p0_beacon, "p0_cross": p0_cross, "w_second": w_second}
    return RunResult(traj, traj, np.array(step_ms), info=info)


def _unmet(log: NavLog) -> str | None:
    if len(log.of("odometry")) < 2:
        return "needs odometry (speed + rate of turn) records"
    if not log.of("beacon"):
        return "needs beacon range/bearing records"
    return None


ESTIMATORS = {
    "ekf-slam": EstimatorSpec(run_ekf_slam, _unmet, "range-bearing EKF-SLAM (beacon paper, eq. 3-27)",
                              "filter"),
}
