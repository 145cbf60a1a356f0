"""The UKF's prediction (:meth:`graphnav.estimators.ukf.UnscentedNav.predict`) over a span of IMU samples in
one compiled call: the same arithmetic, step by step (sigma points of ``(n + lambda) P``, eq. 12 per point,
the wrapped weighted mean, ``P = sum W_c D D^T + Q(T)``), without a Python call per 100 Hz sample.

Compiled by numba when importable (:mod:`graphnav.scan._jit`); :data:`COMPILED` says so, and without it the
filter keeps its numpy step (this loop interpreted would be slower than that).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..scan._jit import HAVE_NUMBA, njit

COMPILED = HAVE_NUMBA
_POSE = (0, 1, 4)  # x, y, theta in the state


@njit(cache=True, inline="always")
def _wrap(a: float) -> float:
    """:func:`graphnav.geometry.wrap_angle` of one angle ([-pi, pi), floored modulo)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def process_noise(n: int, T: float, q_acc: float, q_gyro: float, q_bias: NDArray, q_current: float,
                  ib: int, ic: int, ik: int = -1, q_compass: float = 0.0, il: int = -1, q_log: float = 0.0) -> NDArray:
    """``Q(T)`` of :meth:`~graphnav.estimators.ukf.UnscentedNav._Q`: white acceleration on ``(p, v)`` per axis,
    the gyro's noise on the heading, random walks of the biases (``ib >= 0``), the current (``ic >= 0``),
    the compass bias (``ik >= 0``, density ``q_compass`` [rad/sqrt(s)]) and the speed log's scale (``il >= 0``,
    ``q_log`` [1/sqrt(s)])."""
    Q = np.zeros((n, n))
    qa = q_acc * q_acc
    for i in range(2):
        Q[i, i] = qa * T ** 4 / 4.0
        Q[i, i + 2] = qa * T ** 3 / 2.0
        Q[i + 2, i] = Q[i, i + 2]
        Q[i + 2, i + 2] = qa * T * T
    Q[4, 4] = (q_gyro * T) ** 2
    if ib >= 0:
        for j in range(3):
            Q[ib + j, ib + j] = q_bias[j] * T
    if ic >= 0:
        Q[ic, ic] = q_current * q_current * T
        Q[ic + 1, ic + 1] = q_current * q_current * T
    if ik >= 0:
        Q[ik, ik] = q_compass * q_compass * T
    if il >= 0:
        Q[il, il] = q_log * q_log * T
    return Q


@njit(cache=True)
def predict_span(x: NDArray, P: NDArray, lam: float, wm: NDArray, wc: NDArray, q_acc: float, q_gyro: float,
                 q_bias: NDArray, q_current: float, ib: int, ic: int, ik: int, q_compass: float, il: int,
                 q_log: float, ax: NDArray, ay: NDArray, wz: NDArray, t: NDArray, k0: int, k1: int, poses: NDArray,
                 cov: NDArray, states: NDArray) -> None:
    """Predict ``x``, ``P`` (in place) through the steps ``k0 .. k1-1`` (step ``k``: the IMU sample ``k`` over
    ``t[k] - t[k-1]``, ``k0 >= 1``), writing each step's ``(x, y, theta)``, its covariance and the state to
    ``poses[k]``, ``cov[k]``, ``states[k]``. ``ik``, ``q_compass``: the compass-bias state (-1: none) and its
    random walk (it moves with its noise only); ``il``, ``q_log``: the speed log's scale state (-1: none), likewise."""
    n = x.shape[0]
    m2 = 2 * n + 1
    X = np.empty((m2, n))
    T_last = -1.0
    Q = np.zeros((n, n))
    for k in range(k0, k1):
        T = t[k] - t[k - 1]
        if T != T_last:
            Q = process_noise(n, T, q_acc, q_gyro, q_bias, q_current, ib, ic, ik, q_compass, il, q_log)
            T_last = T
        L = np.linalg.cholesky((n + lam) * P)
        for j in range(n):
            X[0, j] = x[j]
            for i in range(n):
                X[1 + i, j] = x[j] + L[j, i]
                X[1 + n + i, j] = x[j] - L[j, i]
        for r in range(m2):  # eq. 12 (eq. 1-3 discretised), eq. 4 for the acceleration
            th = X[r, 4]
            if ib >= 0:
                axb, ayb, w = ax[k] - X[r, ib], ay[k] - X[r, ib + 1], wz[k] - X[r, ib + 2]
            else:
                axb, ayb, w = ax[k], ay[k], wz[k]
            c, s = math.cos(th), math.sin(th)
            anx = c * axb - s * ayb
            any_ = s * axb + c * ayb
            X[r, 0] += T * X[r, 2] + 0.5 * T * T * anx
            X[r, 1] += T * X[r, 3] + 0.5 * T * T * any_
            X[r, 2] += T * anx
            X[r, 3] += T * any_
            X[r, 4] = _wrap(th + T * w)
        ref = X[0, 4]
        dth = 0.0
        for j in range(n):
            x[j] = 0.0
        for r in range(m2):
            for j in range(n):
                x[j] += wm[r] * X[r, j]
            dth += wm[r] * _wrap(X[r, 4] - ref)
        x[4] = _wrap(ref + dth)
        for r in range(m2):  # the deviations, in place
            for j in range(n):
                X[r, j] -= x[j]
            X[r, 4] = _wrap(X[r, 4])
        for i in range(n):
            for j in range(i, n):
                acc = 0.0
                for r in range(m2):
                    acc += wc[r] * X[r, i] * X[r, j]
                P[i, j] = acc + Q[i, j]
                P[j, i] = P[i, j]
        poses[k, 0], poses[k, 1], poses[k, 2] = x[0], x[1], x[4]
        for a in range(3):
            for b in range(3):
                cov[k, a, b] = P[_POSE[a], _POSE[b]]
        states[k, :] = x
