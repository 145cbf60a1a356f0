"""A general EKF on [x, y, yaw] (optionally + speed): the classic filter baseline.

Motion input: odometry (speed + rate of turn, unicycle model as eq. 3 of the beacon paper), or,
when a log has LiDAR scans but no odometry, ICP increments from :func:`graphnav.scan.weighted_icp.match_scans`
(used only if that module is installed). Measurements: GNSS position and compass heading, each
gated by a chi-square test on the normalised innovation squared (:class:`InnovationGate`: a GNSS
jump is rejected, however long it lasts while the filter is tracking); the measured components
are re-initialised only on sustained evidence -- ``reinit_n`` consecutive measurements that agree
with each other and not with the estimate, when the filter was not confirmed by the sensor (a
wrong prior, a long outage) or after ``reinit_after_s`` of such disagreement.
Heading innovations are wrapped to [-pi, pi); the yaw state is kept wrapped.
Updates use the Joseph form. With ``speed=True`` the state is [x, y, yaw, v]: v is a random walk
(``sigma_acc``) and odometry speed becomes a measurement of it. See docs/ekf.md.

:class:`~graphnav.estimators.pose_ekf.PoseEkf` is the filter algebra (:class:`~graphnav.estimators.ins_ekf.InsEkf`
with the IMU motion); :class:`EkfStepper` the record-by-record cycle around it,
shared by the batch :func:`run_ekf` and the live adapter :class:`graphnav.estimators.ekf_online.EkfOnline`.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import option
from ..graph.speed_log import ZeroReadings
from ..log import Gnss, GnssVelocity, Heading, Imu, NavLog, Odometry, PosePrior, Record, Scan, Truth, WaterSpeed
from ..result import OnEstimate, RunResult
from ..trajectory import Trajectory
from .gating import GATING_DEFAULTS, GateOptions
from .imu_model import compass_bias_model, resolve_flag, yaw_from_compass
from .ins_ekf import InsEkf
from .pose_ekf import PoseEkf

if TYPE_CHECKING:
    from ..graph.imu_chain import RotChain


def icp_available() -> bool:
    try:
        from ..scan.weighted_icp import match_scans  # noqa: F401
    except ImportError:
        return False
    return True


def initial_state(records: Iterable[Record], speed: bool) -> tuple[NDArray, NDArray, str]:
    """Initial state, covariance and anchor from a log's records: its first ``pose_prior``; else
    the first GNSS fix with the first compass heading (yaw sigma pi without one); else the first
    truth pose; else the origin. With ``speed``, v starts at the first odometry speed (sigma 1 m/s)."""
    prior = gnss = head = odo = truth = None
    for r in records:
        if prior is None and isinstance(r, PosePrior):
            prior = r
        elif gnss is None and isinstance(r, Gnss):
            gnss = r
        elif head is None and isinstance(r, Heading):
            head = r
        elif odo is None and isinstance(r, Odometry):
            odo = r
        elif truth is None and isinstance(r, Truth):
            truth = r
    if prior is not None:
        x = [prior.x, prior.y, prior.yaw]
        P = np.diag([prior.sigma_xy**2, prior.sigma_xy**2, prior.sigma_yaw**2])
        anchor = "pose_prior"
    elif gnss is not None:
        yaw, sy = (head.yaw, head.sigma) if head is not None else (0.0, math.pi)
        x = [gnss.x, gnss.y, yaw]
        P = np.diag([gnss.sigma**2, gnss.sigma**2, sy**2])
        anchor = "gnss"
    else:
        x = [truth.x, truth.y, truth.yaw] if truth is not None else [0.0, 0.0, 0.0]
        P = np.zeros((3, 3))
        anchor = "truth" if truth is not None else "origin"
    if speed:
        x = [*x, odo.v if odo is not None else 0.0]
        P4 = np.zeros((4, 4))
        P4[:3, :3] = P
        P4[3, 3] = 1.0
        P = P4
    return np.array(x, dtype=float), P, anchor


def compass_yaw(anchor: str, P0: NDArray) -> bool:
    """Whether :func:`initial_state`'s yaw is a compass reading: the ``"gnss"`` anchor with a heading (sigma < pi)."""
    return anchor == "gnss" and float(P0[2, 2]) < math.pi ** 2


def _sig(v: float, default: float) -> float:
    return default if not math.isfinite(v) else v


