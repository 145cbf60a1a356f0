"""Planar IMU -> GTSAM's native IMU preintegration (``ImuFactor``) and its 3-D companions.

The USV's IMU gives body-frame surge/sway acceleration ``(ax, ay)`` and yaw rate ``wz`` (fuzzy-UKF
paper eq. 5-6, calibrated). They are embedded in 3-D as ``acc = (ax, ay, 0)``, ``omega = (0, 0, wz)``
with **gravity disabled** (``PreintegrationParams.MakeSharedU(0)``): the records are already the
horizontal specific force, so there is nothing to subtract. Between poses ``i`` and ``j`` GTSAM
preintegrates (Forster et al. 2017, eq. 33-38; the continuous form of the paper's eq. 1-4, 12)::

    dR_ij = prod Exp((w - b_g) dt),   dv_ij = sum dR_ik (a - b_a) dt,   dp_ij = sum dv_ik dt + dR_ik (a - b_a) dt^2 / 2

and ``ImuFactor(X_i, V_i, X_j, V_j, B_i)`` ties the ``Pose3``/velocity states to them with the
propagated covariance; biases are ``imuBias.ConstantBias`` states linked by a random-walk
``BetweenFactorConstantBias``.

**Planarity.** Roll, pitch and height are not estimated separately: the measurements are planar
(zero vertical acceleration, zero roll/pitch rate), the first pose has a tight prior on roll, pitch
and z (:func:`initial_state_factors`) and GNSS fixes are 3-D points at z = 0 (:func:`gnss3_factor`).
At roll = pitch = z = 0 every residual's gradient with respect to them vanishes (body deltas have no
z component), so the optimum stays exactly planar; the tests check it. Compass readings are
yaw-only ``PoseRotationPrior3D`` factors (zero precision on roll/pitch).

Noise: ``accelerometerCovariance = sigma_a^2 T`` for records that are means over ``T`` seconds
(so the velocity increment over one record has the 1-sigma ``sigma_a T``), likewise for the gyro.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import gtsam
import numpy as np
from numpy.typing import NDArray

from .robust import robustify


def V(k: int) -> int:
    """Key of the nav-frame velocity at pose ``k``."""
    return gtsam.symbol("v", k)


def IB(k: int) -> int:
    """Key of the IMU bias (``imuBias.ConstantBias``) at pose ``k``."""
    return gtsam.symbol("i", k)


def planar_imu_params(
    acc_sigma: float, gyro_sigma: float, sample_dt: float = 1.0, integration_sigma: float = 1e-4
) -> gtsam.PreintegrationParams:
    """Preintegration parameters, gravity off, for records with white noise ``acc_sigma`` [m/s^2]
    and ``gyro_sigma`` [rad/s] per ``sample_dt`` [s] (continuous densities ``sigma^2 sample_dt``)."""
    p = gtsam.PreintegrationParams.MakeSharedU(0.0)
    p.setAccelerometerCovariance(np.eye(3) * acc_sigma**2 * sample_dt)
    p.setGyroscopeCovariance(np.eye(3) * gyro_sigma**2 * sample_dt)
    p.setIntegrationCovariance(np.eye(3) * integration_sigma**2)
    return p


def bias_vector(b_ax: float = 0.0, b_ay: float = 0.0, b_gz: float = 0.0) -> gtsam.imuBias.ConstantBias:
    """A planar IMU bias: accelerometer (b_ax, b_ay, 0), gyro (0, 0, b_gz)."""
    return gtsam.imuBias.ConstantBias(np.array([b_ax, b_ay, 0.0]), np.array([0.0, 0.0, b_gz]))


def preintegrate(
    params: gtsam.PreintegrationParams,
    bias: gtsam.imuBias.ConstantBias,
    samples: Iterable[tuple[float, float, float, float]],
    substeps: int = 1,
) -> gtsam.PreintegratedImuMeasurements:
    """Preintegrate ``(ax, ay, wz, dt)`` samples (each held constant over ``dt``, split into
    ``substeps`` so that the body-frame acceleration turns with the boat within a sample).

    GTSAM applies a step's acceleration with the attitude at the *start* of the step (first order:
    the velocity lags by ``wz h / 2``); the acceleration is therefore passed rotated by
    ``Rz(wz h / 2)``, which applies it with the mid-step attitude (second order, as the exact
    constant-turn arc). The rotation acts on the bias-corrected sample at the preintegration's
    bias ``bias`` (which GTSAM subtracts again), so it is exact at that linearisation point."""
    pim = gtsam.PreintegratedImuMeasurements(params, bias)
    ba, bg = bias.accelerometer(), bias.gyroscope()
    for ax, ay, wz, dt in samples:
        if dt <= 0.0:
            continue
        h = dt / substeps
        half = 0.5 * (wz - bg[2]) * h
        c, s = math.cos(half), math.sin(half)
        ux, uy = ax - ba[0], ay - ba[1]
        acc = np.array([c * ux - s * uy + ba[0], s * ux + c * uy + ba[1], 0.0])
        omega = np.array([0.0, 0.0, wz])
        for _ in range(substeps):
            pim.integrateMeasurement(acc, omega, h)
    return pim


def imu_factor(k0: int, k1: int, pim: gtsam.PreintegratedImuMeasurements) -> gtsam.ImuFactor:
    """``ImuFactor(X_k0, V_k0, X_k1, V_k1, B_k0)`` with pose keys from :func:`factors.X`."""
    return gtsam.ImuFactor(gtsam.symbol("x", k0), V(k0), gtsam.symbol("x", k1), V(k1), IB(k0), pim)


def bias_between(k0: int, k1: int, rw_acc: float, rw_gyro: float, dt: float) -> gtsam.BetweenFactorConstantBias:
    """Random walk of the bias over ``dt`` [s]: ``rw_acc`` [m/s^2/sqrt(s)], ``rw_gyro`` [rad/s/sqrt(s)]."""
    s = math.sqrt(max(dt, 1e-9))
    sig = np.array([rw_acc] * 3 + [rw_gyro] * 3) * s
    return gtsam.BetweenFactorConstantBias(
        IB(k0), IB(k1), gtsam.imuBias.ConstantBias(), gtsam.noiseModel.Diagonal.Sigmas(sig)
    )


def bias_prior(k: int, sigma_acc: float, sigma_gyro: float) -> gtsam.PriorFactorConstantBias:
    """Prior on the residual bias after calibration: zero mean, ``sigma_acc`` / ``sigma_gyro`` 1-sigma."""
    sig = np.array([sigma_acc] * 3 + [sigma_gyro] * 3)
    return gtsam.PriorFactorConstantBias(IB(k), gtsam.imuBias.ConstantBias(), gtsam.noiseModel.Diagonal.Sigmas(sig))


def planar_pose(x: float, y: float, yaw: float) -> gtsam.Pose3:
    """``(x, y, yaw)`` as a level ``Pose3`` at z = 0."""
    return gtsam.Pose3(gtsam.Rot3.Yaw(float(yaw)), np.array([float(x), float(y), 0.0]))


def pose_xy_yaw(p: gtsam.Pose3) -> NDArray[np.float64]:
    """``(x, y, yaw)`` of a ``Pose3``."""
    t = p.translation()
    return np.array([t[0], t[1], p.rotation().yaw()])


def initial_state_factors(
    k: int,
    pose: tuple[float, float, float],
    sigma_xy: float,
    sigma_yaw: float,
    vel: tuple[float, float],
    sigma_v: float,
    *,
    sigma_tilt: float = 1e-4,
    sigma_z: float = 1e-3,
) -> list[gtsam.NonlinearFactor]:
    """Priors on pose ``k`` (level: roll/pitch ``sigma_tilt``, z ``sigma_z``) and its velocity."""
    pn = gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma_tilt, sigma_tilt, sigma_yaw, sigma_xy, sigma_xy, sigma_z]))
    vn = gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma_v, sigma_v, sigma_z]))
    return [
        gtsam.PriorFactorPose3(gtsam.symbol("x", k), planar_pose(*pose), pn),
        gtsam.PriorFactorVector(V(k), np.array([vel[0], vel[1], 0.0]), vn),
    ]


def gnss3_factor(
    key: int, x: float, y: float, sigma: float, *, robust: str | None = "huber", k: float | None = None
) -> gtsam.GPSFactor:
    """GNSS fix as a ``GPSFactor`` at z = 0 (isotropic ``sigma`` [m]), robust by default."""
    noise = robustify(gtsam.noiseModel.Isotropic.Sigma(3, float(sigma)), robust, k)
    return gtsam.GPSFactor(key, np.array([x, y, 0.0], dtype=float), noise)


def compass3_factor(
    key: int, yaw: float, sigma: float, *, robust: str | None = "huber", k: float | None = None
) -> gtsam.PoseRotationPrior3D:
    """Compass heading as a yaw-only ``PoseRotationPrior3D`` (zero precision on roll/pitch)."""
    noise = robustify(gtsam.noiseModel.Diagonal.Precisions(np.array([0.0, 0.0, 1.0 / float(sigma) ** 2])), robust, k)
    return gtsam.PoseRotationPrior3D(key, gtsam.Rot3.Yaw(float(yaw)), noise)
