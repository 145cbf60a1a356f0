"""The state space of the navigation graph: which GTSAM variable a keyframe is, and how each
measurement becomes a native factor on it.

The builder decides everything in the plane -- keyframes, gates, ICP guesses, the (x, y, yaw)
covariances of matches and odometry -- and hands the factors to one of two spaces:

* :class:`PlanarSpace` -- ``Pose2`` keyframes (the odometry / constant-velocity graph of robots
  and of vessels without an IMU); ``Point2`` beacons; the compass-bias frame a ``Pose2``.
* :class:`NavSpace` -- ``Pose3`` keyframes with a nav-frame velocity ``V(k)`` and an IMU bias
  ``IB(k)`` (GTSAM preintegration between keyframes, :mod:`graphnav.graph.imu_chain`); the same
  planar measurements embedded: a relative pose (ICP, odometry, loop) is a ``BetweenFactorPose3``
  whose (x, y, yaw) block is the measured covariance and whose roll, pitch and z carry no
  information (:data:`LOOSE`); GNSS a ``GPSFactor`` at the sea surface (z = 0); compass a yaw-only
  ``PoseRotationPrior3D`` or a ``BetweenFactorPose3`` from a ``Pose3`` bias frame; beacons
  ``BearingRangeFactor3D`` to ``Point3`` marks at the surface (the bearing's azimuth in the body
  plane, its elevation free: :data:`BEACON_ELEVATION_SIGMA`); GNSS velocity a ``PriorFactorVector`` on ``V(k)``.

Both answer in the plane: :meth:`pose2` of a key, :meth:`world_cov` the (x, y, yaw) covariance in
the world frame (docs/conventions.md). Pose3's tangent is (roll, pitch, yaw, x, y, z) in the body
frame; the planar block of it is (x, y, yaw) = indices (3, 4, 2).
"""

from __future__ import annotations

import math
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F
from factors.imu import IB, V
from factors.robust import robustify

from ..geometry import cov_to_world


def W(k: int) -> int:
    """Key of the water current (nav frame, m/s) at keyframe ``k``."""
    return gtsam.symbol("w", k)


def K(i: int) -> int:
    """Key of the speed log's scale (true speed through water per unit of reading), its ``i``-th segment."""
    return gtsam.symbol("k", i)


#: [rad, rad, m] roll, pitch, z sigmas of an embedded planar relative pose: no information
#: (the IMU and the sea surface decide them)
LOOSE = (0.5, 0.5, 10.0)
#: Pose3 tangent indices of the planar (x, y, yaw)
PLANAR = [3, 4, 2]
_PLANAR_IX = np.ix_(PLANAR, PLANAR)  # (built once: np.ix_ per call was a tenth of the conversions)