#: options of the IMU motion (``motion="imu"``; run_ekf fills the noise from the log's IMU model,
#: :func:`graphnav.estimators.imu_model.imu_noise`): densities [per sqrt(s)], bias/current states,
#: their priors and random walks, the initial velocity ``(v_x, v_y, sigma)``, sigmas for records without one
IMU_DEFAULTS: dict[str, Any] = {
    "acc_density": 0.0039, "gyro_density": math.radians(0.033), "acc_bias_rw": 1e-5,
    "gyro_bias_rw": math.radians(1e-4), "bias": True, "current": False, "sigma_bias_acc": 0.01,
    "sigma_bias_gyro_deg": 0.1, "sigma_current0": 0.5, "q_current": 0.005, "v0": (0.0, 0.0, 2.0),
    "sigma_gnss_velocity": 0.1, "sigma_water_speed": 0.1, "use_velocity": True, "use_odometry": True,
    # motion="vessel" (no IMU): None takes the graph's vessel model (graphnav.graph.imu_chain.ImuConfig)
    "vessel_accel": None, "vessel_yaw_rate_deg": None, "vessel_steerage_speed": None, "vessel_position_walk": None,
    "vessel_rot": None,  # motion="vessel": odometry records are a rate of turn, the heading's rate (None: from meta)
    # the water-speed record's sideways sigma hypot(leeway, leeway_rel |v|); None: the graph's (WaterConfig)
    "water_leeway": None, "water_leeway_rel": None,
    # the compass-bias state (InsEkf): "auto" resolved by imu_options from the log; the stepper takes "auto" as on
    # for the IMU motion and for the vessel motion with the current states (compass_bias_on)
    "compass_bias": "auto",
    # the speed log's scale state k (after the current states): "auto" resolved by imu_options from the log (water
    # speed and the current states); the stepper takes "auto" as on with the current states. Prior N(1,
    # sigma_log_scale^2), random walk q_log_scale [1/sqrt(s)]: the graph's scale state
    "log_scale": "auto", "sigma_log_scale": 0.1, "q_log_scale": 5e-4,
    # a zero water-speed reading (a stalled log) is censored below this [m/s]; None: the smallest non-zero reading
    # so far (graphnav.graph.speed_log, the graph's water.stall_speed)
    "stall_speed": None,
}
VESSEL_KEYS = ("vessel_accel", "vessel_yaw_rate_deg", "vessel_steerage_speed", "vessel_position_walk")


def _water(given: dict[str, Any]) -> Any:
    """The water-speed update's sideways model: the graph's :class:`~graphnav.graph.smoother_config.WaterConfig`
    with ``water_leeway`` / ``water_leeway_rel`` where given (not None)."""
    from ..graph.smoother_config import WaterConfig

    keys = {"water_leeway": "leeway", "water_leeway_rel": "leeway_rel"}
    return WaterConfig(**{f: float(given[k]) for k, f in keys.items() if given.get(k) is not None})


def vessel_model(given: dict[str, Any]) -> dict[str, float]:
    """The vessel motion's densities: ``given`` where not None, else the graph's vessel model
    (:class:`graphnav.graph.imu_chain.ImuConfig`; the position walk its ``integration_sigma`` floor), so
    the filter and the graph move a boat with the same noise."""
    from ..graph.imu_chain import ImuConfig

    c = ImuConfig()
    out = {k: given.get(k) if given.get(k) is not None else getattr(c, k) for k in VESSEL_KEYS}
    out["vessel_position_walk"] = max(float(out["vessel_position_walk"] or 0.0), c.integration_sigma)
    return out


def compass_bias_on(flag: Any, motion: str, current: bool) -> bool:
    """Whether the filter carries the compass-bias state: ``flag`` true/false, or ``"auto"``: with the IMU
    motion (the heading turns the integrated acceleration, so GNSS position/velocity see a heading error
    and tell it from the compass's bias) and with the vessel motion when it has the current states (the
    speed through water along the bow against GNSS is its only tie between heading and track: without it
    the bias cannot be told from the heading and would only widen the heading's covariance)."""
    return resolve_flag(flag, motion == "imu" or (motion == "vessel" and current), "compass_bias")


MatchFn = Callable[..., Any]  # graphnav.scan.weighted_icp.match_scans(scan, prev, init=...) -> MatchResult


