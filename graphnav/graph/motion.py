"""The motion between keyframes: the odometry integrated over the interval, the IMU's preintegration
(the Pose3 graph), the fallback motion model (constant velocity from the last measured motion or the
GNSS velocity, else a random walk) and the fusion of what was measured into the interval's motion.

:class:`Motion` owns the odometry buffer, the IMU chain, the recent GNSS fixes (the GNSS velocity)
and the last measured motion; the variables it adds are the velocity ``V(k)`` and IMU bias ``IB(k)``
of the Pose3 graph, and its factors are the groups ``odometry``, ``motion``, ``imu``, ``imu_bias``.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..log import Gnss, Imu, Odometry
from .imu_chain import ROT_FRESH_S, ImuChain, ImuConfig, relative_prediction
from .keyframes import EPS
from .odometry_buffer import OdometryBuffer
from .scan_factors import proper_cov
from .smoother_config import SmootherConfig
from .space import IB, PlanarSpace, V
from .step import Step

FIX_RESOLUTION_M = 1e-3  # [m] below any receiver's resolution: a fit's scatter under it says nothing of the noise
MIN_IMU_DT = 1e-4  # [s] keyframes closer than this share their state (no ImuFactor: its covariance would vanish)
V0_STATED_SIGMA = 0.2  # [m/s] 1-sigma of an initial velocity the log states (meta["initial_velocity"])
#: the Pose3 graph's estimate of the previous keyframe: pose, nav-frame velocity, IMU bias, velocity covariance
NavPrev = tuple[gtsam.Pose3, NDArray[np.float64], gtsam.imuBias.ConstantBias, NDArray[np.float64] | None]
#: the IMU's prediction of an interval: the state at its end, the planar relative pose, its covariance
Guess = tuple[gtsam.NavState, NDArray[np.float64], NDArray[np.float64]]


class Motion:
    """Odometry, IMU and motion model of the interval between two keyframes (module docstring).

    ``imu``: the Pose3 graph's IMU chain (``None``: the planar graph); ``imu_model``: the log's IMU
    noise and initial velocity (``meta``)."""

    def __init__(self, cfg: SmootherConfig, space: PlanarSpace, nav: bool, imu_model: dict[str, Any] | None,
                 imu_mount: gtsam.Pose3 | None = None, odometry: bool = False) -> None:
        self.cfg = cfg
        self.space = space
        self.imu: ImuChain | None = ImuChain(ImuConfig(**cfg.imu), imu_model) if nav else None
        if self.imu is not None and imu_mount is not None:  # GTSAM's body_P_sensor (docs/mounts.md)
            self.imu.body_P_sensor = imu_mount
        self.imu_model = imu_model
        # the odometry samples (graphnav.graph.odometry_buffer); ``odometry``: the log has them (at rest before
        # the first)
        self.odometry = OdometryBuffer(cfg.odometry, expected=odometry and self.uses_odometry)
        self.last_rel = gtsam.Pose2()  # relative motion of the newest interval
        self.last_gap = 0.0
        self.twist: NDArray[np.float64] | None = None  # [m/s, m/s, rad/s] of the last measured motion
        self.twist_t: float | None = None  # ... and its time
        self.fixes: deque[tuple[float, float, float, float]] = deque(maxlen=256)  # recent GNSS (t, x, y, sigma)
        self.gnss_twist: tuple[float, NDArray[np.float64], float] | None = None  # (t, twist, speed sigma)
        # each odometry factor's samples (t, v, w) and interval by its keys: the closing step's scale estimate
        # (graphnav.graph.odometry_scale) re-integrates them
        self.intervals: dict[tuple[int, int], tuple[NDArray[np.float64], float, float]] = {}

    # -- records in ------------------------------------------------------------------------------
    @property
    def uses_odometry(self) -> bool:
        """Odometry feeds the graph when asked, or (``use_odometry`` unset) on the planar graph."""
        use = self.cfg.odometry.use
        return bool(use or (use is None and self.imu is None))

    def add_odometry(self, rec: Odometry) -> bool:
        """One odometry sample; whether its sigmas came from the configuration."""
        return self.odometry.add(rec)

    def add_rot(self, rec: Odometry) -> bool:
        """A rate of turn for the vessel model's gyro z, when it takes one (the log's ``meta["odometry"]`` says
        the odometry is one: ``imu_model["rot"]``; ``imu.vessel_rot``; no IMU records): whether it did."""
        if self.imu is None or self.imu or not (self.imu.cfg.vessel_rot and (self.imu_model or {}).get("rot")):
            return False
        self.imu.add_rot(rec)
        return True

    def add_imu(self, rec: Imu) -> None:
        assert self.imu is not None
        self.imu.add(rec)

    def add_fix(self, rec: Gnss) -> bool:
        """One GNSS fix (the GNSS velocity's window); whether it is the first after an outage."""
        outage = bool(self.fixes) and rec.t - self.fixes[-1][0] > self.cfg.gnss.gate_outage
        self.fixes.append((rec.t, rec.x, rec.y, rec.sigma))
        return outage

    def imu_until(self, now: float | None = None) -> float | None:
        """The newest IMU sample's time, else the newest ROT record's up to :data:`ROT_FRESH_S` before ``now``
        (the one closing a keyframe's interval is awaited); ``None``: nothing awaited."""
        rot = self.imu.rot if self.imu is not None else None
        if self.imu or not rot or now is None:
            return self.imu.t[-1] if self.imu else None
        return max(rot.t[-1], now - ROT_FRESH_S)

    def speed(self) -> float:
        """[m/s] the newest interval's speed."""
        return math.hypot(self.last_rel.x(), self.last_rel.y()) / self.last_gap if self.last_gap > 0 else 0.0

    def recent_odometry(self, t: float, age: float) -> tuple[float, float] | None:
        """The newest odometry sample's ``(v, w)`` when at most ``age`` seconds before ``t``."""
        odo = self.odometry
        if odo and t - odo.t[-1] <= age:
            _, v, w = odo.rows[-1][:3]
            return v, w
        return None

    def prune(self, t: float) -> None:
        """Samples no later interval needs (the keyframe at ``t`` has its batch)."""
        self.odometry.prune(t)
        if self.imu is not None:
            self.imu.prune(t)

    # -- one interval ----------------------------------------------------------------------------
    def start(self, s: Step) -> None:
        """Velocity and IMU-bias variables of keyframe 0 with their priors: the velocity at rest
        within ``v0_sigma`` (GNSS velocity and fixes make it), the bias the IMU model's residual."""
        assert self.imu is not None
        v0, sv = np.zeros(3), self.cfg.dynamics.v0_sigma
        stated = self.imu_model.get("initial_velocity") if self.imu_model else None
        if stated is not None and len(stated) >= 2:  # the log states it (a simulator's meta): within 0.2 m/s
            v0, sv = np.array([float(stated[0]), float(stated[1]), 0.0]), V0_STATED_SIGMA
        s.add(gtsam.PriorFactorVector(V(0), v0, gtsam.noiseModel.Diagonal.Sigmas(np.array([sv, sv, 0.1]))), "anchor")
        s.add(self.imu.bias_prior(0), "imu_bias")
        s.values.insert(V(0), v0)
        s.values.insert(IB(0), gtsam.imuBias.ConstantBias())
        s.stamps[V(0)] = s.stamps[IB(0)] = s.t

    def measured(self, s: Step, k: int, ta: float, tb: float, state: NavPrev | None
                 ) -> tuple[gtsam.Pose2 | None, NDArray[np.float64] | None, Guess | None]:
        """The measured motion of keyframe ``k``'s interval ``[ta, tb]`` into ``s``: the odometry's
        factor (its relative pose and covariance, ``None`` without odometry) and, on the Pose3 graph,
        the IMU's (its prediction)."""
        odo = self.odometry.between(ta, tb)
        rel: gtsam.Pose2 | None = None
        odo_cov = None
        if odo is not None:
            odo_cov = proper_cov(odo[1], self.floor())
            if odo_cov is not None:
                s.add(self.space.between(F.X(k - 1), F.X(k), _vec(odo[0]), odo_cov), "odometry")
                rel = odo[0]
                if self.cfg.robust.odometry_scale and self.odometry.last is not None:
                    self.intervals[(F.X(k - 1), F.X(k))] = (self.odometry.last[:, :3].copy(), ta, tb)
        guess = self._imu(s, k, ta, tb, state) if self.imu is not None else None
        return rel, odo_cov, guess

    def close(self, s: Step, k: int, dt: float, t: float, odo: tuple[gtsam.Pose2 | None, NDArray[np.float64] | None],
              match: tuple[gtsam.Pose2, NDArray[np.float64]] | None, guess: Guess | None
              ) -> tuple[gtsam.Pose2, NDArray[np.float64], bool]:
        """The interval's motion from what was measured (odometry, scan match, IMU), fused by
        information, or the motion model's factor when nothing was: the relative pose, its covariance
        and whether the motion model was used. The newest measured twist is kept."""
        rel, odo_cov = odo
        fallback = rel is None and match is None and guess is None
        if fallback:  # nothing measured: the motion model ties it
            mean, cov, _ = self.prior(dt, t)
            s.add(self.space.between(F.X(k - 1), F.X(k), _vec(mean), cov), "motion")
            rel, step_cov = mean, cov
        else:
            covs = [c for c in (odo_cov, match[1] if match is not None else None,
                                guess[2] if guess is not None and rel is None else None) if c is not None]
            rel = match[0] if match is not None else rel
            if rel is None:
                assert guess is not None
                rel = gtsam.Pose2(*guess[1])
            if dt > 1e-6:
                self.twist = np.asarray(gtsam.Pose2.Logmap(rel)) / dt
                self.twist_t = t
            step_cov = np.linalg.inv(sum(np.linalg.inv(c) for c in covs))  # the motion's fused covariance
        self.last_rel, self.last_gap = rel, dt
        return rel, step_cov, fallback

    def _imu(self, s: Step, k: int, ta: float, tb: float, state: NavPrev | None) -> Guess:
        """The IMU between keyframes ``k-1`` and ``k``: ``ImuFactor`` (preintegration at the bias
        estimate of ``k-1``) and the bias random walk; returns the predicted state at ``k``, the
        planar relative motion and its covariance (the scan matcher's guess)."""
        assert self.imu is not None and state is not None
        pose, vel, bias, vel_cov = state
        s.add(self.imu.bias_between(k - 1, k, tb - ta), "imu_bias")
        if tb - ta < MIN_IMU_DT:  # keyframes at one time (a duplicated scan): the same state, within the floor
            floor = np.square(self.floor())
            s.add(self.space.between(F.X(k - 1), F.X(k), np.zeros(3), np.diag(floor)), "motion")
            s.add(gtsam.BetweenFactorVector(V(k - 1), V(k), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)),
                  "motion")
            s.values.insert(V(k), vel)
            s.values.insert(IB(k), bias)
            s.stamps[V(k)] = s.stamps[IB(k)] = tb
            self._level(s, k)
            return gtsam.NavState(pose, vel), np.zeros(3), np.diag(floor)
        pim = self.imu.preintegrate(bias, ta, tb, speed=float(np.hypot(vel[0], vel[1])))
        s.add(F.imu_factor(k - 1, k, pim), "imu")
        self._level(s, k)
        pred, rel, cov = relative_prediction(pim, pose, vel, bias, vel_cov)
        cov = cov + np.diag(np.square(self.floor()))
        s.values.insert(V(k), pred.velocity())
        s.values.insert(IB(k), bias)
        s.stamps[V(k)] = s.stamps[IB(k)] = tb
        return pred, rel, cov

    def _level(self, s: Step, k: int) -> None:
        """Roll = pitch = 0 on keyframe ``k`` (``AttitudeFactorPose3``, ``level_sigma_deg``) when the IMU is
        planar or absent: its records are the levelled frame's and observe neither, so without it they
        wander with the gyro's noise (and a rolled body turns the planar acceleration out of the plane).
        With a 6-axis IMU (roll and pitch from gravity): the height at the sea surface (``surface_sigma``)."""
        assert self.imu is not None
        if not self.imu.six and self.cfg.dynamics.level_sigma_deg > 0:
            s.add(self.space.attitude(F.X(k), 0.0, 0.0, math.radians(self.cfg.dynamics.level_sigma_deg)), "level")
        elif self.imu.six and self.cfg.dynamics.surface_sigma > 0:  # a 6-axis IMU's height: at the surface
            s.add(self.space.surface(F.X(k), self.cfg.dynamics.surface_sigma), "level")

    @staticmethod
    def lift(p3: gtsam.Pose3, p2: gtsam.Pose2) -> gtsam.Pose3:
        """The IMU's predicted attitude (roll, pitch) and height with the planar pose ``p2``."""
        r = p3.rotation()
        return gtsam.Pose3(gtsam.Rot3.Ypr(p2.theta(), r.pitch(), r.roll()),
                           np.array([p2.x(), p2.y(), p3.translation()[2]]))

    def floor(self) -> NDArray[np.float64]:
        """[m, m, rad] added in quadrature to every motion factor (``dt = 0`` stays proper)."""
        c = self.cfg.dynamics
        return np.array([c.floor_xy, c.floor_xy, math.radians(c.floor_yaw_deg)])

    # -- motion models ---------------------------------------------------------------------------
    def offset(self, ta: float, t: float, gap: float | None) -> gtsam.Pose2 | None:
        """Motion from a keyframe at ``ta`` to time ``t`` (``None`` when they coincide): odometry when
        the log has it, else the newest relative motion (over ``gap`` seconds; ``None``: there is none
        yet) scaled to the time offset (constant velocity)."""
        if abs(t - ta) < 1e-6:
            return None
        if self.odometry:
            if t > ta:
                odo = self.odometry.between(ta, t)
                return None if odo is None else odo[0]
            odo = self.odometry.between(t, ta)
            return None if odo is None else odo[0].inverse()
        if gap is None:
            return None
        return gtsam.Pose2.Expmap(gtsam.Pose2.Logmap(self.last_rel) * ((t - ta) / gap)) if gap > 0 else None

    def prior(self, dt: float, t: float | None = None) -> tuple[gtsam.Pose2, NDArray[np.float64], str]:
        """The fallback motion over ``dt`` (ending at ``t``) when no odometry covers it.

        * constant velocity: the twist of the last measured relative motion (odometry, ICP) when it
          is at most ``cv_max_age`` old, else the GNSS velocity (:meth:`gnss_velocity`: forward
          at the speed over ground, the unicycle of a vessel or robot); sigma
          ``sqrt(cv_sigma^2 + sigma_speed^2 + (cv_accel age)^2) dt``, ``age`` the time since that
          motion was measured (the velocity is less certain the longer it is extrapolated);
        * random walk (no motion known, or ``motion_model="random-walk"``): identity, sigma
          ``rw_sigma dt``;

        both with the floor in quadrature (``dt = 0`` stays proper). Returns the mean, its
        covariance and the model's name."""
        cfg = self.cfg.dynamics
        dt = max(dt, 0.0)
        twist, extra, age = None, 0.0, 0.0
        if cfg.model == "constant-velocity":
            if self.twist is not None and (t is None or self.twist_t is None or t - self.twist_t <= cfg.cv_max_age):
                twist = self.twist
                age = 0.0 if t is None or self.twist_t is None else max(t - dt - self.twist_t, 0.0)
            elif t is not None:
                g = self.gnss_velocity(t)
                if g is not None:
                    twist, extra, age = g
        return self._model(dt, twist, extra, age)

    def _model(self, dt: float, twist: NDArray[np.float64] | None, extra: float, age: float
               ) -> tuple[gtsam.Pose2, NDArray[np.float64], str]:
        """The motion over ``dt`` at ``twist`` (constant velocity; ``None``: random walk) and its covariance
        (:meth:`prior`)."""
        cfg = self.cfg.dynamics
        if twist is not None:
            mean = gtsam.Pose2.Expmap(twist * dt)
            sv = math.sqrt(cfg.cv_sigma_v**2 + extra**2 + (cfg.cv_accel * age) ** 2)
            rate = np.array([sv, sv, math.radians(cfg.cv_sigma_w_deg)])
            name = "constant-velocity"
        else:
            mean = gtsam.Pose2()
            rate = np.array([cfg.rw_sigma_v, cfg.rw_sigma_v, math.radians(cfg.rw_sigma_w_deg)])
            name = "random-walk"
        return mean, np.diag(np.square(self.floor()) + np.square(rate * dt)), name

    def coast(self, t0: float, dt: float) -> tuple[gtsam.Pose2, NDArray[np.float64], NDArray[np.float64] | None]:
        """The motion model's prediction ``dt`` seconds on from the keyframe at ``t0`` (the online
        output through a gap without records, :mod:`graphnav.graph.coast`): as :meth:`prior`, with the
        velocity it would take at ``t0`` kept through the gap (the prior's choice at the gap's end
        would drop it after ``cv_max_age``: the prediction would snap back to the last pose). The
        graph's state is untouched. Returns the relative motion, its covariance and the twist
        (``None``: random walk)."""
        cfg = self.cfg.dynamics
        twist, extra, age = None, 0.0, 0.0
        if cfg.model == "constant-velocity":
            if self.twist is not None and self.twist_t is not None and t0 - self.twist_t <= cfg.cv_max_age:
                twist, age = self.twist, max(t0 - self.twist_t, 0.0)
            else:
                kept = self.gnss_twist
                g = self.gnss_velocity(t0)
                self.gnss_twist = kept  # an output only: the graph's next factor sees what it would have
                if g is not None:
                    twist, extra, age = g
        mean, cov, _ = self._model(max(dt, 0.0), twist, extra, age)
        return mean, cov, twist

    def gnss_velocity(self, t: float) -> tuple[NDArray[np.float64], float, float] | None:
        """Forward motion at the GNSS speed over ground: the least-squares velocity of the fixes of
        the last ``cv_gnss_window`` seconds before ``t`` (at least 3, spanning a third of it) as a
        body-frame twist ``(speed, 0, 0)``, and the speed's 1-sigma ``sigma / sqrt(sum (t_i -
        mean t)^2)`` and its age [s] (``sigma`` the fixes' stated one or, with at least 5 fixes and when
        lower, their scatter about the fitted line); zero speed when it is below 3 sigma (direction unknown). A fit
        whose speed sigma exceeds ``cv_sigma_v`` (few fixes) is not used: through an outage the last
        good velocity is kept for ``cv_max_age`` seconds."""
        cfg = self.cfg.dynamics
        w = [f for f in self.fixes if t - cfg.cv_gnss_window <= f[0] <= t + EPS]
        if len(w) >= 3 and w[-1][0] - w[0][0] >= cfg.cv_gnss_window / 3:
            a = np.array(w)
            tc = a[:, 0] - a[:, 0].mean()
            ss = float(tc @ tc)
            vx, vy = float(tc @ a[:, 1]) / ss, float(tc @ a[:, 2]) / ss
            sig2 = float(np.mean(a[:, 3] ** 2))  # the fixes' stated variance per axis ...
            if len(w) >= 5:  # ... or, when lower, the fit's own residual variance (2 axes, 4 parameters);
                res = a[:, 1:3] - a[:, 1:3].mean(axis=0) - np.outer(tc, [vx, vy])  # no scatter at all (repeated
                est = float(np.sum(res**2)) / (2 * len(w) - 4)  # or synthetic fixes) is no evidence of the noise
                if est > FIX_RESOLUTION_M**2:
                    sig2 = min(sig2, est)
            sv = float(np.sqrt(sig2 / ss))
            speed = math.hypot(vx, vy)
            if sv <= cfg.cv_sigma_v:  # a fit worth having (else the last one is kept)
                # below 3 sigma the direction is unknown: no motion, with the speed's sigma
                self.gnss_twist = (w[-1][0], np.array([speed if speed > 3 * sv else 0.0, 0.0, 0.0]), sv)
        if self.gnss_twist is None or t - self.gnss_twist[0] > cfg.cv_max_age:
            return None
        return self.gnss_twist[1], self.gnss_twist[2], max(t - self.gnss_twist[0], 0.0)


def _vec(p: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([p.x(), p.y(), p.theta()])