def _vec2(p: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([p.x(), p.y(), p.theta()])


def as_pose2(p: gtsam.Pose3) -> gtsam.Pose2:
    """The planar part of a ``Pose3``: x, y and yaw."""
    t = p.translation()
    return gtsam.Pose2(float(t[0]), float(t[1]), float(p.rotation().yaw()))


def embed_cov(cov3: NDArray[np.float64], loose: tuple[float, float, float] = LOOSE) -> NDArray[np.float64]:
    """A (x, y, yaw) covariance as a Pose3 tangent covariance with ``loose`` roll, pitch, z."""
    c = np.zeros((6, 6))
    c[_PLANAR_IX] = 0.5 * (cov3 + cov3.T)
    c[0, 0], c[1, 1], c[5, 5] = loose[0] ** 2, loose[1] ** 2, loose[2] ** 2
    return c


class PlanarSpace:
    """``Pose2`` keyframes (see the module docstring)."""

    name = "planar"
    pose_type = "Pose2"
    point_type = "Point2"

    def thresholds(self, pose: float, landmark: float, bias_yaw: float, velocity: float = 0.05,
                   imu_bias: tuple[float, float] = (1e-2, 1e-3)) -> dict[str, list[float]]:
        return {"x": [pose] * 3, "l": [landmark] * 2, "b": [1.0, 1.0, bias_yaw]}

    def value(self, p: gtsam.Pose2) -> gtsam.Pose2:
        return p

    def pose2(self, v: Any) -> gtsam.Pose2:
        return v

    def read(self, values: gtsam.Values, key: int) -> gtsam.Pose2:
        return values.atPose2(key)

    def world_cov(self, value: Any, cov: NDArray[np.float64]) -> NDArray[np.float64]:
        return cov_to_world(self.pose2(value).theta(), cov)

    def prior(self, key: int, pose: NDArray[np.float64], sigmas: NDArray[np.float64],
              tilt: tuple[float, float, float] | None = None) -> gtsam.NonlinearFactor:
        """``(x, y, yaw)`` within ``sigmas`` (``tilt``: the Pose3 graph's, not in the plane)."""
        return gtsam.PriorFactorPose2(key, gtsam.Pose2(*pose), gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas)))

    def prior_cov(self, key: int, value: Any, cov: NDArray[np.float64]) -> gtsam.NonlinearFactor:
        """A prior carrying a marginal (tangent) covariance ``cov`` (the fixed-lag re-anchoring)."""
        return F.pose_prior(key, _vec2(value), cov)

    def between(self, k0: int, k1: int, rel: NDArray[np.float64], cov: NDArray[np.float64],
                robust: str | None = None, k: float | None = None,
                model: gtsam.noiseModel.Base | None = None) -> gtsam.NonlinearFactor:
        if model is None:
            model = robustify(gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T)), robust, k)
        return gtsam.BetweenFactorPose2(k0, k1, gtsam.Pose2(*rel), model)

    def gnss(self, key: int, x: float, y: float, sigma: float, robust: str | None, k: float | None,
             arm: tuple[float, float, float] | None = None):
        """A fix of the antenna at ``arm`` (body frame, m; ``None``: the body origin)."""
        return F.gnss_factor(key, x, y, sigma, robust=robust, k=k, arm=None if arm is None else arm[:2])

    def compass(self, key: int, yaw: float, sigma: float, robust: str | None):
        return F.compass_factor(key, yaw, sigma, robust=robust)

    def bias_frame(self) -> gtsam.Pose2:
        return gtsam.Pose2()

    def bias_prior(self, key: int, sigma: float):
        return F.compass_bias_prior(key, sigma)

    def bias_between(self, a: int, b: int, sigma: float):
        """Consecutive compass-bias frames: the same, the angle within ``sigma`` [rad] (x/y pinned as the prior)."""
        return gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(), gtsam.noiseModel.Diagonal.Sigmas(
            np.array([1e-3, 1e-3, sigma])))

    def biased_compass(self, bias_key: int, key: int, yaw: float, sigma: float, robust: str | None):
        return F.biased_compass_factor(bias_key, key, yaw, sigma, robust=robust)

    def compass_bias(self, frame: Any) -> float:
        return F.compass_bias(frame)

    def read_bias_frame(self, values: gtsam.Values, key: int) -> Any:
        return values.atPose2(key)

    def landmark(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(xy, dtype=float)

    def landmark_xy(self, values: gtsam.Values, key: int) -> NDArray[np.float64]:
        return np.asarray(values.atPoint2(key))

    def landmark_prior(self, key: int, x: float, y: float, sigma: float):
        return F.beacon_prior(key, x, y, sigma)

    def landmark_prior_cov(self, key: int, p: NDArray[np.float64], cov: NDArray[np.float64]):
        return gtsam.PriorFactorPoint2(key, p, gtsam.noiseModel.Gaussian.Covariance(cov))

    def beacon(self, key: int, lkey: int, rng: float, brg: float, sr: float, sb: float, robust: str | None,
               k: float | None, tilt: tuple[float, float] | None = None):
        return F.beacon_factor(key, lkey, rng, brg, sr, sb, robust=robust, k=k)


class NavSpace(PlanarSpace):
    """``Pose3`` + velocity + IMU bias keyframes (see the module docstring)."""

    name = "nav"
    pose_type = "Pose3"
    point_type = "Point3"

    def thresholds(self, pose: float, landmark: float, bias_yaw: float, velocity: float = 0.05,
                   imu_bias: tuple[float, float] = (1e-2, 1e-3)) -> dict[str, list[float]]:
        return {"x": [pose] * 6, "v": [velocity] * 3, "w": [velocity] * 3, "k": [1e-3],  # (k: factors linear)
                "i": [imu_bias[0]] * 3 + [imu_bias[1]] * 3, "l": [landmark] * 3,
                "b": [1.0, 1.0, bias_yaw, 1.0, 1.0, 1.0]}

    def value(self, p: gtsam.Pose2) -> gtsam.Pose3:
        return F.planar_pose(p.x(), p.y(), p.theta())

    def pose2(self, v: Any) -> gtsam.Pose2:
        return as_pose2(v) if isinstance(v, gtsam.Pose3) else v

    def read(self, values: gtsam.Values, key: int) -> gtsam.Pose2:
        return as_pose2(values.atPose3(key))

    def world_cov(self, value: Any, cov: NDArray[np.float64]) -> NDArray[np.float64]:
        c = np.asarray(cov)
        if c.shape == (6, 6):
            c = c[_PLANAR_IX]
        return cov_to_world(self.pose2(value).theta(), c)

    def prior(self, key: int, pose: NDArray[np.float64], sigmas: NDArray[np.float64],
              tilt: tuple[float, float, float] | None = None) -> gtsam.NonlinearFactor:
        """``(x, y, yaw)`` within ``sigmas``; level (roll = pitch = 0 within 1e-4 rad) unless ``tilt``
        ``(roll, pitch, sigma)`` [rad] is given (a 6-axis IMU's gravity direction: a boat may heel)."""
        s = np.asarray(sigmas, dtype=float)
        roll, pitch, st = tilt if tilt is not None else (0.0, 0.0, 1e-4)
        model = gtsam.noiseModel.Diagonal.Sigmas(np.array([st, st, s[2], s[0], s[1], 1e-3]))
        return gtsam.PriorFactorPose3(key, self.tilted(pose, roll, pitch), model)

    @staticmethod
    def tilted(pose: NDArray[np.float64], roll: float, pitch: float) -> gtsam.Pose3:
        """``(x, y, yaw)`` at z = 0 with ``roll`` and ``pitch`` (ZYX: yaw, then pitch, then roll)."""
        return gtsam.Pose3(gtsam.Rot3.Ypr(float(pose[2]), float(pitch), float(roll)),
                           np.array([float(pose[0]), float(pose[1]), 0.0]))

    def prior_cov(self, key: int, value: Any, cov: NDArray[np.float64]) -> gtsam.NonlinearFactor:
        return gtsam.PriorFactorPose3(key, value, gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov)))

    def between(self, k0: int, k1: int, rel: NDArray[np.float64], cov: NDArray[np.float64],
                robust: str | None = None, k: float | None = None,
                model: gtsam.noiseModel.Base | None = None) -> gtsam.NonlinearFactor:
        if model is None:
            model = robustify(gtsam.noiseModel.Gaussian.Covariance(embed_cov(np.asarray(cov))), robust, k)
        else:  # a planar model given whole (loops): its covariance embedded, its robust kernel kept
            model = _embed_model(model)
        return gtsam.BetweenFactorPose3(k0, k1, F.planar_pose(*rel), model)

    def gnss(self, key: int, x: float, y: float, sigma: float, robust: str | None, k: float | None,
             arm: tuple[float, float, float] | None = None):
        return F.gnss3_factor(key, x, y, sigma, robust=robust, k=k, arm=arm)

    def compass(self, key: int, yaw: float, sigma: float, robust: str | None):
        return F.compass3_factor(key, yaw, sigma, robust=robust)

    def bias_frame(self) -> gtsam.Pose3:
        return gtsam.Pose3()

    def bias_prior(self, key: int, sigma: float):
        model = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-4, 1e-4, sigma, 1e-3, 1e-3, 1e-3]))
        return gtsam.PriorFactorPose3(key, gtsam.Pose3(), model)

    def bias_between(self, a: int, b: int, sigma: float):
        model = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-4, 1e-4, sigma, 1e-3, 1e-3, 1e-3]))
        return gtsam.BetweenFactorPose3(a, b, gtsam.Pose3(), model)

    def biased_compass(self, bias_key: int, key: int, yaw: float, sigma: float, robust: str | None):
        # roll, pitch, x, y, z: a precision of 1e-8 (sigma 1e4), not 0, so marginals (Cholesky) stay defined
        noise = gtsam.noiseModel.Diagonal.Precisions(np.array([1e-8, 1e-8, 1.0 / sigma**2, 1e-8, 1e-8, 1e-8]))
        return gtsam.BetweenFactorPose3(bias_key, key, F.planar_pose(0.0, 0.0, yaw), robustify(noise, robust, None))

    def compass_bias(self, frame: Any) -> float:
        return -float(frame.rotation().yaw())

    def read_bias_frame(self, values: gtsam.Values, key: int) -> Any:
        return values.atPose3(key)

    def landmark(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array([float(xy[0]), float(xy[1]), 0.0])

    def landmark_xy(self, values: gtsam.Values, key: int) -> NDArray[np.float64]:
        return np.asarray(values.atPoint3(key))[:2]

    def landmark_prior(self, key: int, x: float, y: float, sigma: float):
        return gtsam.PriorFactorPoint3(key, np.array([x, y, 0.0]), gtsam.noiseModel.Diagonal.Sigmas(
            np.array([sigma, sigma, SURFACE_SIGMA])))

    def landmark_prior_cov(self, key: int, p: NDArray[np.float64], cov: NDArray[np.float64]):
        return gtsam.PriorFactorPoint3(key, p, gtsam.noiseModel.Gaussian.Covariance(cov))

    def beacon(self, key: int, lkey: int, rng: float, brg: float, sr: float, sb: float, robust: str | None,
               k: float | None, tilt: tuple[float, float] | None = None):
        """Range and bearing ``brg`` (the azimuth in the hull's plane) to a mark: ``BearingRangeFactor3D``
        whose elevation component has :data:`BEACON_ELEVATION_SIGMA` (a scanning sensor does not measure it).
        GTSAM takes the bearing's error in the basis of the *predicted* direction: which of its two components
        is the vertical one is read from the direction expected at the keyframe's ``tilt`` (roll, pitch; the
        estimate when the factor is made), a mark at the sensor's height."""
        bearing = gtsam.Unit3(np.array([math.cos(brg), math.sin(brg), 0.0]))
        vert = _vertical_component(brg, tilt)
        sig = [sb, sb]
        sig[vert] = BEACON_ELEVATION_SIGMA
        noise = robustify(gtsam.noiseModel.Diagonal.Sigmas(np.array([sig[0], sig[1], sr], dtype=float)), robust, k)
        return gtsam.BearingRangeFactor3D(key, lkey, bearing, float(rng), noise)

    def attitude(self, key: int, roll: float, pitch: float, sigma: float):
        """Roll and pitch (an AHRS, a satellite compass, PASHR/XDR, PGN 127257): GTSAM's
        ``AttitudeFactorPose3``, the body's up direction ``Ry(pitch)^T Rx(roll)^T`` seen as the
        navigation frame's up (2 DoF; the yaw is left free)."""
        up_body = gtsam.Rot3.Ypr(0.0, pitch, roll).unrotate(gtsam.Point3(0.0, 0.0, 1.0))
        return gtsam.AttitudeFactorPose3(key, gtsam.Unit3(np.array([0.0, 0.0, 1.0])),
                                         gtsam.noiseModel.Isotropic.Sigma(2, sigma), gtsam.Unit3(up_body))

    def surface(self, key: int, sigma: float):
        """The keyframe's height at the sea surface (z = 0 within ``sigma`` [m]): a ``GPSFactor`` that says
        nothing of x and y (sigma 1e4 m there)."""
        return gtsam.GPSFactor(key, np.zeros(3), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e4, 1e4, float(sigma)])))

    def velocity(self, k: int, vx: float, vy: float, sigma: float, robust: str | None):
        """GNSS velocity over ground (nav frame) on ``V(k)``; the vertical held at the surface."""
        noise = robustify(gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma, sigma, SURFACE_SIGMA_V])), robust, None)
        return gtsam.PriorFactorVector(V(k), np.array([vx, vy, 0.0]), noise)