class EkfStepper:
    """The EKF's record-by-record cycle, shared by the batch :func:`run_ekf` and the online
    :class:`graphnav.estimators.ekf_online.EkfOnline`: ``step(record)`` predicts to the record's time
    (unicycle odometry, the beacon paper's eq. 3, with the last SOG/ROT control held; or the IMU,
    ``motion="imu"``, :class:`graphnav.estimators.ins_ekf.InsEkf`, each record over its own interval
    and the last one held up to a measurement between records) or composes an ICP increment
    (``motion="icp"``: consecutive scans matched by ``match``, default
    :func:`graphnav.scan.weighted_icp.match_scans`), then applies the gated GNSS/heading (and with the IMU,
    GNSS velocity and water speed) update. ``imu``: the IMU motion's options (:data:`IMU_DEFAULTS`).
    ``keep`` bounds the timing buffers (``None``: keep all). ``compass_yaw``: the initial yaw is a
    compass reading (:func:`initial_state`'s ``"gnss"`` anchor), so with the compass-bias state it starts
    as that reading less the bias: its variance plus the bias prior's, correlated -1 with the bias."""

    def __init__(self, x0: NDArray[np.float64], P0: NDArray[np.float64], *, motion: str = "odometry",
                 gate: float | None = 0.999, sigma_v: float = 0.5,
                 sigma_w: float = math.radians(0.5), sigma_acc: float = 0.5, use_gnss: bool = True,
                 use_heading: bool = True, match: MatchFn | None = None,
                 keep: int | None = None, imu: dict[str, Any] | None = None, compass_yaw: bool = False,
                 **gating: Any) -> None:
        if motion not in ("odometry", "icp", "imu", "vessel"):
            raise ValueError(f"motion must be 'odometry', 'icp', 'imu' or 'vessel', not {motion!r}")
        if motion == "icp" and match is None:
            if not icp_available():
                raise ValueError("ICP motion needs graphnav.scan.weighted_icp (not installed in this build)")
            from ..scan.icp_cache import match_scans as match  # weighted ICP, shared inside icp_cache.active()
        unknown = set(gating) - set(GATING_DEFAULTS)
        if unknown:
            raise ValueError(f"unknown ekf option(s): {sorted(unknown)}")
        unknown = set(imu or {}) - set(IMU_DEFAULTS)
        if unknown:
            raise ValueError(f"unknown ekf option(s): {sorted(unknown)}")
        self.imu_opts = io = {**IMU_DEFAULTS, **(imu or {})}
        self.vessel = vessel_model(io) if motion == "vessel" else None
        self.water = _water(io)
        self.zeros = ZeroReadings(io["stall_speed"])  # the speed log's zero readings (graph.speed_log)
        #: motion="vessel" with a rate of turn: its records (the graph's vessel model's gyro z), the heading's rate
        self.rot: RotChain | None = None
        if motion in ("imu", "vessel"):
            bias, cur = bool(io["bias"]) and motion == "imu", bool(io["current"])
            sb = (io["sigma_bias_acc"], math.radians(io["sigma_bias_gyro_deg"]))
            rw = (io["acc_bias_rw"], io["gyro_bias_rw"])
            if motion == "vessel" and io["vessel_rot"]:  # the ROT's bias: the graph's gyro-z bias state
                from ..graph.imu_chain import ImuConfig, RotChain, rot_bias

                self.rot = RotChain(ImuConfig())
                bias = bool(io["bias"])
                b0, brw = rot_bias(ImuConfig())
                sb, rw = (0.0, b0), (0.0, brw)  # (no accelerometer: its bias states stay 0)
            cb = compass_bias_on(io["compass_bias"], motion, cur)
            (kb0, kbrw) = compass_bias_model() if cb else (0.0, 0.0)
            ls = resolve_flag(io["log_scale"], cur, "log_scale")
            if ls and not cur:
                raise ValueError("ekf option log_scale needs the current states (current=true)")
            vx, vy, sv = io["v0"]
            x = [*np.asarray(x0, float)[:3], vx, vy] + [0.0] * (3 * bias) + [0.0] * (2 * cur) + [1.0] * ls \
                + [0.0] * cb
            d = [sv ** 2] * 2 + [sb[0] ** 2] * (2 * bias) + [sb[1] ** 2] * bias \
                + [io["sigma_current0"] ** 2] * (2 * cur) + [io["sigma_log_scale"] ** 2] * ls + [kb0 ** 2] * cb
            P = np.zeros((len(x), len(x)))
            P[:3, :3] = np.asarray(P0, float)[:3, :3]
            P[3:, 3:] = np.diag(d)
            if cb and compass_yaw:
                yaw_from_compass(P, 2, kb0)
            self.f: PoseEkf = InsEkf(np.array(x), P, bias=bias, current=cur, acc_density=io["acc_density"],
                                     gyro_density=io["gyro_density"], acc_bias_rw=rw[0],
                                     gyro_bias_rw=rw[1], current_rw=io["q_current"], compass_bias=cb,
                                     compass_bias_rw=kbrw, log_scale=ls, log_scale_rw=io["q_log_scale"], gate=gate,
                                     **gating)
        else:
            self.f = PoseEkf(x0, P0, gate=gate, **gating)
        self.motion = motion
        self.kinds: tuple[type, ...] = {"odometry": (Gnss, Heading, Odometry), "icp": (Gnss, Heading, Scan),
                                        "imu": (Gnss, Heading, Imu, GnssVelocity, WaterSpeed, Odometry),
                                        "vessel": (Gnss, Heading, GnssVelocity, WaterSpeed, Odometry)}[motion]
        self.sigma_v, self.sigma_w, self.sigma_acc = sigma_v, sigma_w, sigma_acc
        self.use_gnss, self.use_heading = use_gnss, use_heading
        self.match = match
        self.t: float | None = None  # time of the latest record taken (the state is reported at it)
        self.u: Odometry | None = None  # the held control
        self.imu_u: Imu | None = None  # the held IMU record
        self.prev_scan: Scan | None = None
        self.last_inc, self.last_cov = np.zeros(3), np.eye(3)
        self.inc_dt: float | None = None  # [s] the interval of the last scan increment
        self.icp_failed = 0
        self.step_ms: deque[float] = deque(maxlen=keep)
        self.icp_ms: deque[float] = deque(maxlen=keep)

    def uses(self, r: Record) -> bool:
        """Whether :meth:`step` takes this record (the others are ignored)."""
        return isinstance(r, self.kinds)

    def step(self, r: Record) -> bool:
        """Process one record (time order); False if its type is not used."""
        if not isinstance(r, self.kinds):
            return False
        if self.t is None:
            self.t = r.t
        f = self.f
        if isinstance(r, Scan):
            if self.prev_scan is not None:
                inc, cov = self._icp_increment(r, self.prev_scan)
                if r.t > self.prev_scan.t:
                    self.inc_dt = r.t - self.prev_scan.t  # the interval of the last increment (coasting)
                t0 = time.perf_counter()
                f.predict_increment(inc, cov)
                self.step_ms.append((time.perf_counter() - t0) * 1e3)
            self.prev_scan = r
            self.t = r.t
            return True
        t0 = time.perf_counter()
        if self.rot is not None and isinstance(r, Odometry):  # the rate over the interval up to r.t
            self.rot.add_rot(r)
        if r.t > self.t:  # (with ICP motion the state only moves at scans, but it is reported at r.t)
            # an IMU record is the mean over its own interval
            self._predict(f, r.t - self.t, r if isinstance(r, Imu) else self.imu_u)
            self.t = r.t
        io = self.imu_opts
        if isinstance(r, Imu):
            self.imu_u = r
        elif isinstance(r, Odometry) and self.motion in ("imu", "vessel"):
            if io["use_odometry"]:
                f.update_sog(r.v, _sig(r.sigma_v, self.sigma_v), r.t)  # type: ignore[attr-defined]
        elif isinstance(r, Odometry):
            self.u = r
            if f.has_speed:
                f.update_speed(r.v, _sig(r.sigma_v, self.sigma_v), r.t)
        elif isinstance(r, Gnss) and self.use_gnss:
            f.update_position((r.x, r.y), r.sigma, r.t)
        elif isinstance(r, Heading) and self.use_heading:
            f.update_heading(r.yaw, r.sigma, r.t)
        elif isinstance(r, GnssVelocity) and io["use_velocity"]:
            f.update_velocity((r.vx, r.vy), _sig(r.sigma, io["sigma_gnss_velocity"]), r.t)  # type: ignore
        elif isinstance(r, WaterSpeed) and io["current"]:
            self._water_speed(f, r)
        self.step_ms.append((time.perf_counter() - t0) * 1e3)
        return True

    def _water_speed(self, f: PoseEkf, r: WaterSpeed) -> None:
        """The speed through water ``r``: the water model's update, a zero reading censored below the log's stall
        speed (:mod:`graphnav.graph.speed_log`; not used before one is known)."""
        assert isinstance(f, InsEkf)
        sigma = _sig(r.sigma_v, self.imu_opts["sigma_water_speed"])
        how = self.zeros.see(r.v)
        if how == "plain":
            f.update_water_speed(r.v, sigma, r.t, leeway=self.water.leeway_sigma(r.v))
        elif how == "censored":
            f.update_water_zero(*self.zeros.sigmas(sigma, self.water.leeway_sigma(0.0)), r.t)

    def _predict(self, f: PoseEkf, T: float, m: Imu | None) -> None:
        """Filter ``f`` moved ``T`` seconds by the motion model: the unicycle with the held control, the IMU
        record ``m`` held, or the vessel model (with ICP motion the state moves at scans only)."""
        u = self.u
        if u is not None and self.motion == "odometry":
            f.predict_odometry(u.v, u.w, T, _sig(u.sigma_v, self.sigma_v), _sig(u.sigma_w, self.sigma_w),
                               self.sigma_acc)
        elif self.motion == "imu":
            if m is not None:
                f.predict_imu(m.ax, m.ay, m.wz, T)  # type: ignore[attr-defined]
        elif self.vessel is not None:
            self._predict_vessel(T, f)

    def coast(self, t: float) -> PoseEkf | None:
        """A copy of the filter predicted to ``t`` (coasting through a gap without records): the motion model
        with the held inputs (odometry: the unicycle with the held control; the IMU record held; the vessel
        model; ICP: the last increment's constant twist, with the constant-velocity bridge's covariance,
        :data:`~graphnav.scan.motion_guess.CV_BRIDGE_SIGMA`, per scan interval, as a failed match), the
        covariance grown by that model's process noise. ``None``: the model has nothing to move with yet (no
        control, IMU record or scan increment). The filter itself is untouched."""
        if self.t is None or t < self.t:
            return None
        if (self.motion == "odometry" and self.u is None) or (self.motion == "imu" and self.imu_u is None) \
                or (self.motion == "icp" and (self.inc_dt is None or self.prev_scan is None)):
            return None
        g = copy.copy(self.f)  # the predictions replace x and P (they never touch the gate)
        g.x, g.P = self.f.x.copy(), self.f.P.copy()
        if self.motion == "icp":
            assert self.prev_scan is not None and self.inc_dt is not None
            import gtsam

            from ..scan.motion_guess import CV_BRIDGE_SIGMA

            frac = (t - self.prev_scan.t) / self.inc_dt
            twist = np.asarray(gtsam.Pose2.Logmap(gtsam.Pose2(*self.last_inc)))
            inc = gtsam.Pose2.Expmap(twist * frac)
            g.predict_increment(np.array([inc.x(), inc.y(), inc.theta()]), np.diag(np.square(CV_BRIDGE_SIGMA)) * frac)
        else:
            self._predict(g, t - self.t, self.imu_u)
        return g

    def _predict_vessel(self, T: float, f: PoseEkf | None = None) -> None:
        """The vessel model over ``T`` (:meth:`InsEkf.predict_vessel`) on ``f`` (default: the filter), its
        yaw-rate density the graph's: x ``steerage / speed`` through the water below steerage speed, at most x10."""
        vm, f = self.vessel, self.f if f is None else f
        assert vm is not None and isinstance(f, InsEkf)
        from ..graph.imu_chain import yaw_rate_scale

        scale = yaw_rate_scale(f.speed_through_water(), vm["vessel_steerage_speed"])
        rot = None
        if self.rot is not None and self.t is not None:  # the rate of turn over the interval, as the graph's
            yaw = self.rot.interval(self.t, self.t + T)
            rot = (float(np.sum(yaw[0] * yaw[1])), yaw[2]) if yaw is not None else None
            self.rot.prune(self.t)
        f.predict_vessel(T, accel_density=vm["vessel_accel"],
                         yaw_density=scale * math.radians(vm["vessel_yaw_rate_deg"]),
                         position_walk=vm["vessel_position_walk"], rot=rot)

    def _icp_increment(self, scan: Scan, prev: Scan) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Body-frame increment prev -> scan and its covariance (a failed match re-uses the last
        increment as a constant-velocity step with the stated sigma of that motion model,
        :data:`graphnav.scan.motion_guess.CV_BRIDGE_SIGMA`, as icp-dr does without odometry). The one
        place the EKF matches scans."""
        t0 = time.perf_counter()
        res = self.match(scan, prev, init=self.last_inc)
        self.icp_ms.append((time.perf_counter() - t0) * 1e3)
        if res.ok:
            self.last_inc, self.last_cov = np.asarray(res.pose, float), np.asarray(res.cov_target, float)
            return self.last_inc, self.last_cov
        self.icp_failed += 1
        from ..scan.motion_guess import CV_BRIDGE_SIGMA

        return self.last_inc, np.diag(np.square(CV_BRIDGE_SIGMA))


def auto_motion(log: NavLog, least: int = 2) -> str:
    """``motion="auto"``: the graph's choice for a vessel's instruments (``"vessel"``,
    :func:`graphnav.graph.smoother_config.auto_motion`: a compass with GNSS velocity or water speed, no
    IMU, odometer or LiDAR; a rate of turn with the SOG is no odometer); else odometry if the log has
    it, else the IMU, else ICP on the scans, else (GNSS alone) the vessel model. A rate of turn with the
    SOG gives way to an IMU: as a unicycle it moves a boat along its bow at its speed over ground (Solent
    s1-s3: 9.07 / 13.93 / 14.23 m, NEES 308-814; with the IMU 1.56 / 4.04 / 2.25 m). ``least``: records of a
    kind that make it count."""
    from ..graph.smoother_config import auto_motion as graph_motion
    from ..log import odometry_is_rot

    if graph_motion(log.counts(), log.meta) == "vessel":
        return "vessel"
    rot = odometry_is_rot(log.meta)
    if len(log.of("odometry")) >= least and not (rot and len(log.of("imu")) >= least):
        return "odometry"
    if len(log.of("imu")) >= least:
        return "imu"
    return "icp" if len(log.of("scan")) >= least or not log.of("gnss") else "vessel"


def imu_options(log: NavLog, given: dict[str, Any], motion: str | None = None) -> dict[str, Any]:
    """The IMU motion's options for ``log`` (:data:`IMU_DEFAULTS`): the noise densities and bias
    random walks of the log's IMU model (:func:`graphnav.estimators.imu_model.imu_noise`, the
    graph's), bias states when the IMU has a bias and current states when the log has water speed
    (``"auto"``), the speed log's scale state with the current states when the log has water speed, the
    compass-bias state when the log has a compass and GNSS and ``motion`` (default: the IMU's
    if the log has one, else the vessel model's) ties the heading to the track (:func:`compass_bias_on`), the
    initial velocity from ``meta["initial_velocity"]`` or the first GNSS velocity;
    ``given`` (options of the same names) wins."""
    from ..log import odometry_is_rot
    from .imu_model import imu_noise, wants_bias

    m = imu_noise(log)
    given = dict(given)
    out: dict[str, Any] = {**IMU_DEFAULTS, "acc_density": m["acc_std"] / math.sqrt(m["hz"]),
                           "gyro_density": m["gyro_std"] / math.sqrt(m["hz"]),
                           "acc_bias_rw": m["acc_bias_rw"], "gyro_bias_rw": m["gyro_bias_rw"]}
    rot = given.get("vessel_rot")
    out["vessel_rot"] = rot = (odometry_is_rot(log.meta) and bool(log.of("odometry"))
                               and not log.of("imu")) if rot is None else bool(rot)
    out["bias"] = (resolve_flag(given.pop("bias", "auto"), wants_bias(log)[0], "bias") if log.of("imu")
                   else rot and resolve_flag(given.pop("bias", "auto"), True, "bias"))  # the ROT's bias
    out["current"] = resolve_flag(given.pop("current", "auto"), bool(log.of("water_speed")), "current")
    out["log_scale"] = resolve_flag(given.pop("log_scale", "auto"), out["current"] and bool(log.of("water_speed")),
                                    "log_scale")
    # the compass bias: observable with a compass and GNSS (position or velocity) to hold the heading against
    out["compass_bias"] = resolve_flag(given.pop("compass_bias", "auto"), bool(log.of("heading")) and bool(
        log.of("gnss") or log.of("gnss_velocity")) and compass_bias_on(
        "auto", motion or ("imu" if log.of("imu") else "vessel"), out["current"]), "compass_bias")
    v0 = log.meta.get("initial_velocity") if isinstance(log.meta, dict) else None
    gv = log.of("gnss_velocity")
    t0 = log.t0
    if v0 is not None:
        out["v0"] = (float(v0[0]), float(v0[1]), 0.2)
    elif gv and t0 is not None and gv[0].t - t0 <= 1.0:
        out["v0"] = (gv[0].vx, gv[0].vy, 3.0 * _sig(gv[0].sigma, out["sigma_gnss_velocity"]))
    if not log.of("imu") and given.get("vessel_position_walk") is None:  # the vessel model: the log's walk
        from ..graph.position_walk import position_walk

        walk = position_walk(log)
        if walk is not None:
            out["vessel_position_walk"] = walk["walk"]
    out.update({k: v for k, v in given.items() if v is not None or k not in IMU_DEFAULTS})
    return out


def run_ekf(log: NavLog, *, on_estimate: OnEstimate | None = None, motion: str = "auto", speed: bool = False,
            gate: float | None = 0.999, sigma_v: float = 0.5,
            sigma_w: float = math.radians(0.5), sigma_acc: float = 0.5, use_gnss: bool = True,
            use_heading: bool = True, **gating: Any) -> RunResult:
    """EKF over a log. ``motion``: ``"odometry"``, ``"imu"``, ``"icp"`` or ``"auto"``
    (:func:`auto_motion`: odometry if the log has it, else the IMU, else ICP on the scans). ``gate``:
    chi-square probability (``None`` disables gating); ``gating``: the other options of
    :class:`~graphnav.estimators.gating.InnovationGate` (``reinit_n``, ``confirm_n``, ``confirm_s``,
    ``reinit_after_s``, ``scale_window``) and the IMU motion's (:data:`IMU_DEFAULTS`, filled from the
    log by :func:`imu_options`). Sigmas in the records win over ``sigma_v``/``sigma_w``. One estimate
    per record time."""
    live = sorted(k for k in LIVE_ONLY if gating.pop(k, None) is not None)
    if live:
        logging.getLogger("graphnav.ekf").warning("ekf option(s) %s apply to graphnav live only: ignored", live)
    if motion == "auto":
        motion = auto_motion(log)
    imu_given = {k: gating.pop(k) for k in list(gating) if k in IMU_DEFAULTS or k == "bias" or k == "current"}
    imu = imu_options(log, imu_given, motion) if motion in ("imu", "vessel") else None
    for k in ("compass_bias", "log_scale"):  # (auto: no such state without InsEkf's motions)
        if imu_given.get(k, "auto") == "auto":
            imu_given.pop(k, None)
    if imu_given and motion not in ("imu", "vessel"):
        raise ValueError(f"ekf option(s) {sorted(imu_given)} need motion='imu' or 'vessel'")
    x0, P0, anchor = initial_state(log.records, speed)
    st = EkfStepper(x0, P0, motion=motion, gate=gate, sigma_v=sigma_v,
                    sigma_w=sigma_w, sigma_acc=sigma_acc, use_gnss=use_gnss, use_heading=use_heading,
                    imu=imu, compass_yaw=compass_yaw(anchor, P0), **gating)
    recs = [r for r in log.records if st.uses(r)]
    if motion == "imu":  # at equal times the IMU record (the motion up to t) before the measurements at t
        recs.sort(key=lambda r: (r.t, not isinstance(r, Imu)))
    if not recs:
        raise ValueError("ekf: the log has no usable records")
    ts, poses, covs = [], [], []
    ahead = 0  # the rate of turn up to t before the measurements at t (the SOG updates keep their place)
    for i, r in enumerate(recs):
        while st.rot is not None and ahead < len(recs) and recs[ahead].t <= r.t:
            if isinstance(recs[ahead], Odometry):
                st.rot.add_rot(recs[ahead])
            ahead += 1
        st.step(r)
        if i + 1 == len(recs) or recs[i + 1].t > r.t:  # the last record of this time
            ts.append(r.t)
            poses.append(st.f.x[:3].copy())
            covs.append(st.f.P[:3, :3].copy())
            if on_estimate is not None:
                on_estimate(r.t, poses[-1], covs[-1])
    traj = Trajectory(np.array(ts), np.array(poses), np.array(covs), name="ekf")
    info: dict[str, Any] = {"anchor": anchor, "motion": motion, "speed_state": speed,
                            **st.f.gater.info(), "icp_failed": st.icp_failed}
    if imu is not None:
        f = st.f
        info.update(bias_states=imu["bias"], current_states=imu["current"],
                    process_noise=dict(st.vessel, q_current=imu["q_current"]) if st.vessel is not None else
                    {k: imu[k] for k in ("acc_density", "gyro_density", "acc_bias_rw", "gyro_bias_rw", "q_current")})
        if imu["bias"]:
            info["bias_final"] = f.x[5:8].tolist()
        if imu["current"]:
            ic = 5 + 3 * imu["bias"]
            info["current_final"] = f.x[ic:ic + 2].tolist()
        il = getattr(f, "il", None)
        if il is not None:
            info["process_noise"]["q_log_scale"] = imu["q_log_scale"]
            info["log_scale_final"] = float(f.x[il])
            info["log_scale_sigma"] = math.sqrt(float(f.P[il, il]))
        info["log_scale_state"] = il is not None
        info.update(st.zeros.info())
        ik = getattr(f, "ik", None)
        info["compass_bias_state"] = ik is not None
        if ik is not None:
            info["compass_bias_final_deg"] = math.degrees(float(f.x[ik]))
            info["compass_bias_sigma_deg"] = math.degrees(math.sqrt(float(f.P[ik, ik])))
    return RunResult(traj, traj, np.array(st.step_ms), np.array(st.icp_ms), info=info)


def _unmet(log: NavLog) -> str | None:
    has_odo = len(log.of("odometry")) >= 2
    has_imu = len(log.of("imu")) >= 2
    has_scans = len(log.of("scan")) >= 2
    if not has_odo and not has_imu and not (has_scans and icp_available()) and not log.of("gnss"):
        extra = " (scans need graphnav.scan.weighted_icp, not installed)" if has_scans else ""
        return "needs odometry, imu, LiDAR or GNSS records" + extra
    return None


def _inputs(log: NavLog, options: dict) -> set[str]:
    """The kinds :func:`run_ekf` reads with ``options``: its motion's (odometry, IMU or scans), the
    updates it makes, and its start (:func:`initial_state`)."""
    motion = options.get("motion", "auto")
    if motion == "auto":
        motion = auto_motion(log)
    kinds = {"pose_prior", {"odometry": "odometry", "imu": "imu", "icp": "scan", "vessel": "gnss"}[motion]}
    if options.get("use_gnss", True):
        kinds.add("gnss")
    if options.get("use_heading", True):
        kinds.add("heading")
    if motion in ("imu", "vessel"):
        if options.get("use_velocity", True):
            kinds.add("gnss_velocity")
        if options.get("current", "auto") not in (False, "false"):
            kinds.add("water_speed")
        if options.get("use_odometry", True):
            kinds.add("odometry")  # speed over ground, an update
    if options.get("speed", False):
        kinds.add("odometry")  # the speed state starts at the first odometry speed
    if log.pose_prior() is None and log.of("gnss"):
        kinds |= {"gnss", "heading"}  # the start: the first fix and compass heading
    return kinds


@dataclass
class ImuMotionOptions:
    """The IMU motion's options (``motion=imu``); null: from the log (:func:`imu_options`)."""

    group: ClassVar[str] = "IMU and vessel motion (motion=imu, motion=vessel)"
    acc_density: float | None = option(None, "accelerometer noise density (null: the log's meta['imu'])",
                                       unit="m/s^2/sqrt(Hz)")
    gyro_density: float | None = option(None, "gyro noise density (null: the log's meta['imu'])",
                                        unit="rad/s/sqrt(Hz)")
    acc_bias_rw: float | None = option(None, "accelerometer bias random walk (null: the log's meta['imu'])",
                                       unit="m/s^2/sqrt(s)")
    gyro_bias_rw: float | None = option(None, "gyro bias random walk (null: the log's meta['imu'])",
                                        unit="rad/s/sqrt(s)")
    bias: bool | str = option("auto", "bias states: auto (unless meta['imu'] says bias_free), true, false")
    current: bool | str = option("auto", "water-current states: auto (when the log has water_speed), true, false")
    compass_bias: bool | str = option(
        "auto", "a compass-bias state (the compass reads yaw + b; the graph's prior [compass] bias_sigma_deg and "
        "random walk bias_drift_deg): auto (a compass and GNSS position or velocity, with the IMU motion, or the "
        "vessel motion with the current states: what ties the heading to the track), true, false")
    sigma_bias_acc: float = option(0.01, "prior on the residual accelerometer bias", unit="m/s^2")
    sigma_bias_gyro_deg: float = option(0.1, "prior on the residual gyro bias", unit="deg/s")
    sigma_current0: float = option(0.5, "prior 1-sigma of the water current", unit="m/s")
    q_current: float = option(0.005, "water-current random walk", unit="m/s/sqrt(s)")
    log_scale: bool | str = option(
        "auto", "the speed log's scale state k (the speed through water along the bow is k x the reading; the "
        "graph's): auto (with the current states, when the log has water_speed), true, false")
    sigma_log_scale: float = option(0.1, "prior 1-sigma of the speed log's scale (around 1: a log within 10 %)")
    q_log_scale: float = option(5e-4, "the speed log's scale: random walk", unit="1/sqrt(s)")
    v0: list[float] | None = option(None, "initial velocity [vx, vy, sigma] (null: meta initial_velocity, else the "
                                    "first GNSS velocity)")
    sigma_gnss_velocity: float = option(0.1, "GNSS velocity sigma when the record gives none", unit="m/s")
    sigma_water_speed: float = option(0.1, "water-speed sigma when the record gives none", unit="m/s")
    stall_speed: float | None = option(None, "a zero water-speed reading (a stalled paddle wheel) says only that the "
                                       "speed through water is below this: censored, with this / sqrt(3) added to "
                                       "both sigmas, no scale (null: the smallest non-zero reading so far; before "
                                       "one a zero is not used; the graph's [water] stall_speed)", unit="m/s")
    use_velocity: bool = option(True, "false: GNSS velocities are not used")
    use_odometry: bool = option(True, "false: odometry speeds are not used as SOG updates")
    water_leeway: float | None = option(None, "water speed across the bow: sigma hypot(this, water_leeway_rel |v|) "
                                        "(null: the graph's, [water] leeway)", unit="m/s")
    water_leeway_rel: float | None = option(None, "... x |v| (null: the graph's, [water] leeway_rel)")
    vessel_accel: float | None = option(None, "motion=vessel: manoeuvring acceleration density (null: the graph's "
                                        "vessel model, [imu] vessel_accel)", unit="m/s^2/sqrt(s)")
    vessel_yaw_rate_deg: float | None = option(None, "motion=vessel: yaw-rate density under way (null: the graph's)",
                                               unit="deg/s/sqrt(s)")
    vessel_steerage_speed: float | None = option(None, "motion=vessel: below this speed through the water the "
                                                 "yaw-rate density grows as 1/speed, at most x10 (null: the graph's)",
                                                 unit="m/s")
    vessel_position_walk: float | None = option(None, "motion=vessel: the position's own random walk (null: the "
                                                "log's, fixes against GNSS velocity, as the graph)", unit="m/sqrt(s)")
    vessel_rot: bool | None = option(None, "motion=vessel: odometry records are a rate of turn that turns the heading "
                                     "(the graph's vessel model's gyro z, its bias a state; null: when the log's "
                                     "meta['odometry'] says so and it has no IMU)")


