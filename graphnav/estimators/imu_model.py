"""The IMU-driven filters' sensor model, read from the log as the graph reads it (docs/ekf.md, *IMU motion*).

* White noise per IMU sample: ``meta["imu"]["acc_std"]`` [m/s^2], ``["gyro_std"]`` [rad/s] at
  ``["hz"]`` (else the median record rate) when the log states them; else the fuzzy-UKF paper's
  Table 2 (0.0039 m/s^2, 0.033 deg/s per 1 s sample).
* Bias random walk: ``meta["imu"]["acc_bias_rw"]`` [m/s^2/sqrt(s)], ``["gyro_bias_rw"]`` [rad/s/sqrt(s)]
  when stated; else 1e-5 m/s^2/sqrt(s), 1e-4 deg/s/sqrt(s).
* Bias states (``bias="auto"``): always, unless ``meta["imu"]["bias_free"]`` is true. Every real
  IMU has a residual bias after calibration (the logs that describe their IMU state it in
  ``meta["imu"]``: ``bias_true``, ``bias_residual``, ``acc_bias_rw``, ...), and without an odometer
  the IMU is the only motion sensor, so the textbook filter estimates it. The choice does not
  depend on other record kinds (dropping odometry does not change the filter). ``bias=false`` (with
  ``compass_bias=false``) is the fuzzy-UKF paper's 5-state conventional UKF.
* Water-current states (``current="auto"``): when the log has ``water_speed`` records.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..log import NavLog

TABLE2_ACC_STD = 0.0039  # m/s^2 per 1 s sample (fuzzy-UKF paper, Table 2 q_1)
TABLE2_GYRO_STD = math.radians(0.033)  # rad/s per 1 s sample (q_2)
DEFAULT_ACC_BIAS_RW = 1e-5  # m/s^2/sqrt(s)
DEFAULT_GYRO_BIAS_RW = math.radians(1e-4)  # rad/s/sqrt(s)
_BIAS_FIELDS = ("bias_true", "bias_residual", "bias_estimate", "acc_bias_rw", "gyro_bias_rw")


def _imu_meta(log: NavLog) -> dict[str, Any]:
    m = log.meta.get("imu") if isinstance(log.meta, dict) else None
    return m if isinstance(m, dict) else {}


def _num(m: dict[str, Any], key: str) -> float | None:
    v = m.get(key)
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) and f >= 0.0 else None


def imu_rate(log: NavLog) -> float:
    """The IMU's sample rate [Hz]: ``meta["imu"]["hz"]``, else the median record interval's inverse (1 Hz
    with fewer than two records)."""
    hz = _num(_imu_meta(log), "hz")
    if hz:
        return hz
    t = log.columns("imu")["t"]
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return 1.0 / dt if dt > 0 else 1.0


def imu_noise(log: NavLog) -> dict[str, Any]:
    """``acc_std``, ``gyro_std`` (per sample), ``hz``, ``acc_bias_rw``, ``gyro_bias_rw`` and ``source``
    ("meta" or "table2") of the log's IMU (module docstring)."""
    m = _imu_meta(log)
    hz = imu_rate(log)
    acc, gyro = _num(m, "acc_std"), _num(m, "gyro_std")
    src = "meta" if acc and gyro else "table2"
    if not (acc and gyro):  # Table 2's 1 s values as noise densities, scaled to the log's rate
        acc, gyro = TABLE2_ACC_STD * math.sqrt(hz), TABLE2_GYRO_STD * math.sqrt(hz)
    return {"acc_std": acc, "gyro_std": gyro, "hz": hz, "source": src,
            "acc_bias_rw": _num(m, "acc_bias_rw") or DEFAULT_ACC_BIAS_RW,
            "gyro_bias_rw": _num(m, "gyro_bias_rw") or DEFAULT_GYRO_BIAS_RW}


def wants_bias(log: NavLog) -> tuple[bool, str]:
    """Whether the IMU filters carry bias states by default, and why (module docstring)."""
    m = _imu_meta(log)
    if m.get("bias_free") is True:
        return False, "meta['imu'] states a bias-free IMU"
    if any(k in m for k in _BIAS_FIELDS):
        return True, "meta['imu'] states a bias"
    return True, "every IMU has a residual bias (the log states none)"


def resolve_flag(value: Any, auto: bool, name: str) -> bool:
    """``"auto"``/``None`` -> ``auto``; a bool (or "true"/"false") as given."""
    if value is None or value == "auto":
        return auto
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.lower() in ("true", "false"):
        return value.lower() == "true"
    raise ValueError(f"{name} must be true, false or 'auto', not {value!r}")


def compass_bias_model() -> tuple[float, float]:
    """The compass bias's prior sigma [rad] and random walk [rad/sqrt(s)]: the graph's
    (:class:`graphnav.graph.smoother_config.CompassConfig` ``bias_sigma_deg``, ``bias_drift_deg``), the same
    sensor model as the smoother's."""
    from ..graph.smoother_config import CompassConfig

    c = CompassConfig()
    return math.radians(c.bias_sigma_deg), math.radians(c.bias_drift_deg)


def yaw_from_compass(P: np.ndarray, iyaw: int, sigma: float) -> None:
    """``P`` (in place) for a start whose yaw (row ``iyaw``) is a compass reading and whose last state is the
    compass bias of prior ``sigma``: yaw = reading - b, so the yaw's variance gains the bias's and the two
    are correlated -1."""
    P[iyaw, iyaw] += sigma ** 2
    P[iyaw, -1] = P[-1, iyaw] = -sigma ** 2
