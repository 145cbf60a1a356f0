"""The EKF's filter algebra on a planar pose: :class:`PoseEkf` (predict, gated Joseph update,
wrapping), driven record by record by :class:`graphnav.estimators.ekf.EkfStepper` (docs/ekf.md)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle
from .gating import InnovationGate, reinit_block


class PoseEkf:
    """EKF on [x, y, yaw] or [x, y, yaw, v] with Joseph-form, chi-square-gated updates
    (:class:`graphnav.estimators.gating.InnovationGate`; ``gating`` holds its options)."""

    def __init__(self, x0: NDArray[np.float64], P0: NDArray[np.float64], *, gate: float | None = 0.999,
                 **gating: Any) -> None:
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.gate = gate
        self.gater = InnovationGate(gate, **gating)
        self.counts = self.gater.counts  # accepted, rejected, reinit
        self.n_updates = 0

    def gate_limit(self, dof: int) -> float:
        """``chi2.ppf(gate, dof)`` (the same expression as scipy.stats' ``chi2``), computed once per dof."""
        return self.gater.limit(dof)

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
    def _update(self, sensor: str, nu: NDArray, H: NDArray, R: NDArray, t: float | None = None,
                angle: bool = False, reinit: bool = True, reinit_idx: list[int] | None = None) -> bool:
        """Gated Joseph update; ``t`` the measurement time [s] for the gate's time rules (default:
        the number of updates so far). False if the measurement was rejected. ``reinit=False`` (a
        measurement that is no state component): a re-initialisation verdict is a plain update.
        ``reinit_idx``: the components a re-initialisation restarts (default: every one H touches;
        a biased compass restarts the yaw at the reading less the bias, the bias kept)."""
        self.n_updates += 1
        HPH = H @ self.P @ H.T
        S = HPH + R
        verdict = self.gater.test(sensor, float(self.n_updates if t is None else t), nu, HPH, R, angle=angle)
        if verdict == "reject":
            return False
        if verdict == "reinit" and reinit:  # sustained evidence: the measured components restart at the measurement
            idx = np.flatnonzero(H.any(axis=0)) if reinit_idx is None else np.asarray(reinit_idx)
            z = self.x[idx] + nu
            if angle:
                z = wrap_angle(z)
            reinit_block(self.x, self.P, idx, z, R * self.gater.scale(sensor))
            return True
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ nu
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(len(self.x)) - K @ H
        self.P = A @ self.P @ A.T + K @ R @ K.T
        self.P = 0.5 * (self.P + self.P.T)
        return True

    def update_position(self, xy: tuple[float, float], sigma: float, t: float | None = None) -> bool:
        H = np.zeros((2, len(self.x)))
        H[0, 0] = H[1, 1] = 1.0
        return self._update("gnss", np.asarray(xy) - self.x[:2], H, np.eye(2) * sigma**2, t)

    def update_heading(self, yaw: float, sigma: float, t: float | None = None) -> bool:
        H = np.zeros((1, len(self.x)))
        H[0, 2] = 1.0
        return self._update("heading", np.array([wrap_angle(yaw - self.x[2])]), H, np.array([[sigma**2]]), t,
                            angle=True)

    def update_speed(self, v: float, sigma: float, t: float | None = None) -> bool:
        H = np.zeros((1, 4))
        H[0, 3] = 1.0
        return self._update("speed", np.array([v - self.x[3]]), H, np.array([[sigma**2]]), t)
