"""The conventional UKF of Liu, Liu & Bucknall (IEEE Access 2019), and a bias-augmented variant.

State (eq. 11) ``x = [p_x, p_y, v_x, v_y, theta]`` (``ukf-bias`` appends the accelerometer and gyro
biases ``[b_ax, b_ay, b_g]``; the water current ``[c_x, c_y]`` follows with ``current``, then the speed
log's scale ``k`` with ``log_scale`` (the speed through water along the bow is ``k`` x the reading; prior
N(1, ``sigma_log_scale^2``), random walk ``q_log_scale``: the graph's scale state; it needs the current
states), and the compass bias ``b_c`` comes last with ``compass_bias``: the compass reads ``theta + b_c``,
b_c a random walk, the graph's compass model, :class:`graphnav.graph.smoother_config.CompassConfig`).
Inputs: the body-frame IMU acceleration rotated into the navigation frame by the heading (eq. 4) and the
gyro yaw rate; dynamics eq. 1-3 / 12 with the sample time T::

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
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import option
from ..geometry import wrap_angle
from ..graph.speed_log import ZeroReadings, through_water_rows
from ..log import NavLog
from ..result import OnEstimate, RunResult
from ..trajectory import Trajectory
from . import _ukf_fast
from .base import BatchEstimator
from .gating import GATING_DEFAULTS, GateOptions, InnovationGate, reinit_block
from .imu_model import compass_bias_model, imu_noise, resolve_flag, wants_bias, yaw_from_compass

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
    """The appendix UKF for the USV model; ``n_bias = 3`` adds accelerometer/gyro bias states,
    ``current=True`` the water current ``[c_x, c_y]`` (a random walk) after them, ``log_scale=True`` the
    speed log's scale ``k`` after the current (``q_log_scale`` its random walk [1/sqrt(s)]),
    ``compass_bias=True`` the compass bias last (the compass channel measures ``theta + b_c``;
    ``q_compass_bias`` its random walk [rad/sqrt(s)])."""

    TH = 4  # index of theta

    def __init__(self, x0: NDArray, P0: NDArray, *, q_acc: float, q_gyro: float,
                 q_bias_acc: float = 0.0, q_bias_gyro: float = 0.0, current: bool = False, q_current: float = 0.0,
                 compass_bias: bool = False, q_compass_bias: float = 0.0, log_scale: bool = False,
                 q_log_scale: float = 0.0, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> None:
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.n = n = self.x.shape[0]
        if log_scale and not current:
            raise ValueError("the speed log's scale state needs the current states")
        nb = n - 5 - 2 * bool(current) - bool(log_scale) - bool(compass_bias)
        if nb not in (0, 3):
            raise ValueError("state must have 5 or 8 entries (+2 with the current, +1 with the log's scale, +1 with "
                             "the compass bias)")
        self.bias = nb == 3
        self.ib = 5 if self.bias else None  # first bias index
        self.ic = 5 + nb if current else None  # first current index
        self.il = 7 + nb if log_scale else None  # the speed log's scale, after the current
        self.ik = n - 1 if compass_bias else None  # the compass bias
        self.q_compass = float(q_compass_bias)
        self.q_log = float(q_log_scale)
        self.wm, self.wc, self.lam = merwe_weights(n, alpha, beta, kappa)
        self.q_acc, self.q_gyro = q_acc, q_gyro
        self.q_bias = np.array([q_bias_acc, q_bias_acc, q_bias_gyro]) ** 2
        self.q_current = q_current
        self._Q_T = None
        self.P_pred = self.P.copy()
        self.spans = _ukf_fast.COMPILED  # predict_span compiled (else the filter steps one sample at a time)

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
                Q[5:8, 5:8] = np.diag(self.q_bias * T)
            if self.ic is not None:
                Q[self.ic, self.ic] = Q[self.ic + 1, self.ic + 1] = self.q_current ** 2 * T
            if self.il is not None:
                Q[self.il, self.il] = self.q_log ** 2 * T
            if self.ik is not None:
                Q[self.ik, self.ik] = self.q_compass ** 2 * T
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

    def predict_span(self, tab: dict[str, NDArray], k0: int, k1: int, poses: NDArray, cov: NDArray,
                     states: NDArray) -> None:
        """:meth:`predict` with the IMU samples ``k0 .. k1-1`` of :func:`measurement_table`'s ``tab`` in one
        compiled call (:func:`graphnav.estimators._ukf_fast.predict_span`), each step's pose, its covariance
        and the state written to row ``k`` of ``poses``, ``cov``, ``states``."""
        x, P = self.x.copy(), self.P.copy()
        _ukf_fast.predict_span(x, P, self.lam, self.wm, self.wc, self.q_acc, self.q_gyro, self.q_bias,
                               self.q_current, self.ib if self.ib is not None else -1,
                               self.ic if self.ic is not None else -1, self.ik if self.ik is not None else -1,
                               self.q_compass, self.il if self.il is not None else -1, self.q_log,
                               tab["ax"], tab["ay"], tab["wz"], tab["t"], k0, k1, poses, cov, states)
        self.x, self.P = x, P
        self.P_pred = P

    def _H(self, idx: NDArray) -> NDArray | None:
        """H of the rows ``idx`` when the compass is one of them and reads ``theta + b_c``; else None (H picks)."""
        if self.ik is None or idx[-1] != 4:
            return None
        H = np.zeros((len(idx), self.n))
        H[np.arange(len(idx)), idx] = 1.0
        H[-1, self.ik] = 1.0
        return H

    def channel_var(self) -> NDArray:
        """``diag(H P^- H^T)`` of the GNSS x, GNSS y and compass channels."""
        d = self.P[_STATE, _STATE]
        if self.ik is not None:
            d = d.copy()
            d[2] += 2.0 * self.P[4, self.ik] + self.P[self.ik, self.ik]
        return d

    def innovation(self, idx: NDArray, z: NDArray, ix: tuple | None = None) -> tuple[NDArray, NDArray]:
        """``eps = z - H x^-`` (eq. 14, heading wrapped) and ``H P^- H^T`` for the rows ``idx`` of eq. 13
        (``ix`` = ``np.ix_(idx, idx)``, precomputed by callers in a loop; with the compass bias the compass
        row of H also picks ``b_c``)."""
        H = self._H(idx)
        if H is not None:
            eps = z - H @ self.x
            eps[-1] = wrap_angle(eps[-1])
            return eps, H @ self.P @ H.T
        eps = z - self.x[idx]
        if idx[-1] == 4:
            eps[-1] = wrap_angle(eps[-1])
        return eps, self.P[ix if ix is not None else np.ix_(idx, idx)]

    def update(self, idx: NDArray, eps: NDArray, HPH: NDArray, R: NDArray) -> None:
        """Step 2 of the appendix: ``K = P^- H^T (H P^- H^T + R)^-1``, ``x += K eps``, ``P = (I-KH) P^-``."""
        S = HPH + R
        H = self._H(idx)
        PHt = self.P[:, idx] if H is None else self.P @ H.T
        K = PHt @ np.linalg.inv(S)
        self.x = self.x + K @ eps
        self.x[4] = wrap_angle(self.x[4])
        P = self.P - K @ PHt.T
        self.P = 0.5 * (P + P.T)

    def water_speed_innovation(self, v: float) -> tuple[NDArray, NDArray, NDArray]:
        """Unscented transform of the speed through water along the bow,
        ``h(x) = (v_x - c_x) cos(theta) + (v_y - c_y) sin(theta)`` (current states required):
        ``(eps (1,), P_zz without R (1, 1), P_xz (n, 1))``. With the scale state the log reads ``h(x) / k``
        (the EKF's model, :mod:`graphnav.estimators.ins_ekf`, which says why not ``h(x) = k v``)."""
        if self.ic is None:
            raise ValueError("a water-speed update needs the current states")
        X = sigma_points(self.x, self.P, self.lam)
        th = X[:, 4]
        Z = (X[:, 2] - X[:, self.ic]) * np.cos(th) + (X[:, 3] - X[:, self.ic + 1]) * np.sin(th)
        if self.il is not None:
            Z = Z / X[:, self.il]
        zm = float(self.wm @ Z)
        dz = Z - zm
        D = X - self.x
        D[:, 4] = wrap_angle(D[:, 4])
        pzz = float(self.wc @ (dz * dz))
        pxz = (D.T * self.wc) @ dz
        return np.array([v - zm]), np.array([[pzz]]), pxz[:, None]

    def water_zero_innovation(self) -> tuple[NDArray, NDArray, NDArray]:
        """A zero reading of a stalled log (:mod:`graphnav.graph.speed_log`): the velocity through the water
        ``R(theta)^T (v - c) = (0, 0)`` along and across the bow, linear in ``(v, c)`` about the estimated bow
        (the scale's and the heading's columns zero, as the EKF's ``InsEkf.update_water_zero``): ``(eps (2,),
        H P H^T (2, 2), P H^T (n, 2))`` for :meth:`update_nonlinear`."""
        if self.ic is None:
            raise ValueError("a water-speed update needs the current states")
        H = through_water_rows(self.n, float(self.x[4]), 2, self.ic)
        PHt = self.P @ H.T
        return -H @ self.x, H @ PHt, PHt


    def update_nonlinear(self, eps: NDArray, Pzz: NDArray, Pxz: NDArray, R: NDArray) -> None:
        """The unscented Kalman update ``K = P_xz (P_zz + R)^-1``, ``P -= K S K^T``."""
        S = Pzz + R
        K = Pxz @ np.linalg.inv(S)
        self.x = self.x + K @ eps
        self.x[4] = wrap_angle(self.x[4])
        P = self.P - K @ S @ K.T
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


#: measurement channels of :func:`measurement_table`: GNSS x, y [m], compass [rad], GNSS velocity
#: east, north [m/s], speed through water [m/s]
CHANNELS = ("gnss_x", "gnss_y", "heading", "gnss_vx", "gnss_vy", "water_speed")
_SOURCES = (("gnss", ("x", "y"), "sigma", 0), ("heading", ("yaw",), "sigma", 2),
            ("gnss_velocity", ("vx", "vy"), "sigma", 3), ("water_speed", ("v",), "sigma_v", 5))


def measurement_table(log: NavLog) -> dict[str, NDArray]:
    """Filter timeline (start + IMU times) and the measurements attached to each step: ``z`` (n, 6)
    values and ``r`` (n, 6) the records' variances (NaN: none there, or no sigma given), channels
    :data:`CHANNELS`; a record attaches to the nearest step within half an IMU interval."""
    imu = log.columns("imu")
    if len(imu["t"]) < 1:
        raise ValueError("needs imu records")
    ti = imu["t"]
    dt0 = float(np.median(np.diff(ti))) if len(ti) > 1 else 1.0
    t = np.concatenate([[ti[0] - dt0], ti])
    n = len(t)
    z = np.full((n, len(CHANNELS)), np.nan)
    r = np.full((n, len(CHANNELS)), np.nan)
    for kind, cols, sig, j0 in _SOURCES:
        c = log.columns(kind)
        if not len(c["t"]):
            continue
        k = np.clip(np.searchsorted(t, c["t"]), 0, n - 1)
        km = np.clip(k - 1, 0, n - 1)
        k = np.where(np.abs(t[km] - c["t"]) < np.abs(t[k] - c["t"]), km, k)
        ok = np.abs(t[k] - c["t"]) <= 0.5 * dt0
        for j, name in enumerate(cols):
            z[k[ok], j0 + j] = c[name][ok]
            r[k[ok], j0 + j] = np.asarray(c[sig], dtype=float)[ok] ** 2
    return {"t": t, "ax": np.concatenate([[0.0], imu["ax"]]), "ay": np.concatenate([[0.0], imu["ay"]]),
            "wz": np.concatenate([[0.0], imu["wz"]]), "z": z, "r": r}


def channel_variances(tab: dict[str, NDArray], opts: dict[str, Any]) -> NDArray:
    """(n, 6) measurement variances per step: the records' sigmas (docs/ekf.md: the graph's sensor
    model), where an option overrides them (``r_gps_x``, ``r_gps_y`` [m], ``r_com_deg`` [deg]: Table 2's
    values reproduce the paper) or a record gives none (``sigma_gnss_velocity``, ``sigma_water_speed``)."""
    r = tab["r"].copy()
    for j, key, scale in ((0, "r_gps_x", 1.0), (1, "r_gps_y", 1.0), (2, "r_com_deg", math.pi / 180)):
        if opts.get(key) is not None:
            r[:, j] = (float(opts[key]) * scale) ** 2
    for cols, key in (((3, 4), "sigma_gnss_velocity"), ((5,), "sigma_water_speed")):
        for j in cols:
            r[:, j] = np.where(np.isfinite(r[:, j]) & (r[:, j] > 0), r[:, j], float(opts[key]) ** 2)
    z = tab["z"]
    return np.where(np.isnan(z), np.nan, r)


def initial_state(log: NavLog, tab: dict[str, NDArray], n_bias: int,
                  opts: dict[str, Any], current: bool = False, compass_bias: float | None = None,
                  log_scale: bool = False) -> tuple[NDArray, NDArray]:
    """x0/P0 from the pose prior (else the first GNSS fix and compass heading, with their sigmas);
    velocity from ``meta["initial_velocity"]`` when the log knows it (the paper's known initial state),
    else the GNSS velocity at the first step when there is one, else zero (2 m/s); the current (if
    estimated) zero with ``sigma_current0``; the log's scale (``log_scale``) 1 with ``sigma_log_scale``; the
    compass bias (``compass_bias``: its prior sigma [rad]) zero, and a heading taken from the compass is that
    reading less the bias (correlated -1)."""
    prior = log.pose_prior()
    z, r = tab["z"], channel_variances(tab, opts)
    i0 = np.flatnonzero(~np.isnan(z[:, 0]))
    h0 = np.flatnonzero(~np.isnan(z[:, 2]))
    if prior is not None:
        p, yaw, sp, sy = (prior.x, prior.y), prior.yaw, prior.sigma_xy, prior.sigma_yaw
    else:
        p = tuple(z[i0[0], :2]) if len(i0) else (0.0, 0.0)
        sp = math.sqrt(float(np.max(r[i0[0], :2]))) if len(i0) else TABLE2["r_gps_y"]
        yaw = float(z[h0[0], 2]) if len(h0) else 0.0
        sy = max(math.sqrt(float(r[h0[0], 2])), math.radians(10.0)) if len(h0) else math.pi
    v0 = log.meta.get("initial_velocity")
    iv = np.flatnonzero(~np.isnan(z[:, 3]) & ~np.isnan(z[:, 4]))
    if v0 is not None:
        v, sv = (float(v0[0]), float(v0[1])), opts["sigma_v0"]
    elif len(iv) and iv[0] <= 1:
        v, sv = (float(z[iv[0], 3]), float(z[iv[0], 4])), 3.0 * math.sqrt(float(np.max(r[iv[0], 3:5])))
    else:
        v, sv = (0.0, 0.0), 2.0
    x = [p[0], p[1], v[0], v[1], yaw] + [0.0] * n_bias
    d = [sp * sp, sp * sp, sv * sv, sv * sv, sy * sy]
    if n_bias:
        d += [opts["sigma_bias_acc"] ** 2] * 2 + [math.radians(opts["sigma_bias_gyro_deg"]) ** 2]
    if current:
        x += [0.0, 0.0]
        d += [opts["sigma_current0"] ** 2] * 2
    if log_scale:
        x += [1.0]
        d += [opts["sigma_log_scale"] ** 2]
    if compass_bias is None:
        return np.array(x), np.diag(d)
    P = np.diag([*d, compass_bias ** 2])
    if prior is None and len(h0):
        yaw_from_compass(P, 4, compass_bias)
    return np.array([*x, 0.0]), P


@dataclass
class UkfOptions(GateOptions):
    """The UKF's options (:func:`run_nav_filter`) and its innovation gate's."""

    group: ClassVar[str] = "ukf"
    # measurement noise: null = the records' sigmas
    r_gps_x: float | None = option(None, "GNSS x sigma (null: the records'; Table 2: 6)", unit="m")
    r_gps_y: float | None = option(None, "GNSS y sigma (null: the records'; Table 2: 7)", unit="m")
    r_com_deg: float | None = option(None, "compass sigma (null: the records'; Table 2: 0.5)", unit="deg")
    sigma_gnss_velocity: float = option(0.1, "GNSS velocity sigma when the record gives none", unit="m/s")
    sigma_water_speed: float = option(0.1, "water-speed sigma when the record gives none", unit="m/s")
    stall_speed: float | None = option(None, "a zero water-speed reading (a stalled paddle wheel) says only that the "
                                       "speed through water is below this: censored, with this / sqrt(3) added to "
                                       "both sigmas, no scale (null: the smallest non-zero reading so far; before "
                                       "one a zero is not used; the graph's [water] stall_speed)", unit="m/s")
    q_acc: float | None = option(None, "IMU acceleration noise per sample (null: meta['imu'] acc_std, else Table "
                                 "2's 0.0039)", unit="m/s^2")
    q_gyro_deg: float | None = option(None, "IMU yaw-rate noise per sample (null: meta['imu'] gyro_std, else "
                                      "Table 2's 0.033)", unit="deg/s")
    alpha: float = option(0.5, "sigma-point spread (Merwe weights)")
    beta: float = option(2.0, "sigma-point weight of the prior (2: Gaussian)")
    kappa: float = option(0.0, "secondary sigma-point spread")
    sigma_v0: float = option(0.2, "prior 1-sigma of the initial velocity", unit="m/s")
    sigma_bias_acc: float = option(0.01, "bias states: prior on the residual accelerometer bias", unit="m/s^2")
    sigma_bias_gyro_deg: float = option(0.1, "bias states: prior on the residual gyro bias", unit="deg/s")
    q_bias_acc: float | None = option(None, "bias states: accelerometer bias random walk (null: the log's "
                                      "meta['imu'])", unit="m/s^2/sqrt(s)")
    q_bias_gyro_deg: float | None = option(None, "bias states: gyro bias random walk (null: the log's meta['imu'])",
                                           unit="deg/s/sqrt(s)")
    current: bool | str = option("auto", "water-current states: auto (when the log has water_speed), true, false")
    sigma_current0: float = option(0.5, "prior 1-sigma of the water current", unit="m/s")
    q_current: float = option(0.005, "water-current random walk", unit="m/s/sqrt(s)")
    log_scale: bool | str = option(
        "auto", "the speed log's scale state k (the speed through water along the bow is k x the reading; the "
        "graph's): auto (with the current states, when the log has water_speed), true, false")
    sigma_log_scale: float = option(0.1, "prior 1-sigma of the speed log's scale (around 1: a log within 10 %)")
    q_log_scale: float = option(5e-4, "the speed log's scale: random walk", unit="1/sqrt(s)")
    compass_bias: bool | str = option(
        "auto", "a compass-bias state (the compass reads theta + b; the graph's prior [compass] bias_sigma_deg and "
        "random walk bias_drift_deg): auto (when the log has compass and GNSS position or velocity, which hold "
        "the heading through the IMU's integrated acceleration), true, false")


DEFAULTS: dict[str, Any] = {f.name: f.default for f in fields(UkfOptions)}
"""The UKF's options and their defaults (:class:`UkfOptions`)."""


def _noise(log: NavLog, opts: dict[str, Any]) -> dict[str, float]:
    """The process noise in force: options over the log's IMU model (:func:`imu_noise`)."""
    m = imu_noise(log)
    return {"q_acc": m["acc_std"] if opts["q_acc"] is None else float(opts["q_acc"]),
            "q_gyro": m["gyro_std"] if opts["q_gyro_deg"] is None else math.radians(opts["q_gyro_deg"]),
            "q_bias_acc": m["acc_bias_rw"] if opts["q_bias_acc"] is None else float(opts["q_bias_acc"]),
            "q_bias_gyro": (m["gyro_bias_rw"] if opts["q_bias_gyro_deg"] is None
                            else math.radians(opts["q_bias_gyro_deg"])),
            "source": m["source"]}


def run_nav_filter(log: NavLog, name: str, *, bias: bool | str = False, adapter: Adapter | None = None,
                   on_estimate: OnEstimate | None = None, options: dict[str, Any] | None = None) -> RunResult:
    """Run the UKF over the log: predict with each IMU record, update with the GNSS/compass at that
    time, then the GNSS velocity and (with the current states) the speed through water.
    ``bias``: ``"auto"`` (:func:`graphnav.estimators.imu_model.wants_bias`), true or false."""
    opts = {**DEFAULTS, **(options or {})}
    unknown = set(opts) - set(DEFAULTS)
    if unknown:
        raise ValueError(f"unknown {name} option(s): {sorted(unknown)}")
    auto_bias, bias_why = wants_bias(log)
    bias = resolve_flag(bias, auto_bias, "bias")
    tab = measurement_table(log)
    water = bool(np.any(~np.isnan(tab["z"][:, 5])))
    current = resolve_flag(opts["current"], water, "current")
    ls = resolve_flag(opts["log_scale"], current and water, "log_scale")
    if ls and not current:
        raise ValueError(f"{name} option log_scale needs the current states (current=true)")
    seen = ~np.isnan(tab["z"])
    cb = resolve_flag(opts["compass_bias"], bool(seen[:, 2].any() and seen[:, [0, 1, 3, 4]].any()), "compass_bias")
    kb0, kbrw = compass_bias_model()
    x0, P0 = initial_state(log, tab, 3 if bias else 0, opts, current, kb0 if cb else None, ls)
    qn = _noise(log, opts)
    f = UnscentedNav(x0, P0, q_acc=qn["q_acc"], q_gyro=qn["q_gyro"],
                     q_bias_acc=qn["q_bias_acc"], q_bias_gyro=qn["q_bias_gyro"],
                     current=current, q_current=float(opts["q_current"]), compass_bias=cb, q_compass_bias=kbrw,
                     log_scale=ls, q_log_scale=float(opts["q_log_scale"]),
                     alpha=opts["alpha"], beta=opts["beta"], kappa=opts["kappa"])
    gater = InnovationGate(**{k: opts[k] for k in GATING_DEFAULTS})
    step = _Updates(f, gater, tab, channel_variances(tab, opts), adapter, current, opts["stall_speed"])
    t = tab["t"]
    n = len(t)
    poses = np.empty((n, 3))
    cov = np.empty((n, 3, 3))
    states = np.empty((n, f.n))
    step_ms = np.empty(n - 1)
    pidx = np.array([0, 1, 4])
    pix = np.ix_(pidx, pidx)
    has = step.has
    quiet = ~has.any(axis=1)  # steps with nothing to update: predicted in spans (UnscentedNav.predict_span)
    loud = np.append(np.flatnonzero(~quiet), n)
    k = 0
    while k < n:
        t0 = time.perf_counter()
        if k and quiet[k] and f.spans:
            k1 = int(loud[np.searchsorted(loud, k)])
            f.predict_span(tab, k, k1, poses, cov, states)
            step_ms[k - 1:k1 - 1] = (time.perf_counter() - t0) * 1e3 / (k1 - k)
            if on_estimate is not None:
                for j in range(k, k1):
                    on_estimate(float(t[j]), poses[j].copy(), cov[j].copy())
            k = k1
            continue
        if k:
            f.predict(tab["ax"][k], tab["ay"][k], tab["wz"][k], t[k] - t[k - 1])
        step.measure(k)
        if k:
            step_ms[k - 1] = (time.perf_counter() - t0) * 1e3
        poses[k] = f.x[pidx]
        cov[k] = f.P[pix]
        states[k] = f.x
        if on_estimate is not None:
            on_estimate(float(t[k]), poses[k].copy(), cov[k].copy())
        k += 1
    traj = Trajectory(t, poses, cov, name=name)
    info: dict[str, Any] = {"options": {k: opts[k] for k in sorted(opts)}, "state_final": f.x.tolist(),
                            "r_used": step.r_used, "velocity": states[:, 2:4], **gater.info(),
                            "bias_states": bias, "bias_reason": bias_why if bias == auto_bias else "option",
                            "current_states": current, "process_noise": dict(qn), **step.zeros.info()}
    _state_info(info, f, states, opts)
    return RunResult(traj, traj, step_ms, info=info)


def _state_info(info: dict[str, Any], f: UnscentedNav, states: NDArray, opts: dict[str, Any]) -> None:
    """:func:`run_nav_filter`'s ``info`` (in place) on the augmented states: the final biases, current, speed-log
    scale (with its sigma; its walk in ``process_noise``) and compass bias, the last three also per step
    (``states``: the state at each step)."""
    if f.bias:
        info["bias_final"] = f.x[5:8].tolist()
    if f.ic is not None:
        info["current_final"] = f.x[f.ic:f.ic + 2].tolist()
        info["current"] = states[:, f.ic:f.ic + 2]
    info["log_scale_state"] = f.il is not None
    if f.il is not None:
        info["process_noise"]["q_log_scale"] = float(opts["q_log_scale"])
        info["log_scale_final"] = float(f.x[f.il])
        info["log_scale_sigma"] = math.sqrt(float(f.P[f.il, f.il]))
        info["log_scale"] = states[:, f.il]
    info["compass_bias_state"] = f.ik is not None
    if f.ik is not None:
        info["compass_bias_final_deg"] = math.degrees(float(f.x[f.ik]))
        info["compass_bias_sigma_deg"] = math.degrees(math.sqrt(float(f.P[f.ik, f.ik])))
        info["compass_bias"] = states[:, f.ik]


class _Updates:
    """The measurement updates of one filter step (:func:`run_nav_filter`): the GNSS position and compass
    (inflated by an adaptive filter's factor, gated, with an adapter's R), then the velocities."""

    def __init__(self, f: UnscentedNav, gater: InnovationGate, tab: dict[str, NDArray], rk: NDArray,
                 adapter: Adapter | None, current: bool, stall_speed: float | None = None) -> None:
        from ..graph.smoother_config import WaterConfig

        self.f, self.gater, self.adapter, self.current = f, gater, adapter, current
        self.zeros = ZeroReadings(stall_speed)  # the speed log's zero readings (graph.speed_log)
        self.leeway0 = WaterConfig().leeway_sigma(0.0)  # [m/s] across the bow at rest: the graph's
        self.t, self.z, self.rk = tab["t"], tab["z"], rk
        self.has = ~np.isnan(self.z)
        self.r_gate = getattr(adapter, "r_current", None)  # an adaptive R: gate with the one it holds now
        self.inflation = getattr(adapter, "inflation", None)
        self.r_used = np.full((len(self.t), 3), np.nan)
        self.sel: dict[tuple, tuple] = {}

    def measure(self, k: int) -> None:
        """Every update of step ``k``."""
        f, gater, z, t = self.f, self.gater, self.z, float(self.t[k])
        m = self.has[k, :3]
        r0k = self.rk[k, :3]
        if self.inflation is not None and m.any():
            lam = np.ones(3)
            lam[m] = self.inflation(np.flatnonzero(m), f.channel_var()[m])
            if np.any(lam > 1.0):
                f.P = inflate(f.P, lam)
        if m.any() and gater.gate is not None:
            m = _gated(f, gater, t, z[k], m, self.r_gate(np.flatnonzero(m)) if self.r_gate else r0k[m])
        if m.any():
            key = (m[0], m[1], m[2])
            if key not in self.sel:
                ch_ = slice(0, 3) if m.all() else np.flatnonzero(m)  # basic slicing is cheaper
                self.sel[key] = (_STATE[m], ch_, np.ix_(_STATE[m], _STATE[m]))
            idx, ch, ix = self.sel[key]
            eps, HPH = f.innovation(idx, z[k, ch], ix)
            R = self.adapter(k, ch, eps, HPH, r0k[ch]) if self.adapter is not None else r0k[ch]
            self.r_used[k, ch] = R
            f.update(idx, eps, HPH, np.diag(R))
        _velocity_updates(f, gater, t, z[k], self.rk[k], self.has[k])
        if self.current and self.has[k, 5]:
            self.water_speed(t, float(z[k, 5]), float(self.rk[k, 5]))

    def water_speed(self, t: float, v: float, r: float) -> None:
        """The speed through water ``v`` (variance ``r``): (v - c) along the bow, unscented; a zero reading censored
        below the log's stall speed (:mod:`graphnav.graph.speed_log`; not used before one is known)."""
        f, how = self.f, self.zeros.see(v)
        if how == "plain":
            eps, Pzz, Pxz = f.water_speed_innovation(v)
            R = np.array([[r]])
        elif how == "censored":
            eps, Pzz, Pxz = f.water_zero_innovation()
            R = np.diag(np.square(self.zeros.sigmas(math.sqrt(r), self.leeway0)))
        else:
            return
        if self.gater.test("water_speed" if how == "plain" else "water_speed_zero", t, eps, Pzz, R) != "reject":
            f.update_nonlinear(eps, Pzz, Pxz, R)


def _velocity_updates(f: UnscentedNav, gater: InnovationGate, t: float, zk: NDArray, rkk: NDArray,
                      hk: NDArray) -> None:
    """The GNSS velocity over ground after the pose's updates at one time (H picks v_x, v_y); the speed through
    water follows (:meth:`_Updates.water_speed`)."""
    if hk[3] and hk[4]:
        vidx = _VELOCITY
        eps, HPH = f.innovation(vidx, zk[3:5])
        R = np.diag(rkk[3:5])
        verdict = gater.test("gnss_velocity", t, eps, HPH, R)
        if verdict == "accept":
            f.update(vidx, eps, HPH, R)
        elif verdict == "reinit":
            reinit_block(f.x, f.P, vidx, zk[3:5].astype(float), R * gater.scale("gnss_velocity"))


_VELOCITY = np.array([2, 3])  # v_x, v_y: the state entries of the GNSS velocity channels


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
        if verdict == "reinit":  # (a biased compass: theta restarts at the reading less the bias, kept)
            zz = z[ch].astype(float)
            if angle:
                zz = wrap_angle(zz - (f.x[f.ik] if f.ik is not None else 0.0))
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
    """The UKF at its best for the log: bias states by default when the IMU has a bias (``bias``:
    ``"auto"``, true, false; false is the paper's conventional 5-state UKF)."""
    options = dict(options)
    bias = options.pop("bias", "auto")
    return run_nav_filter(log, "ukf", bias=bias, on_estimate=on_estimate, options=options)


def run_ukf_bias(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    return run_nav_filter(log, "ukf-bias", bias=True, on_estimate=on_estimate, options=options)


def inputs(log: NavLog, options: dict) -> set[str]:
    """The kinds :func:`run_nav_filter` reads: IMU (prediction), GNSS position and velocity, compass and
    (with the current states, by default whenever the log has it) water speed (updates), the pose prior."""
    kinds = {"imu", "gnss", "gnss_velocity", "heading", "pose_prior"}
    if options.get("current", "auto") not in (False, "false"):
        kinds.add("water_speed")
    return kinds


@dataclass
class UkfConfig(UkfOptions):
    """The ``ukf`` estimator's options."""

    bias: bool | str = option("auto", "IMU bias states: auto (unless meta['imu'] says bias_free), true, false (with "
                              "compass_bias=false: the paper's 5-state UKF)")


class Ukf(BatchEstimator):
    """The UKF at its best for the log (:func:`run_ukf`)."""

    description = "conventional UKF, IMU-driven, GNSS + compass (Liu 2019)"
    Config = UkfConfig
    unmet = staticmethod(unmet)
    inputs = staticmethod(inputs)
    batch = staticmethod(run_ukf)


class UkfBias(Ukf):
    """The UKF with bias states (:func:`run_ukf_bias`)."""

    description = "UKF with accelerometer/gyro bias states"
    Config = UkfOptions
    batch = staticmethod(run_ukf_bias)


ESTIMATORS = {"ukf": Ukf, "ukf-bias": UkfBias}
