"""The IMU error model of a real vessel's IMU at its own rate: the ``solent`` scenario's constant
bias (the fuzzy-UKF paper's Table 3, calibrated to a residual) plus a bias random walk plus white
noise at the datasheet's noise density.

Per channel (ax, ay [m/s^2], wz [rad/s]), sample ``k`` at rate ``hz`` (``T = 1/hz``), the record is
the mean over (t_{k-1}, t_k] of the true body-frame specific force / yaw rate plus

    b + w_k + n_k - b_hat

* ``b``: Table 3's constant bias (0.03, 0.02 m/s^2; 0.28 deg/s); ``b_hat = b - e`` its calibrated
  estimate, ``e ~ N(0, (calib_residual b)^2)`` (default 10 %), as :func:`graphnav.sim.solent.imu_measurements`;
* ``w_k``: a random walk from 0 at the start, ``w_k = w_{k-1} + q sqrt(T) N(0, 1)``, with
  ``q`` = :data:`ACC_BIAS_RW` / :data:`GYRO_BIAS_RW` (per sqrt(s));
* ``n_k``: white, ``N(0, (s sqrt(hz))^2)``, ``s`` the noise density = Table 3's 1-sigma at T = 1 s
  (0.0042 m/s^2/sqrt(Hz), 0.036 deg/s/sqrt(Hz)), so the 1 s means are as noisy as the solent IMU's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .solent import TABLE3_ACC_BIAS, TABLE3_ACC_STD, TABLE3_GYRO_BIAS_DEG, TABLE3_GYRO_STD_DEG

ACC_NOISE_DENSITY = TABLE3_ACC_STD  # m/s^2/sqrt(Hz) (velocity random walk 0.0042 m/s/sqrt(s))
GYRO_NOISE_DENSITY = math.radians(TABLE3_GYRO_STD_DEG)  # rad/s/sqrt(Hz) (angle random walk 2.2 deg/sqrt(h))
ACC_BIAS_RW = 5e-5  # m/s^2/sqrt(s): ~1.2e-3 m/s^2 (120 micro-g) 1-sigma after 10 min
GYRO_BIAS_RW = 1e-5  # rad/s/sqrt(s): ~2.4e-4 rad/s (0.014 deg/s, 50 deg/h) 1-sigma after 10 min


def imu_with_drift(rng: np.random.Generator, t: NDArray[np.float64], acc_b: NDArray[np.float64],
                   rate: NDArray[np.float64], hz: float, *, calibrate: bool = True, calib_residual: float = 0.1,
                   acc_bias_rw: float = ACC_BIAS_RW, gyro_bias_rw: float = GYRO_BIAS_RW,
                   series_every: float = 10.0) -> tuple[NDArray, NDArray, dict[str, Any]]:
    """IMU records at times ``t`` (m,) from the true interval means ``acc_b`` (m, 2) and ``rate`` (m,)
    (the module docstring). Returns the logged ``(acc (m, 2), gyro (m,), meta["imu"])``; the meta
    holds every parameter and ``bias_series``: the bias left in the records (``b - b_hat + w``) about
    every ``series_every`` s. Draws: the calibration residual (3, only when ``calibrate``), then the
    walk increments (m, 3), then the white noise (m, 3)."""
    m = len(rate)
    bias = np.array([*TABLE3_ACC_BIAS, math.radians(TABLE3_GYRO_BIAS_DEG)])
    frac = calib_residual if calibrate else 1.0
    resid = rng.normal(0.0, 1.0, 3) * frac * np.abs(bias) if calibrate else bias.copy()
    b_hat = bias - resid if calibrate else np.zeros(3)
    q = np.array([acc_bias_rw, acc_bias_rw, gyro_bias_rw])
    walk = np.cumsum(rng.normal(0.0, 1.0, (m, 3)) * q * math.sqrt(1.0 / hz), axis=0)
    dens = np.array([ACC_NOISE_DENSITY, ACC_NOISE_DENSITY, GYRO_NOISE_DENSITY])
    white = rng.normal(0.0, 1.0, (m, 3)) * dens * math.sqrt(hz)
    left = resid + walk  # the bias the records carry
    acc = acc_b + left[:, :2] + white[:, :2]
    gyr = rate + left[:, 2] + white[:, 2]
    step = max(int(round(series_every * hz)), 1)
    idx = np.unique(np.append(np.arange(0, m, step), m - 1)) if m else np.arange(0)
    meta = {
        "record_semantics": "mean over (t_{k-1}, t_k], stamped t_k; calibrated (bias estimate removed)",
        "hz": hz,
        "bias_true": bias.tolist(), "bias_estimate": b_hat.tolist(),
        "bias_residual": resid.tolist(), "calib_residual_frac": frac,
        "acc_noise_density": ACC_NOISE_DENSITY, "gyro_noise_density": GYRO_NOISE_DENSITY,
        "acc_std": ACC_NOISE_DENSITY * math.sqrt(hz), "gyro_std": GYRO_NOISE_DENSITY * math.sqrt(hz),
        "acc_bias_rw": acc_bias_rw, "gyro_bias_rw": gyro_bias_rw,
        "bias_series": {"t": t[idx].tolist(), "ax": left[idx, 0].tolist(), "ay": left[idx, 1].tolist(),
                        "wz": left[idx, 2].tolist()},
    }
    return acc, gyr, meta