@dataclass
class EkfLiveOptions:
    """The live filter's options (:class:`graphnav.estimators.ekf_online.EkfOnline`, ``graphnav live -e ekf``);
    a batch run has no output stream and ignores them (with a warning)."""

    group: ClassVar[str] = "live only (graphnav live -e ekf)"
    emit: str = option("fix", "fix: an estimate per GNSS fix, and per used record after outage_s without one; "
                       "all: one per used record")
    outage_s: float = option(1.5, "emit=fix: no fix for this long and every used record yields an estimate", unit="s")
    init_wait: float = option(2.0, "the filter starts at the first complete epoch with a fix and a heading, or this "
                              "long after the first fix; motion=auto is final this long after it", unit="s")
    coast_hz: float | None = option(None, "the output's rate through a silent stream: the filter's predictions "
                                    "(flagged coasted) on this grid; None: the estimates' own rate; 0: off "
                                    "(as the graph's coast_hz)", unit="Hz")
    coast_max_s: float | None = option(None, "coasting stops this long after the newest real estimate (None: no "
                                       "limit, the covariance grows with the motion model's noise)", unit="s")


#: the options only the live filter reads
LIVE_ONLY = tuple(f.name for f in fields(EkfLiveOptions))


@dataclass
class EkfConfig(EkfLiveOptions, ImuMotionOptions, GateOptions):
    """The ``ekf`` estimator's options (:func:`run_ekf`)."""

    group: ClassVar[str] = "ekf"
    motion: str = option("auto", "odometry, imu, icp, vessel or auto (vessel for a compass with GNSS velocity or "
                         "water speed and no IMU, odometer or LiDAR, as the graph; else odometry if the log has it, "
                         "else the IMU, else ICP on the scans, else vessel)")
    speed: bool = option(False, "true: the state is [x, y, yaw, v] (v a random walk, the odometry speed a "
                         "measurement of it)")
    sigma_v: float = option(0.5, "odometry speed sigma when the record gives none", unit="m/s")
    sigma_w: float = option(math.radians(0.5), "odometry rate-of-turn sigma when the record gives none",
                            unit="rad/s")
    sigma_acc: float = option(0.5, "speed state (speed=true): its random walk", unit="m/s^2")
    use_gnss: bool = option(True, "false: GNSS fixes are not used")
    use_heading: bool = option(True, "false: compass headings are not used")
