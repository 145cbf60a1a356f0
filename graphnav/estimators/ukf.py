"""The conventional UKF of Liu, Liu & Bucknall (IEEE Access 2019), and a bias-augmented variant.

State (eq. 11) ``x = [p_x, p_y, v_x, v_y, theta]`` (``ukf-bias`` appends the accelerometer and gyro
biases ``[b_ax, b_ay, b_g]``). Inputs: the body-frame IMU acceleration rotated into the navigation
frame by the heading (eq. 4) and the gyro yaw rate; dynamics eq. 1-3 / 12 with the sample time T::

    a_n = R(theta) (a_i - b_a);  p += T v + T^2/2 a_n;  v += T a_n;  theta += T (omega - b_g)

Measurements: GNSS position and compass heading, ``z = H x + v`` with H of eq. 13. Sigma points and
weights of the appendix (scaled: ``lambda = alpha^2 (n + kappa) - n``; alpha = 0.5, beta = 2,
kappa = 0 by default, the paper gives no values), additive process noise Q from Table 2's
accelerometer / gyro noise (white acceleration over the step). The heading is wrapped in the
sigma-point mean (weighted mean of wrapped differences to the central point) and in the innovation.
Since H is linear the estimation step is the appendix's Kalman update. Not in the paper: every
GNSS and compass innovation is gated (:class:`graphnav.estimators.gating.InnovationGate`, the
``ekf``'s rule: chi-square test on a robust innovation scale, re-initialisation only on sustained
evidence; options ``gate`` (``null`` for the paper's ungated filter), ``reinit_n``, ``confirm_n``,
``confirm_s``, ``reinit_after_s``, ``scale_window``), so a sustained GNSS jump is not followed.

The numeric core is :class:`UnscentedNav` (pure numpy, a few dozen small array ops per step);
:func:`run_nav_filter` drives it over a log and is shared with ``fuzzy-ukf``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle
from ..log import NavLog
from ..trajectory import Trajectory
from . import EstimatorSpec, OnEstimate, RunResult
from .gating import GATING_DEFAULTS, InnovationGate, reinit_block

# Table 2: the filters' a-priori noise (1-sigma)
TABLE2 = {
    "q_acc": 0.0039,  # m/s^2
    "q_gyro_deg": 0.033,  # deg/s
    "r_gps_x": 6.0,  # m
    "r_gps_y": 7.0,  # m
    "r_com_deg": 0.5,  # deg
}


def merwe_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[NDArray, NDArray, float]:
    """Appendix weights: ``W_0^m = lambda/(n+lambda)``, ``W_0^c = W_0^m + 1 - alpha^2 + beta``,
    ``W_i = 1 / (2 (n + lambda))``; returns ``(Wm, Wc, lambda)``."""
    lam = alpha * alpha * (n + kappa) - n
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = wm[0] + (1.0 - alpha * alpha + beta)
    return wm, wc, lam


def sigma_points(x: NDArray, P: NDArray, lam: float) -> NDArray:
    """``chi_0 = m``, ``chi_i = m + sqrt(n+lambda) [sqrt(P)]_i``, ``chi_{i+n} = m - ...`` (rows)."""
    n = x.shape[0]
    U = np.linalg.cholesky((n + lam) * P).T  # rows are the columns of the lower factor: U.T @ U = (n+lam)P
    return np.concatenate([x[None, :], x + U, x - U])


def wrapped_mean(X: NDArray, wm: NDArray, angle_idx: int) -> NDArray:
    """Weighted sigma-point mean with the angle averaged as wrapped differences to the central point."""
    m = wm @ X
    ref = X[0, angle_idx]
    d = wrap_angle(X[:, angle_idx] - ref)
    m[angle_idx] = wrap_angle(ref + wm @ d)
    return m


class UnscentedNav:
    """The appendix UKF for the USV model; ``n_bias = 3`` adds accelerometer/gyro bias states."""

    TH = 4  # index of theta

    def __init__(self, x0: NDArray, P0: NDArray, *, q_acc: float, q_gyro: float,
                 q_bias_acc: float = 0.0, q_bias_gyro: float = 0.0,
                 alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> None:
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.n = n = self.x.shape[0]
        self.bias = n == 8
        if n not in (5, 8):
            raise ValueError("state must have 5 or 8 entries")
        self.wm, self.wc, self.lam = merwe_weights(n, alpha, beta, kappa)
        self.q_acc, self.q_gyro = q_acc, q_gyro
        self.q_bias = np.array([q_bias_acc, q_bias_acc, q_bias_gyro]) ** 2
        self._Q_T = None
        self.P_pred = self.P.copy()

    def _Q(self, T: float) -> NDArray:
        if self._Q_T is None or self._Q_T[0] != T:
            qa = self.q_acc ** 2
            Q = np.zeros((self.n, self.n))
            for i in (0, 1):
                Q[i, i] = qa * T ** 4 / 4
                Q[i, i + 2] = Q[i + 2, i] = qa * T ** 3 / 2
                Q[i + 2, i + 2] = qa * T * T
            Q[4, 4] = (self.q_gyro * T) ** 2
            if self.bias:
                Q[5:, 5:] = np.diag(self.q_bias * T)
            self._Q_T = (T, Q)
        return self._Q_T[1]

    def predict(self, ax: float, ay: float, wz: float, T: float) -> None:
        """Step 1 of the appendix: sigma points through eq. 12 (discretised as eq. 1-3) + Q."""
        X = sigma_points(self.x, self.P, self.lam)
        th = X[:, 4]
        if self.bias:
            axb, ayb, w = ax - X[:, 5], ay - X[:, 6], wz - X[:, 7]
        else:
            axb, ayb, w = ax, ay, wz
        c, s = np.cos(th), np.sin(th)
        anx = c * axb - s * ayb  # eq. 4
        any_ = s * axb + c * ayb
        Y = X.copy()
        Y[:, 0] += T * X[:, 2] + 0.5 * T * T * anx
        Y[:, 1] += T * X[:, 3] + 0.5 * T * T * any_
        Y[:, 2] += T * anx
        Y[:, 3] += T * any_
        Y[:, 4] = wrap_angle(th + T * w)
        m = wrapped_mean(Y, self.wm, 4)
        D = Y - m
        D[:, 4] = wrap_angle(D[:, 4])
        self.x = m
        self.P = (D.T * self.wc) @ D + self._Q(T)
        self.P_pred = self.P

    def innovation(self, idx: NDArray, z: NDArray, ix: tuple | None = None) -> tuple[NDArray, NDArray]:
        """``eps = z - H x^-`` (eq. 14, heading wrapped) and ``H P^- H^T`` for the rows ``idx`` of eq. 13
        (``ix`` = ``np.ix_(idx, idx)``, precomputed by callers in a loop)."""
        eps = z - self.x[idx]
        if idx[-1] == 4:
            eps[-1] = wrap_angle(eps[-1])
        return eps, self.P[ix if ix is not None else np.ix_(idx, idx)]

    def update(self, idx: NDArray, eps: NDArray, HPH: NDArray, R: NDArray) -> None:
        """Step 2 of the appendix: ``K = P^- H^T (H P^- H^T + R)^-1``, ``x += K eps``, ``P = (I-KH) P^-``."""
        S = HPH + R
        PHt = self.P[:, idx]
        K = PHt @ np.linalg.inv(S)
        self.x = self.x + K @ eps
        self.x[4] = wrap_angle(self.x[4])
        P = self.P - K @ PHt.T
        self.P = 0.5 * (P + P.T)


# --- driving a filter over a log --------------------------------------------------------------

Adapter = Callable[[int, NDArray, NDArray, NDArray, NDArray], NDArray]
"""``adapter(k, idx, eps, HPH, R0_rows) -> R`` returns the measurement covariance to use. An adapter
may also have ``inflation(ch, HPH_diag) -> lambda`` (per channel, >= 1): the predicted covariance's
position/velocity block is then scaled by the larger GNSS lambda and the heading by the compass one
(:func:`inflate`) before the gate and the update."""

_BLOCKS = ((np.array([0, 1]), np.array([0, 1, 2, 3])), (np.array([2]), np.array([4])))
"""(measurement channels, the state entries they observe directly or through the dynamics)."""


def inflate(P: NDArray, lam: NDArray) -> NDArray:
    """``S P S`` with ``S = diag(sqrt(lambda_i))``: ``lambda`` of the GNSS channels (max of x, y) on
    ``px, py, vx, vy``, of the compass on ``theta``, 1 on the bias states. A congruence: P stays
    symmetric positive definite, its correlations unchanged (a fading-memory / strong-tracking
    factor per block)."""
    s = np.ones(P.shape[0])
    for chans, states in _BLOCKS:
        s[states] = math.sqrt(float(np.max(lam[chans])))
    return P * np.outer(s, s)


def measurement_table(log: NavLog) -> dict[str, NDArray]:
    """Filter timeline (start + IMU times) and the GNSS/compass values attached to each step."""
    imu = log.columns("imu")
    if len(imu["t"]) < 1:
        raise ValueError("needs imu records")
    ti = imu["t"]
    dt0 = float(np.median(np.diff(ti))) if len(ti) > 1 else 1.0
    t = np.concatenate([[ti[0] - dt0], ti])
    n = len(t)
    z = np.full((n, 3), np.nan)
    for kind, cols in (("gnss", ("x", "y")), ("heading", ("yaw",))):
        c = log.columns(kind)
        if not len(c["t"]):
            continue
        k = np.clip(np.searchsorted(t, c["t"]), 0, n - 1)
        km = np.clip(k - 1, 0, n - 1)
        k = np.where(np.abs(t[km] - c["t"]) < np.abs(t[k] - c["t"]), km, k)
        ok = np.abs(t[k] - c["t"]) <= 0.5 * dt0
        j0 = 0 if kind == "gnss" else 2
        for j, name in enumerate(cols):
            z[k[ok], j0 + j] = c[name][ok]
    return {"t": t, "ax": np.concatenate([[0.0], imu["ax"]]), "ay": np.concatenate([[0.0], imu["ay"]]),
            "wz": np.concatenate([[0.0], imu["wz"]]), "z": z}


def initial_state(log: NavLog, tab: dict[str, NDArray], n_bias: int,
                  opts: dict[str, Any]) -> tuple[NDArray, NDArray]:
    """x0/P0 from the pose prior (else the first GNSS fix and compass heading); velocity from
    ``meta["initial_velocity"]`` when the log knows it (the paper's known initial state), else zero."""
    prior = log.pose_prior()
    z0 = tab["z"][~np.isnan(tab["z"][:, 0])]
    h0 = tab["z"][~np.isnan(tab["z"][:, 2])]
    if prior is not None:
        p, yaw, sp, sy = (prior.x, prior.y), prior.yaw, prior.sigma_xy, prior.sigma_yaw
    else:
        p = tuple(z0[0, :2]) if len(z0) else (0.0, 0.0)
        yaw = float(h0[0, 2]) if len(h0) else 0.0
        sp, sy = TABLE2["r_gps_y"], math.radians(10.0)
    v0 = log.meta.get("initial_velocity")
    v, sv = ((float(v0[0]), float(v0[1])), opts["sigma_v0"]) if v0 is not None else ((0.0, 0.0), 2.0)
    x = [p[0], p[1], v[0], v[1], yaw] + [0.0] * n_bias
    d = [sp * sp, sp * sp, sv * sv, sv * sv, sy * sy]
    if n_bias:
        d += [opts["sigma_bias_acc"] ** 2] * 2 + [math.radians(opts["sigma_bias_gyro_deg"]) ** 2]
    return np.array(x), np.diag(d)


DEFAULTS: dict[str, Any] = {
    **TABLE2, "alpha": 0.5, "beta": 2.0, "kappa": 0.0, "sigma_v0": 0.2,
    **GATING_DEFAULTS,  # the innovation gate (gating.py)
    # ukf-bias only: prior on the residual bias after calibration, and its random walk
    "sigma_bias_acc": 0.01, "sigma_bias_gyro_deg": 0.1, "q_bias_acc": 1e-5, "q_bias_gyro_deg": 1e-4,
}


def run_nav_filter(log: NavLog, name: str, *, bias: bool = False, adapter: Adapter | None = None,
                   on_estimate: OnEstimate | None = None, options: dict[str, Any] | None = None) -> RunResult:
    """Run the UKF over the log: predict with each IMU record, update with the GNSS/compass at that time."""
    opts = {**DEFAULTS, **(options or {})}
    unknown = set(opts) - set(DEFAULTS)
    if unknown:
        raise ValueError(f"unknown {name} option(s): {sorted(unknown)}")
    tab = measurement_table(log)
    x0, P0 = initial_state(log, tab, 3 if bias else 0, opts)
    f = UnscentedNav(x0, P0, q_acc=opts["q_acc"], q_gyro=math.radians(opts["q_gyro_deg"]),
                     q_bias_acc=opts["q_bias_acc"], q_bias_gyro=math.radians(opts["q_bias_gyro_deg"]),
                     alpha=opts["alpha"], beta=opts["beta"], kappa=opts["kappa"])
    r0 = np.array([opts["r_gps_x"], opts["r_gps_y"], math.radians(opts["r_com_deg"])]) ** 2
    gater = InnovationGate(**{k: opts[k] for k in GATING_DEFAULTS})
    r_gate = getattr(adapter, "r_current", None)  # an adaptive R: gate with the one it holds now
    inflation = getattr(adapter, "inflation", None)
    t, z = tab["t"], tab["z"]
    n = len(t)
    poses = np.empty((n, 3))
    cov = np.empty((n, 3, 3))
    states = np.empty((n, f.n))
    r_used = np.full((n, 3), np.nan)
    step_ms = np.empty(n - 1)
    pidx = np.array([0, 1, 4])
    pix = np.ix_(pidx, pidx)
    has = ~np.isnan(z)
    all_idx = np.array([0, 1, 4])
    sel = {}
    for k in range(n):
        t0 = time.perf_counter()
        if k:
            f.predict(tab["ax"][k], tab["ay"][k], tab["wz"][k], t[k] - t[k - 1])
        m = has[k]
        if inflation is not None and m.any():
            lam = np.ones(3)
            lam[m] = inflation(np.flatnonzero(m), f.P[pidx, pidx][m])
            if np.any(lam > 1.0):
                f.P = inflate(f.P, lam)
        if m.any() and gater.gate is not None:
            m = _gated(f, gater, float(t[k]), z[k], m, r_gate(np.flatnonzero(m)) if r_gate else r0[m])
        if m.any():
            key = (m[0], m[1], m[2])
            if key not in sel:
                ch_ = slice(0, 3) if m.all() else np.flatnonzero(m)  # basic slicing is cheaper
                sel[key] = (all_idx[m], ch_, np.ix_(all_idx[m], all_idx[m]))
            idx, ch, ix = sel[key]
            eps, HPH = f.innovation(idx, z[k, ch], ix)
            R = adapter(k, ch, eps, HPH, r0[ch]) if adapter is not None else r0[ch]
            r_used[k, ch] = R
            f.update(idx, eps, HPH, np.diag(R))
        if k:
            step_ms[k - 1] = (time.perf_counter() - t0) * 1e3
        poses[k] = f.x[pidx]
        cov[k] = f.P[pix]
        states[k] = f.x
        if on_estimate is not None:
            on_estimate(float(t[k]), poses[k].copy(), cov[k].copy())
    traj = Trajectory(t, poses, cov, name=name)
    info: dict[str, Any] = {"options": {k: opts[k] for k in sorted(opts)}, "state_final": f.x.tolist(),
                            "r_used": r_used, "velocity": states[:, 2:4], **gater.info()}
    if bias:
        info["bias_final"] = f.x[5:].tolist()
    return RunResult(traj, traj, step_ms, info=info)


_STATE = np.array([0, 1, 4])  # x, y, theta: the state entries of the GNSS x, GNSS y and compass channels


def _gated(f: UnscentedNav, gater: InnovationGate, t: float, z: NDArray, m: NDArray, r_rows: NDArray) -> NDArray:
    """Gate the GNSS (channels 0-1) and compass (2) measurements of one step separately; returns the
    channels to update with. A re-initialised block is set here (not updated)."""
    m = m.copy()
    r = dict(zip(np.flatnonzero(m).tolist(), np.asarray(r_rows, dtype=float).tolist(), strict=True))
    for sensor, ch, angle in (("gnss", [0, 1], False), ("heading", [2], True)):
        if not m[ch].all():
            continue
        idx = _STATE[ch]
        eps, HPH = f.innovation(idx, z[ch])
        R = np.diag([r[c] for c in ch])
        verdict = gater.test(sensor, t, eps, HPH, R, angle=angle)
        if verdict != "accept":
            m[ch] = False
        if verdict == "reinit":
            zz = z[ch].astype(float)
            if angle:
                zz = wrap_angle(zz)
            reinit_block(f.x, f.P, idx, zz, R * gater.scale(sensor))
    return m


def unmet(log: NavLog) -> str | None:
    c = log.counts()
    if c.get("imu", 0) < 1:
        return "needs imu records"
    if not (c.get("gnss", 0) or c.get("heading", 0)):
        return "needs gnss or heading records"
    return None


def run_ukf(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    return run_nav_filter(log, "ukf", on_estimate=on_estimate, options=options)


def run_ukf_bias(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    return run_nav_filter(log, "ukf-bias", bias=True, on_estimate=on_estimate, options=options)


def inputs(log: NavLog, options: dict) -> set[str]:
    """The kinds :func:`run_nav_filter` reads: IMU (prediction), GNSS and compass (updates), the pose prior."""
    return {"imu", "gnss", "heading", "pose_prior"}


ESTIMATORS = {
    "ukf": EstimatorSpec(run_ukf, unmet, "conventional UKF, IMU-driven, GNSS + compass (Liu 2019)", "filter",
                         inputs),
    "ukf-bias": EstimatorSpec(run_ukf_bias, unmet, "UKF with accelerometer/gyro bias states", "filter", inputs),
}
