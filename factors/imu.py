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
from numpy.typing import ArrayLike, NDArray

from .robust import robustify


def V(k: int) -> int:
    """Key of the nav-frame velocity at pose ``k``."""
    return gtsam.symbol("v", k)


def IB(k: int) -> int:
    """Key of the IMU bias (``imuBias.ConstantBias``) at pose ``k``."""
    return gtsam.symbol("i", k)


def preintegrate(
    params: gtsam.PreintegrationParams,
    bias: gtsam.imuBias.ConstantBias,
    samples: Iterable[tuple[NDArray[np.float64], NDArray[np.float64], float]],
    substeps: int = 1,
    *,
    planar: bool = True,
) -> gtsam.PreintegratedImuMeasurements:
    """Preintegrate ``(acc, omega, dt)`` samples (3-vectors, each held constant over ``dt``, split
    into ``substeps``).

    ``planar`` (the 3-axis record: ``acc = (ax, ay, 0)``, ``omega = (0, 0, wz)``): GTSAM applies a
    step's acceleration with the attitude at the *start* of the step (first order: the velocity lags
    by ``wz h / 2``); the acceleration is therefore passed rotated by ``Rz(wz h / 2)``, which applies it
    with the mid-step attitude (second order, as the exact constant-turn arc). The rotation acts on
    the bias-corrected sample at the preintegration's bias ``bias`` (which GTSAM subtracts again), so
    it is exact at that linearisation point. 6-axis samples are passed as they are."""
    rows = [(a, w, d) for a, w, d in samples]
    if not rows:
        return gtsam.PreintegratedImuMeasurements(params, bias)
    acc = np.array([np.asarray(a, dtype=float) for a, _, _ in rows])
    omega = np.array([np.asarray(w, dtype=float) for _, w, _ in rows])
    return preintegrate_arrays(params, bias, acc, omega, np.array([d for _, _, d in rows], dtype=float), substeps,
                               planar=planar)


def preintegrate_arrays(
    params: gtsam.PreintegrationParams,
    bias: gtsam.imuBias.ConstantBias,
    acc: NDArray[np.float64],
    omega: NDArray[np.float64],
    dt: NDArray[np.float64],
    substeps: int = 1,
    *,
    planar: bool = True,
) -> gtsam.PreintegratedImuMeasurements:
    """:func:`preintegrate` of samples given as arrays (``acc``, ``omega``: (n, 3); ``dt``: (n,)), the
    planar mid-step rotation computed for all of them at once."""
    pim = gtsam.PreintegratedImuMeasurements(params, bias)
    n = max(1, int(substeps))
    keep = dt > 0.0
    acc, omega, h = np.asarray(acc, dtype=float)[keep], np.asarray(omega, dtype=float)[keep], dt[keep] / n
    if planar and len(h):
        ba, bg = np.asarray(bias.accelerometer()), np.asarray(bias.gyroscope())
        half = 0.5 * (omega[:, 2] - bg[2]) * h
        c, s = np.cos(half), np.sin(half)
        ux, uy = acc[:, 0] - ba[0], acc[:, 1] - ba[1]
        acc = np.column_stack([c * ux - s * uy + ba[0], s * ux + c * uy + ba[1], np.zeros(len(h))])
    acc, omega = np.ascontiguousarray(acc), np.ascontiguousarray(omega)
    integrate = pim.integrateMeasurement
    if n == 1:  # (rows as views, the steps as floats: ~20 % of the loop's cost was indexing)
        for a, w, hk in zip(acc, omega, h.tolist(), strict=True):
            integrate(a, w, hk)
        return pim
    for a, w, hk in zip(acc, omega, h.tolist(), strict=True):
        for _ in range(n):
            integrate(a, w, hk)
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


def bias_prior(k: int, sigma_acc: ArrayLike, sigma_gyro: ArrayLike) -> gtsam.PriorFactorConstantBias:
    """Prior on the residual bias after calibration: zero mean, ``sigma_acc`` / ``sigma_gyro`` 1-sigma
    (scalars, or one per axis x, y, z)."""
    sig = np.concatenate([np.broadcast_to(np.asarray(sigma_acc, dtype=float), 3),
                          np.broadcast_to(np.asarray(sigma_gyro, dtype=float), 3)])
    return gtsam.PriorFactorConstantBias(IB(k), gtsam.imuBias.ConstantBias(), gtsam.noiseModel.Diagonal.Sigmas(sig))


def planar_pose(x: float, y: float, yaw: float) -> gtsam.Pose3:
    """``(x, y, yaw)`` as a level ``Pose3`` at z = 0."""
    return gtsam.Pose3(gtsam.Rot3.Yaw(float(yaw)), np.array([float(x), float(y), 0.0]))


def pose_xy_yaw(p: gtsam.Pose3) -> NDArray[np.float64]:
    """``(x, y, yaw)`` of a ``Pose3``."""
    t = p.translation()
    return np.array([t[0], t[1], p.rotation().yaw()])


def gnss3_factor(
    key: int, x: float, y: float, sigma: float, *, robust: str | None = "huber", k: float | None = None,
    arm: tuple[float, float, float] | None = None,
) -> gtsam.NonlinearFactor:
    """GNSS fix as a ``GPSFactor`` at z = 0 (isotropic ``sigma`` [m]), robust by default; with a lever
    ``arm`` (the antenna's offset in the body frame, m) GTSAM's ``GPSFactorArm`` with the horizontal
    part of the arm: the graph does not observe roll and pitch, so a height on the arm would let them
    absorb the fixes' noise (harbour circle: 2.9 m median instead of 0.05 m); heel is not modelled."""
    noise = robustify(gtsam.noiseModel.Isotropic.Sigma(3, float(sigma)), robust, k)
    if arm is None or (arm[0] == 0.0 and arm[1] == 0.0):
        return gtsam.GPSFactor(key, np.array([x, y, 0.0], dtype=float), noise)
    a = np.array([arm[0], arm[1], 0.0], dtype=float)
    return gtsam.GPSFactorArm(key, np.array([x, y, 0.0], dtype=float), a, noise)


def compass3_factor(
    key: int, yaw: float, sigma: float, *, robust: str | None = "huber", k: float | None = None
) -> gtsam.PoseRotationPrior3D:
    """Compass heading as a yaw-only ``PoseRotationPrior3D`` (zero precision on roll/pitch)."""
    noise = robustify(gtsam.noiseModel.Diagonal.Precisions(np.array([0.0, 0.0, 1.0 / float(sigma) ** 2])), robust, k)
    return gtsam.PoseRotationPrior3D(key, gtsam.Rot3.Yaw(float(yaw)), noise)