#: [rad] the elevation of a beacon bearing: not measured (a bearing is the azimuth in the sensor's plane, which
#: heels with the hull); held at 0 with the bearing's sigma, it pulled the roll of a boat heeled 10 deg by 1.5 deg
BEACON_ELEVATION_SIGMA = 1.0
def _vertical_component(brg: float, tilt: tuple[float, float] | None) -> int:
    """Which tangent component (0 or 1) of GTSAM's ``Unit3`` basis is the vertical one for a mark at azimuth
    ``brg`` in the body plane seen from a body at ``tilt`` = (roll, pitch) (None: level). ``Unit3::basis``:
    ``b1 = n x a / |n x a|``, ``a`` the axis of ``n``'s smallest absolute component (x, y, z in that order on
    ties), ``b2 = n x b1``. ``n`` is the body direction of a horizontal world direction of that azimuth: its
    body z is ``w . R e_z`` with ``R e_z = (cos r sin p, -sin r, cos r cos p)``."""
    roll, pitch = tilt if tilt is not None else (0.0, 0.0)
    c, s = math.cos(brg), math.sin(brg)
    z = c * math.cos(roll) * math.sin(pitch) - s * math.sin(roll)
    r = math.sqrt(c * c + s * s + z * z)
    n = (c / r, s / r, z / r)
    a = min(range(3), key=lambda i: abs(n[i]))  # (the first on ties, as np.argmin)
    # b1 = n x e_a / |n x e_a|; only the z components of b1 and b2 = n x b1 are compared (plain floats:
    # one keyframe's beacon factors, ~1 ms with numpy's small-array overhead)
    b1 = (n[1] * (a == 2) - n[2] * (a == 1), n[2] * (a == 0) - n[0] * (a == 2), n[0] * (a == 1) - n[1] * (a == 0))
    nb = math.sqrt(b1[0] * b1[0] + b1[1] * b1[1] + b1[2] * b1[2])
    b1 = (b1[0] / nb, b1[1] / nb, b1[2] / nb)
    b2z = n[0] * b1[1] - n[1] * b1[0]
    return 0 if abs(b1[2]) > abs(b2z) else 1


#: [m] a mark's height above the surface (charted or unknown: a prior at 0)
SURFACE_SIGMA = 1.0
#: [m/s] the vertical velocity of a GNSS velocity record (a surface vessel's heave rate)
SURFACE_SIGMA_V = 0.5


def _embed_model(model: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
    """A planar (3x3) noise model as a Pose3 one (:func:`embed_cov`), keeping a robust kernel."""
    if isinstance(model, gtsam.noiseModel.Robust):
        return gtsam.noiseModel.Robust.Create(model.robust(), _embed_model(model.noise()))
    cov = np.linalg.inv(model.R().T @ model.R())
    return gtsam.noiseModel.Gaussian.Covariance(embed_cov(cov))


__all__ = ["IB", "LOOSE", "NavSpace", "PlanarSpace", "V", "W", "as_pose2", "embed_cov"]
