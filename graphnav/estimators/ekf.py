"""A general EKF on [x, y, yaw] (optionally + speed): the classic filter baseline.

Motion input: odometry (speed + rate of turn, unicycle model as eq. 3 of the beacon paper), or,
when a log has LiDAR scans but no odometry, ICP increments from :func:`graphnav.icp.match_scans`
(used only if that module is installed). Measurements: GNSS position and compass heading, each
gated by a chi-square test on the normalised innovation squared (a GNSS jump is rejected, the
estimate survives); after ``max_rejects`` consecutive rejections of one sensor the next
measurement is accepted, with the covariance of the measured components inflated by the
innovation, so the filter recovers from its own divergence (e.g. after a long outage).
Heading innovations are wrapped to [-pi, pi); the yaw state is kept wrapped.
Updates use the Joseph form. With ``speed=True`` the state is [x, y, yaw, v]: v is a random walk
(``sigma_acc``) and odometry speed becomes a measurement of it. See docs/ekf.md.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from ..geometry import wrap_angle
from ..log import Gnss, Heading, NavLog, Odometry, Scan
from ..trajectory import Trajectory
from . import EstimatorSpec, OnEstimate, RunResult


def icp_available() -> bool:
    try:
        from ..icp import match_scans  # noqa: F401
    except ImportError:
        return False
    return True


class PoseEkf:
    """EKF on [x, y, yaw] or [x, y, yaw, v] with Joseph-form, chi-square-gated updates."""

    def __init__(self, x0: NDArray[np.float64], P0: NDArray[np.float64], *, gate: float | None = 0.999,
                 max_rejects: int = 10) -> None:
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.gate = gate
        self.max_rejects = max_rejects
        self.rejects: dict[str, int] = {}
        self.counts = {"accepted": 0, "rejected": 0, "forced": 0}

    @property
    def has_speed(self) -> bool:
        return len(self.x) == 4

    # ------------------------------------------------------------------ prediction
    def predict_odometry(self, v: float, w: float, dt: float, sigma_v: float, sigma_w: float,
                         sigma_acc: float = 0.5) -> None:
        """Unicycle step over ``dt`` with speed ``v`` (ignored when v is a state) and yaw rate ``w``."""
        th = self.x[2]
        c, s = math.cos(th), math.sin(th)
        n = len(self.x)
        G = np.eye(n)
        if self.has_speed:
            v = self.x[3]
            G[0, 3], G[1, 3] = c * dt, s * dt
        G[0, 2], G[1, 2] = -s * dt * v, c * dt * v
        Wm = np.zeros((n, 2))
        Q = np.zeros((n, n))
        if self.has_speed:
            Q[3, 3] = sigma_acc**2 * dt
        else:
            Wm[0, 0], Wm[1, 0] = c * dt, s * dt
        Wm[2, 1] = dt
        self.x[0] += v * dt * c
        self.x[1] += v * dt * s
        self.x[2] = wrap_angle(th + w * dt)
        self.P = G @ self.P @ G.T + Wm @ np.diag([sigma_v**2, sigma_w**2]) @ Wm.T + Q

    def predict_increment(self, delta: NDArray[np.float64], cov: NDArray[np.float64]) -> None:
        """Compose a body-frame increment (dx, dy, dyaw) with additive covariance ``cov``."""
        th = self.x[2]
        c, s = math.cos(th), math.sin(th)
        dx, dy, dth = delta
        n = len(self.x)
        G = np.eye(n)
        G[0, 2], G[1, 2] = -s * dx - c * dy, c * dx - s * dy
        V = np.zeros((n, 3))
        V[:2, :2] = [[c, -s], [s, c]]
        V[2, 2] = 1.0
        self.x[0] += c * dx - s * dy
        self.x[1] += s * dx + c * dy
        self.x[2] = wrap_angle(th + dth)
        self.P = G @ self.P @ G.T + V @ cov @ V.T

    # ------------------------------------------------------------------ corrections
    def _update(self, sensor: str, nu: NDArray, H: NDArray, R: NDArray) -> bool:
        S = H @ self.P @ H.T + R
        if self.gate is not None:
            d2 = float(nu @ np.linalg.solve(S, nu))
            if d2 > chi2.ppf(self.gate, len(nu)):
                self.rejects[sensor] = self.rejects.get(sensor, 0) + 1
                if self.rejects[sensor] <= self.max_rejects:
                    self.counts["rejected"] += 1
                    return False
                # persistent disagreement: the filter, not the sensor, is wrong. Inflate the measured
                # components by the innovation (H selects state entries) and accept.
                self.counts["forced"] += 1
                self.P = self.P + H.T @ np.outer(nu, nu) @ H
                S = H @ self.P @ H.T + R
        self.rejects[sensor] = 0
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ nu
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(len(self.x)) - K @ H
        self.P = A @ self.P @ A.T + K @ R @ K.T
        self.P = 0.5 * (self.P + self.P.T)
        self.counts["accepted"] += 1
        return True

    def update_position(self, xy: tuple[float, float], sigma: float) -> bool:
        H = np.zeros((2, len(self.x)))
        H[0, 0] = H[1, 1] = 1.0
        return self._update("gnss", np.asarray(xy) - self.x[:2], H, np.eye(2) * sigma**2)

    def update_heading(self, yaw: float, sigma: float) -> bool:
        H = np.zeros((1, len(self.x)))
        H[0, 2] = 1.0
        return self._update("heading", np.array([wrap_angle(yaw - self.x[2])]), H, np.array([[sigma**2]]))

    def update_speed(self, v: float, sigma: float) -> bool:
        H = np.zeros((1, 4))
        H[0, 3] = 1.0
        return self._update("speed", np.array([v - self.x[3]]), H, np.array([[sigma**2]]))


def _initial(log: NavLog, speed: bool) -> tuple[NDArray, NDArray, str]:
    prior = log.pose_prior()
    gnss, heads = log.of("gnss"), log.of("heading")
    if prior is not None:
        x = [prior.x, prior.y, prior.yaw]
        P = np.diag([prior.sigma_xy**2, prior.sigma_xy**2, prior.sigma_yaw**2])
        anchor = "pose_prior"
    elif gnss:
        yaw, sy = (heads[0].yaw, heads[0].sigma) if heads else (0.0, math.pi)
        x = [gnss[0].x, gnss[0].y, yaw]
        P = np.diag([gnss[0].sigma**2, gnss[0].sigma**2, sy**2])
        anchor = "gnss"
    else:
        truth = log.of("truth")
        x = [truth[0].x, truth[0].y, truth[0].yaw] if truth else [0.0, 0.0, 0.0]
        P = np.zeros((3, 3))
        anchor = "truth" if truth else "origin"
    if speed:
        odo = log.of("odometry")
        x = [*x, odo[0].v if odo else 0.0]
        P4 = np.zeros((4, 4))
        P4[:3, :3] = P
        P4[3, 3] = 1.0
        P = P4
    return np.array(x, dtype=float), P, anchor


def _sig(v: float, default: float) -> float:
    return default if not math.isfinite(v) else v


def run_ekf(log: NavLog, *, on_estimate: OnEstimate | None = None, motion: str = "auto", speed: bool = False,
            gate: float | None = 0.999, max_rejects: int = 10, sigma_v: float = 0.5,
            sigma_w: float = math.radians(0.5), sigma_acc: float = 0.5, use_gnss: bool = True,
            use_heading: bool = True, icp_inflate: float = 100.0) -> RunResult:
    """EKF over a log. ``motion``: ``"odometry"``, ``"icp"`` or ``"auto"`` (odometry if the log has
    it, else ICP on the scans). ``gate``: chi-square probability (``None`` disables gating).
    Sigmas in the records win over ``sigma_v``/``sigma_w``."""
    odo_n = len(log.of("odometry"))
    if motion == "auto":
        motion = "odometry" if odo_n >= 2 else "icp"
    if motion == "icp" and not icp_available():
        raise ValueError("ICP motion needs graphnav.icp (not installed in this build)")
    x0, P0, anchor = _initial(log, speed)
    f = PoseEkf(x0, P0, gate=gate, max_rejects=max_rejects)
    kinds = (Gnss, Heading, Odometry) if motion == "odometry" else (Gnss, Heading, Scan)
    recs = [r for r in log.records if isinstance(r, kinds)]
    if not recs:
        raise ValueError("ekf: the log has no usable records")
    match_scans = None
    if motion == "icp":
        from ..icp_cache import match_scans  # graphnav.icp's, shared inside icp_cache.active()
    t_cur = recs[0].t
    u: Odometry | None = None
    prev_scan: Scan | None = None
    last_inc, last_cov = np.zeros(3), np.eye(3)
    ts, poses, covs, step_ms, icp_ms = [], [], [], [], []
    icp_failed = 0

    def emit(t: float) -> None:
        ts.append(t)
        poses.append(f.x[:3].copy())
        covs.append(f.P[:3, :3].copy())
        if on_estimate is not None:
            on_estimate(t, poses[-1], covs[-1])

    for i, r in enumerate(recs):
        if isinstance(r, Scan):
            if prev_scan is not None:
                t0 = time.perf_counter()
                res = match_scans(r, prev_scan, init=last_inc)
                icp_ms.append((time.perf_counter() - t0) * 1e3)
                if res.ok:
                    last_inc, last_cov = np.asarray(res.pose, float), np.asarray(res.cov_target, float)
                    inc, cov = last_inc, last_cov
                else:
                    icp_failed += 1
                    inc, cov = last_inc, last_cov * icp_inflate
                t0 = time.perf_counter()
                f.predict_increment(inc, cov)
                step_ms.append((time.perf_counter() - t0) * 1e3)
            prev_scan = r
            t_cur = r.t
        else:
            t0 = time.perf_counter()
            if r.t > t_cur and motion == "odometry":
                if u is not None:
                    f.predict_odometry(u.v, u.w, r.t - t_cur, _sig(u.sigma_v, sigma_v),
                                       _sig(u.sigma_w, sigma_w), sigma_acc)
                t_cur = r.t
            if isinstance(r, Odometry):
                u = r
                if f.has_speed:
                    f.update_speed(r.v, _sig(r.sigma_v, sigma_v))
            elif isinstance(r, Gnss) and use_gnss:
                f.update_position((r.x, r.y), r.sigma)
            elif isinstance(r, Heading) and use_heading:
                f.update_heading(r.yaw, r.sigma)
            step_ms.append((time.perf_counter() - t0) * 1e3)
        if i + 1 == len(recs) or recs[i + 1].t > r.t:
            emit(r.t)
    traj = Trajectory(np.array(ts), np.array(poses), np.array(covs), name="ekf")
    info: dict[str, Any] = {"anchor": anchor, "motion": motion, "speed_state": speed, "gate": gate,
                            **f.counts, "icp_failed": icp_failed}
    return RunResult(traj, traj, np.array(step_ms), np.array(icp_ms), info=info)


def _unmet(log: NavLog) -> str | None:
    has_odo = len(log.of("odometry")) >= 2
    has_scans = len(log.of("scan")) >= 2
    if not has_odo and not (has_scans and icp_available()):
        extra = " (scans need graphnav.icp, not installed)" if has_scans else ""
        return "needs odometry records" + extra
    return None


ESTIMATORS = {
    "ekf": EstimatorSpec(run_ekf, _unmet,
                         "EKF on x, y, yaw (+speed): odometry or ICP motion, gated GNSS + compass", "filter"),
}
