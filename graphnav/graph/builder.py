"""The navigation graph, built record by record: every sensor of a log as native GTSAM factors on
``Pose2`` keyframes, one factor batch per keyframe for the solver (:mod:`graphnav.graph.solver`).

:class:`GraphBuilder` is fed records in time order (:meth:`~GraphBuilder.push`) and decides online

* **the anchor**: records are held until it can be chosen (a ``pose_prior``; or a GNSS fix and a
  compass reading; or two charted beacons sighted together; else, ``anchor_wait`` seconds of log
  time after the first record, the first GNSS fix, one charted sighting, the first truth pose or
  the origin -- the same priority as a look at the whole log), then the held records are replayed;
* **the keyframes**: one per scan (every ``scan_stride``-th) once scans arrive, else a
  ``keyframe_period`` grid from the first record (:mod:`graphnav.graph.keyframes`) -- where no
  record came for ``grid_gap`` seconds (a GNSS outage of a GNSS-only log) the slots inside the
  gap are skipped: no input, no pose (the motion factor spans the gap);
* **the attachment**: a measurement between two keyframes waits for the later one, joins the
  nearer of the two (ties: the earlier) and is added with the later keyframe's batch, exactly as
  :func:`graphnav.graph.keyframes.schedule` does on a whole log; a keyframe's batch is ready when a
  record later than it arrives (or at :meth:`~GraphBuilder.finish`), so every record stamped at
  or before the keyframe is in it and none after it (causal).

Per keyframe ``k`` (:meth:`~GraphBuilder.step`): a **motion factor** ``X(k-1) -> X(k)`` always --
the odometry integrated over the interval (beacon paper eq. 3-5), else a constant-velocity
prediction from the last measured motion or a random walk, with a sigma that grows with ``dt``
and a floor that keeps ``dt = 0`` proper --; the weighted-ICP match of the keyframe's scan to the
previous one with the matcher's covariance (a degenerate match is kept: its covariance is inflated
along the directions it does not observe); and the measurements due: robust GNSS
(``PoseTranslationPrior2D``, gated online by the Mahalanobis distance to the prediction), compass
through an estimated bias frame, ``BearingRangeFactor2D`` beacons (charted ones with a chart
prior, unknown ones initialised from their first sighting) and later ``pose_prior`` records. Each
factor carries its sensor group (:data:`GROUPS`), which the noise estimation uses.
"""

from __future__ import annotations

import bisect
import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..config import OptionError
from ..geometry import cov_to_world
from ..log import (
    Cloud,
    Gnss,
    KnownBeacon,
    PosePrior,
    Record,
    Scan,
)
from .anchor import anchor_ready, choose_anchor
from .imu_chain import ImuChain, ImuConfig, relative_prediction
from .keyframes import DEFAULT_PERIOD
from .measurements import Measurements
from .mounts import parse_mounts
from .odometry_buffer import OdometryBuffer
from .scan_factors import (  # noqa: F401  (Matcher, default_matcher, make_loop_closer: the graph's public names)
    UNOBSERVED_COV,
    CloudPath,
    Matcher,
    default_matcher,
    make_loop_closer,
    mounted,
    proper_cov,
    screen_match,
)
from .smoother_config import SmootherConfig
from .space import IB, NavSpace, PlanarSpace, V
from .step import Step

#: sensor groups of the factors (the noise estimation scales ``SCALABLE`` ones)
GROUPS = ("anchor", "odometry", "motion", "icp", "loop", "gnss", "compass", "bias", "beacon", "chart", "pose_prior",
          "cloud", "imu", "imu_bias", "gnss_velocity", "water_speed", "current", "attitude")
SCALABLE = ("odometry", "motion", "icp", "gnss", "compass", "beacon", "cloud")
EPS = 1e-9  # [s] times closer than this are equal (as keyframes.schedule)
FIX_RESOLUTION_M = 1e-3  # [m] below any receiver's resolution: a fit's scatter under it says nothing of the noise
MIN_IMU_DT = 1e-4  # [s] keyframes closer than this share their state (no ImuFactor: its covariance would vanish)
V0_STATED_SIGMA = 0.2  # [m/s] 1-sigma of an initial velocity the log states (meta["initial_velocity"])
#: the Pose3 graph's estimate of the previous keyframe: pose, nav-frame velocity, IMU bias, velocity covariance
NavPrev = tuple[gtsam.Pose3, NDArray[np.float64], gtsam.imuBias.ConstantBias, NDArray[np.float64] | None]
MEASUREMENTS = ("gnss", "heading", "beacon", "pose_prior", "gnss_velocity", "water_speed", "attitude")


class GraphBuilder:
    """Records in, per-keyframe factor batches out (see the module docstring).

    ``chart``: charted beacons; ``lidar``: the log's LiDAR error model (``sigma_r_rel``,
    ``sigma_alpha``); ``scans``: whether the log has scans (``None``: decided by the first scan --
    a grid until then); ``matcher``: replaces the weighted ICP (tests).
    """

    def __init__(self, cfg: SmootherConfig, *, matcher: Matcher | None = None,
                 chart: Iterable[KnownBeacon] = (), lidar: dict[str, Any] | None = None,
                 scans: bool | None = None, lidar3d: dict[str, Any] | None = None,
                 imu: bool | None = None, imu_model: dict[str, Any] | None = None) -> None:
        self.cfg = cfg
        # the state space: Pose3 + velocity + IMU bias when the log has an IMU (motion "auto") or
        # when asked ("imu"; "vessel": the same without an IMU, a white-noise acceleration model)
        nav = cfg.motion in ("imu", "vessel") or (cfg.motion == "auto" and bool(imu))
        self.space: PlanarSpace = NavSpace() if nav else PlanarSpace()
        self.imu: ImuChain | None = ImuChain(ImuConfig(**cfg.imu), imu_model) if nav else None
        self.mounts = parse_mounts(cfg.mounts)
        if self.imu is not None and "imu" in self.mounts:  # GTSAM's body_P_sensor (docs/mounts.md)
            self.imu.body_P_sensor = self.mounts["imu"].pose3()
        lidar_mount = self.mounts.get("lidar")
        self.extrinsic = None if lidar_mount is None or lidar_mount.is_identity else gtsam.Pose2(*lidar_mount.planar)
        self.imu_model = imu_model
        self.cloud3d = CloudPath(cfg, lidar3d, self.extrinsic)  # the 3D path (clouds): graphnav.scan.cloud_match
        self.charted = {b.id: b for b in chart}
        icp_opts = dict(cfg.icp)
        for k in ("sigma_r_rel", "sigma_alpha"):  # the log's LiDAR error model, when it states one
            if lidar and k in lidar and k not in icp_opts:
                icp_opts[k] = float(lidar[k])
        self._matcher_given = matcher
        self._icp_opts = icp_opts
        self.matcher: Matcher | None = None
        self.loops: Any = None  # graphnav.graph.loops.LoopCloser, with scans and cfg.loops
        self._loop_cov: NDArray[np.float64] | None = None  # the loop closer's covariance of the newest pose
        self._icp_cov: NDArray[np.float64] | None = None  # the newest accepted ICP factor's covariance
        # keyframe policy: "grid" (fixed period) or "scan"; with keyframe_period set always the grid
        self.grid_only = cfg.keyframe_period is not None
        self.period = cfg.keyframe_period if cfg.keyframe_period is not None else DEFAULT_PERIOD
        self.mode = "scan" if (scans and not self.grid_only) else "grid"
        if self.mode == "scan":
            self._want_matcher()
        self.kf_t: list[float] = []
        self.stepped = 0  # keyframes [0, stepped) have their batch
        self.grid_t0: float | None = None
        self.grid_i = 0  # the next grid slot
        self.kf_scan: dict[int, Scan] = {}
        self.n_scans = 0
        self.lidar_kind: str | None = None  # "scan" or "cloud": the first LiDAR record's kind drives the keyframes
        self.pending: list[Record] = []  # measurements after the newest keyframe
        self.due: dict[int, list[tuple[int, Record]]] = {}  # step -> (attach, record)
        self.late: list[tuple[int, Record]] = []  # after the last keyframe's batch (finish)
        self.odometry = OdometryBuffer(cfg)  # the odometry samples (graphnav.graph.odometry_buffer)
        self.held: list[Record] | None = []  # before the anchor is chosen
        self.t_last: float | None = None
        self.t_data: float | None = None
        self.finished = False
        # state carried between keyframes
        self.last_rel = gtsam.Pose2()  # relative motion of the newest interval
        self.last_gap = 0.0
        self.twist: NDArray[np.float64] | None = None  # [m/s, m/s, rad/s] of the last measured motion
        self.twist_t: float | None = None  # ... and its time
        self.fixes: deque[tuple[float, float, float, float]] = deque(maxlen=256)  # recent GNSS (t, x, y, sigma)
        self.gnss_twist: tuple[float, NDArray[np.float64], float] | None = None  # (t, twist, speed sigma)
        self.anchor_pose: NDArray[np.float64] | None = None
        self.anchor_sigmas: NDArray[np.float64] | None = None
        self.anchor: str | None = None
        self.counts = {"records": 0, "late": 0, "ignored": 0, "motion_fallback": 0}
        self.n_icp = self.n_icp_failed = self.n_icp_degenerate = self.n_icp_gated = 0
        self.defaulted: set[str] = set()  # groups whose sigmas came from the configuration
        # the measurement factors and their state (beacons, compass-bias frame, GNSS gate, water current)
        self.meas = Measurements(cfg, self.space, self.imu is not None, self.charted, self.kf_t, self.defaulted,
                                 self.counts)
        for name, g in self.mounts.items():  # the GNSS antennas: the sensor's, and each source's
            if name == "gnss" or name.startswith("gnss@"):
                self.meas.arms[name.partition("@")[2]] = (g.x, g.y, g.z)
        if "water_speed" in self.mounts:
            self.meas.log_yaw = self.mounts["water_speed"].yaw
            if abs(math.cos(self.meas.log_yaw)) < 0.5:
                raise OptionError("mounts.water_speed.yaw", "mounts.water_speed.yaw: a speed log more than 60 deg "
                                  f"off the bow measures no speed along it, got {self.meas.log_yaw:g} rad")

    # the measurement state the navigator reads (and, for the current, keeps up to date)
    @property
    def beacon_ids(self) -> dict[str, int]:
        return self.meas.beacon_ids

    @property
    def beacon_init(self) -> dict[str, NDArray[np.float64]]:
        return self.meas.beacon_init

    @property
    def bias_key(self) -> int | None:
        return self.meas.bias_key

    @property
    def current(self) -> tuple[int, int] | None:
        return self.meas.current

    @property
    def current_guess(self) -> NDArray[np.float64]:
        return self.meas.current_guess

    @current_guess.setter
    def current_guess(self, value: NDArray[np.float64]) -> None:
        self.meas.current_guess = value

    # -- records in ------------------------------------------------------------------------------
    @property
    def started(self) -> bool:
        return self.held is None

    def push(self, rec: Record | KnownBeacon) -> None:
        """Take one record (time-ordered; one older than the newest is counted and dropped)."""
        if isinstance(rec, KnownBeacon):
            self.charted[rec.id] = rec
            return
        self.counts["records"] += 1
        if self.held is not None:  # the anchor is chosen once the records of a time stamp are all in
            if (self.held and rec.t > self.held[-1].t + EPS
                    and anchor_ready(self.held, self.charted, self.cfg.anchor_wait, rec.t)):
                self._start()
            else:
                self.held.append(rec)
                if isinstance(rec, PosePrior):
                    self._start()
                return
        self._ingest(rec)

    def finish(self) -> None:
        """End of the records: every keyframe becomes ready; measurements after the last keyframe
        join it (in a batch of their own when its batch is already out)."""
        if self.finished:
            return
        if self.held is not None:
            self._start()
        self.finished = True
        if not self.kf_t:
            return
        last = len(self.kf_t) - 1
        for r in self.pending:
            if self.stepped > last:
                self.late.append((last, r))
            else:
                self.due.setdefault(last, []).append((last, r))
        self.pending = []

    def ready(self) -> list[int]:
        """Keyframes whose batch can be built now (in order)."""
        if self.finished:
            return list(range(self.stepped, len(self.kf_t)))
        if self.t_last is None:
            return []
        t_ready = self.t_last - EPS
        if self.imu:  # the IMU sample closing a keyframe's interval is awaited (a 1 Hz IMU: up to 1 s)
            t_ready = min(t_ready, self.imu.t[-1] + EPS)
        return [k for k in range(self.stepped, len(self.kf_t)) if self.kf_t[k] < t_ready]

    def _ingest(self, rec: Record) -> None:
        """One record. Records may come a little out of order (two sockets): a record is late, and
        dropped, only when its keyframe's batch is already out (a scan: when it is older than the
        newest keyframe)."""
        t = rec.t
        kind = rec.kind
        behind_batch = self.stepped > 0 and t < self.kf_t[self.stepped - 1] - EPS
        behind_scan = kind == "scan" and self.mode == "scan" and bool(self.kf_t) and t < self.kf_t[-1] - EPS
        if behind_batch or behind_scan:
            self.counts["late"] += 1
            return
        prev_t = self.t_data  # the last record with data (truth is a reference, not an input)
        if kind != "truth":
            self.t_data = t if self.t_data is None else max(self.t_data, t)
        self.t_last = t if self.t_last is None else max(self.t_last, t)
        self.counts[rec.kind] = self.counts.get(rec.kind, 0) + 1
        if self.mode == "grid":
            if self.grid_t0 is None:
                self.grid_t0 = t
            gap = prev_t is not None and kind != "truth" and t - prev_t > self.cfg.grid_gap
            while (kind != "truth" or prev_t is None or t - prev_t <= self.cfg.grid_gap) and (
                    ts := self.grid_t0 + self.period * self.grid_i) <= t + EPS * self.period:
                # no record for grid_gap seconds: the slots more than a period from both sides are skipped,
                # by index arithmetic (a jump of days must not walk its slots one by one)
                if gap and prev_t + self.period + EPS < ts < t - self.period - EPS:
                    self.grid_i = max(self.grid_i + 1,
                                      math.ceil((t - self.period - EPS - self.grid_t0) / self.period))
                    continue
                self.grid_i += 1
                self._new_keyframe(ts, None)
        if kind == "scan" or (kind == "cloud" and self.cfg.use_cloud):
            if self.lidar_kind is None:
                self.lidar_kind = kind
            elif kind != self.lidar_kind:  # a log with 2D scans and 3D clouds: the first kind is the LiDAR
                self.counts["ignored"] += 1  # (-O use_cloud=false picks the 2D scans)
                self.counts["lidar_other"] = self.counts.get("lidar_other", 0) + 1
                return
            if self.mode == "grid" and not self.grid_only:  # the first scan: one keyframe per scan from now on
                self.mode = "scan"
                self._want_matcher()
            if self.mode == "scan":
                if self._scan_is_keyframe(t):
                    self._new_keyframe(t, rec)
                self.n_scans += 1
        elif kind == "odometry":
            if self.cfg.use_odometry or (self.cfg.use_odometry is None and self.imu is None):
                if self.odometry.add(rec):
                    self.defaulted.add("odometry")
            else:
                self.counts["odometry_unused"] = self.counts.get("odometry_unused", 0) + 1
        elif kind in MEASUREMENTS:
            if isinstance(rec, Gnss):
                if self.fixes and t - self.fixes[-1][0] > self.cfg.gnss_gate_outage:
                    self.meas.after_outage.add(id(rec))  # the first fix after an outage is not gated
                self.fixes.append((rec.t, rec.x, rec.y, rec.sigma))
            if self.kf_t and t <= self.kf_t[-1] + EPS:  # at (or, late, before) the newest keyframe
                j = bisect.bisect_left(self.kf_t, t - EPS)  # the first keyframe at or after it: added there
                if j < self.stepped:
                    self.counts["late"] += 1
                    return
                a = j - 1 if j > 0 and t - self.kf_t[j - 1] <= self.kf_t[j] - t else j
                self.due.setdefault(j, []).append((a, rec))
            else:
                self.pending.append(rec)
        elif kind == "imu" and self.imu is not None:
            self.imu.add(rec)
        else:  # truth (a reference, not a measurement); imu on the planar graph; water speed, attitude
            self.counts["ignored"] += 1

    def _scan_is_keyframe(self, t: float) -> bool:
        """Every ``scan_stride``-th scan; with an IMU (``keyframe_motion``), only once the vessel has
        moved ``keyframe_distance`` (at the newest interval's speed) or turned ``keyframe_angle_deg``
        (the gyro) since the newest keyframe, or ``keyframe_max_dt`` has passed."""
        cfg = self.cfg
        if self.n_scans % cfg.scan_stride:
            return False
        use = cfg.keyframe_motion if cfg.keyframe_motion is not None else bool(self.imu)
        if not use or not self.kf_t or not self.imu:
            return True
        dt = t - self.kf_t[-1]
        if dt >= cfg.keyframe_max_dt - EPS:
            return True
        speed = math.hypot(self.last_rel.x(), self.last_rel.y()) / self.last_gap if self.last_gap > 0 else 0.0
        if speed * dt >= cfg.keyframe_distance:
            return True
        return self.imu.rotation(self.kf_t[-1], t) >= math.radians(cfg.keyframe_angle_deg)

    def _want_matcher(self) -> None:
        if self.matcher is None and self.cfg.use_icp:
            self.matcher = mounted(self._matcher_given if self._matcher_given is not None
                                   else default_matcher(self._icp_opts), self.extrinsic)
        if self.loops is None and self.cfg.loops:
            self.loops = make_loop_closer(self.cfg, self._icp_opts, self.extrinsic)

    def _new_keyframe(self, t: float, scan: Scan | None) -> None:
        k = len(self.kf_t)
        self.kf_t.append(t)
        if scan is not None:
            self.kf_scan[k] = scan
        for r in self.pending:  # they all lie in (t_{k-1}, t_k]: join the nearer keyframe, added now
            a = k - 1 if k > 0 and r.t - self.kf_t[k - 1] <= t - r.t else k
            self.due.setdefault(k, []).append((a, r))
        self.pending = []

    # -- anchor ----------------------------------------------------------------------------------
    def _start(self) -> None:
        held, self.held = sorted(self.held or [], key=lambda r: r.t), None
        self.anchor_pose, self.anchor_sigmas, self.anchor = choose_anchor(held, self.charted, self.cfg)
        if held:  # the grid starts at the first record, whatever it is (as keyframes.keyframe_times)
            self.grid_t0 = held[0].t
        first_prior = next((r for r in held if isinstance(r, PosePrior)), None)
        for r in held:
            if r is first_prior:  # it is the anchor
                continue
            self._ingest(r)

    # -- relative motion -------------------------------------------------------------------------
    def _offset_motion(self, a: int, t: float, k: int) -> gtsam.Pose2 | None:
        """Motion from keyframe ``a`` to time ``t`` (``None`` when they coincide): odometry when the
        log has it, else the newest relative motion scaled to the time offset (constant velocity)."""
        ta = self.kf_t[a]
        if abs(t - ta) < 1e-6:
            return None
        if self.odometry:
            if t > ta:
                odo = self.odometry.between(ta, t)
                return None if odo is None else odo[0]
            odo = self.odometry.between(t, ta)
            return None if odo is None else odo[0].inverse()
        if k == 0:
            return None
        gap = self.kf_t[k] - self.kf_t[k - 1]
        return gtsam.Pose2.Expmap(gtsam.Pose2.Logmap(self.last_rel) * ((t - ta) / gap)) if gap > 0 else None

    def motion_prior(self, dt: float, t: float | None = None) -> tuple[gtsam.Pose2, NDArray[np.float64], str]:
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
        cfg = self.cfg
        dt = max(dt, 0.0)
        floor = self._motion_floor()
        twist, extra, age = None, 0.0, 0.0
        if cfg.motion_model == "constant-velocity":
            if self.twist is not None and (t is None or self.twist_t is None or t - self.twist_t <= cfg.cv_max_age):
                twist = self.twist
                age = 0.0 if t is None or self.twist_t is None else max(t - dt - self.twist_t, 0.0)
            elif t is not None:
                g = self.gnss_velocity(t)
                if g is not None:
                    twist, extra, age = g
        if twist is not None:
            mean = gtsam.Pose2.Expmap(twist * dt)
            sv = math.sqrt(cfg.cv_sigma_v**2 + extra**2 + (cfg.cv_accel * age) ** 2)
            rate = np.array([sv, sv, math.radians(cfg.cv_sigma_w_deg)])
            name = "constant-velocity"
        else:
            mean = gtsam.Pose2()
            rate = np.array([cfg.rw_sigma_v, cfg.rw_sigma_v, math.radians(cfg.rw_sigma_w_deg)])
            name = "random-walk"
        return mean, np.diag(np.square(floor) + np.square(rate * dt)), name

    def gnss_velocity(self, t: float) -> tuple[NDArray[np.float64], float, float] | None:
        """Forward motion at the GNSS speed over ground: the least-squares velocity of the fixes of
        the last ``cv_gnss_window`` seconds before ``t`` (at least 3, spanning a third of it) as a
        body-frame twist ``(speed, 0, 0)``, and the speed's 1-sigma ``sigma / sqrt(sum (t_i -
        mean t)^2)`` and its age [s] (``sigma`` the fixes' stated one or, with at least 5 fixes and when
        lower, their scatter about the fitted line); zero speed when it is below 3 sigma (direction unknown). A fit
        whose speed sigma exceeds ``cv_sigma_v`` (few fixes) is not used: through an outage the last
        good velocity is kept for ``cv_max_age`` seconds."""
        cfg = self.cfg
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

    # -- one keyframe ----------------------------------------------------------------------------
    def step(self, k: int, prev: gtsam.Pose2 | None, prev_cov: NDArray[np.float64] | None = None,
             state: NavPrev | None = None) -> Step:
        """Factors and new values of keyframe ``k`` (the next one, in order). ``prev`` is the current
        estimate of pose ``k-1``, ``prev_cov`` its world covariance (the online GNSS gate; ``None``
        turns the gate off); ``state`` (the Pose3 graph) its full state: pose, velocity, IMU bias and
        the velocity's covariance."""
        if k != self.stepped:
            raise ValueError(f"keyframe {k} stepped out of order (next is {self.stepped})")
        t = self.kf_t[k]
        nav = self.imu is not None
        s = Step(k, t, gtsam.NonlinearFactorGraph(), gtsam.Values(), {F.X(k): t}, space=self.space)
        xk = F.X(k)
        floor = self._motion_floor()
        step_cov: NDArray[np.float64] | None = None
        value_k: Any = None
        if k == 0:
            assert self.anchor_pose is not None and self.anchor_sigmas is not None
            pose_k = gtsam.Pose2(*self.anchor_pose)
            s.add(self.space.prior(xk, self.anchor_pose, self.anchor_sigmas), "anchor")
            if nav:
                self._nav_start(s)
        else:
            assert prev is not None
            t_prev = self.kf_t[k - 1]
            dt = t - t_prev
            odo = self.odometry.between(t_prev, t)
            rel: gtsam.Pose2 | None = None
            odo_cov = None
            if odo is not None:
                odo_cov = proper_cov(odo[1], floor)
                if odo_cov is not None:
                    s.add(self.space.between(F.X(k - 1), xk, _vec(odo[0]), odo_cov), "odometry")
                    rel = odo[0]
            guess = None  # the IMU's prediction: (state at k, relative pose, its covariance)
            if nav:
                guess = self._nav_motion(s, k, t_prev, t, state)
            icp_rel = self._icp(s, k, rel, odo_cov, guess)
            if rel is None and icp_rel is None and guess is None:  # nothing measured: the motion model ties it
                mean, cov, _ = self.motion_prior(dt, t)
                s.add(self.space.between(F.X(k - 1), xk, _vec(mean), cov), "motion")
                self.counts["motion_fallback"] += 1
                rel = mean
                step_cov = cov
            else:
                covs = [c for c in (odo_cov, self._icp_cov if icp_rel is not None else None,
                                    guess[2] if guess is not None and rel is None else None) if c is not None]
                rel = icp_rel if icp_rel is not None else rel
                if rel is None:
                    assert guess is not None
                    rel = gtsam.Pose2(*guess[1])
                if dt > 1e-6:
                    self.twist = np.asarray(gtsam.Pose2.Logmap(rel)) / dt
                    self.twist_t = t
                step_cov = np.linalg.inv(sum(np.linalg.inv(c) for c in covs))  # the motion's fused covariance
            self.last_rel, self.last_gap = rel, dt
            pose_k = prev.compose(rel)
            if guess is not None:
                value_k = self._lift(guess[0].pose(), pose_k)
        s.values.insert(xk, value_k if value_k is not None else self.space.value(pose_k))
        if self.loops is not None:
            self._loop_step(s, k, pose_k, prev, prev_cov, rel if k > 0 else None, step_cov if k > 0 else None)
        if self.bias_key is not None:
            s.stamps[self.bias_key] = t
        gate_cov = prev_cov
        if nav and k > 0 and prev_cov is not None and step_cov is not None:
            # the Pose3 graph: the gate's prediction is the pose at k, with the motion's covariance added
            # (rotated to the world); k-1's alone let a drifting online estimate reject correct fixes
            # (Solent s2, 20 m fixes: 15.9 m ATE with the gate on k-1's covariance, 3.2 m without a gate)
            gate_cov = prev_cov + cov_to_world(prev.theta(), step_cov)
        self.meas.add(s, k, self.due.pop(k, []), pose_k, gate_cov, prev if k > 0 else None, self._offset_motion)
        if self.meas.current is not None:
            self.meas.current_step(s, k)
        for i in self.beacon_ids.values():
            s.stamps[F.L(i)] = t
        self.stepped = k + 1
        self.kf_scan.pop(k - 1, None)
        self.odometry.prune(self.kf_t[k])
        if nav:
            assert self.imu is not None
            self.imu.prune(self.kf_t[k])
        return s

    # -- the Pose3 + velocity + bias graph (graphnav.graph.space.NavSpace) ------------------------
    def _nav_start(self, s: Step) -> None:
        """Velocity and IMU-bias variables of keyframe 0 with their priors: the velocity at rest
        within ``v0_sigma`` (GNSS velocity and fixes make it), the bias the IMU model's residual."""
        assert self.imu is not None
        v0, sv = np.zeros(3), self.cfg.v0_sigma
        stated = self.imu_model.get("initial_velocity") if self.imu_model else None
        if stated is not None and len(stated) >= 2:  # the log states it (a simulator's meta): within 0.2 m/s
            v0, sv = np.array([float(stated[0]), float(stated[1]), 0.0]), V0_STATED_SIGMA
        s.add(gtsam.PriorFactorVector(V(0), v0, gtsam.noiseModel.Diagonal.Sigmas(np.array([sv, sv, 0.1]))), "anchor")
        s.add(self.imu.bias_prior(0), "imu_bias")
        s.values.insert(V(0), v0)
        s.values.insert(IB(0), gtsam.imuBias.ConstantBias())
        s.stamps[V(0)] = s.stamps[IB(0)] = s.t

    def _nav_motion(self, s: Step, k: int, ta: float, tb: float, state: NavPrev | None
                    ) -> tuple[gtsam.NavState, NDArray[np.float64], NDArray[np.float64]]:
        """The IMU between keyframes ``k-1`` and ``k``: ``ImuFactor`` (preintegration at the bias
        estimate of ``k-1``) and the bias random walk; returns the predicted state at ``k``, the
        planar relative motion and its covariance (the scan matcher's guess)."""
        assert self.imu is not None and state is not None
        pose, vel, bias, vel_cov = state
        s.add(self.imu.bias_between(k - 1, k, tb - ta), "imu_bias")
        if tb - ta < MIN_IMU_DT:  # keyframes at one time (a duplicated scan): the same state, within the floor
            floor = np.square(self._motion_floor())
            s.add(self.space.between(F.X(k - 1), F.X(k), np.zeros(3), np.diag(floor)), "motion")
            s.add(gtsam.BetweenFactorVector(V(k - 1), V(k), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)),
                  "motion")
            s.values.insert(V(k), vel)
            s.values.insert(IB(k), bias)
            s.stamps[V(k)] = s.stamps[IB(k)] = tb
            return gtsam.NavState(pose, vel), np.zeros(3), np.diag(floor)
        pim = self.imu.preintegrate(bias, ta, tb, speed=float(np.hypot(vel[0], vel[1])))
        s.add(F.imu_factor(k - 1, k, pim), "imu")
        pred, rel, cov = relative_prediction(pim, pose, vel, bias, vel_cov)
        cov = cov + np.diag(np.square(self._motion_floor()))
        s.values.insert(V(k), pred.velocity())
        s.values.insert(IB(k), bias)
        s.stamps[V(k)] = s.stamps[IB(k)] = tb
        return pred, rel, cov

    def _motion_floor(self) -> NDArray[np.float64]:
        """[m, m, rad] added in quadrature to every motion factor (``dt = 0`` stays proper)."""
        c = self.cfg
        return np.array([c.motion_floor_xy, c.motion_floor_xy, math.radians(c.motion_floor_yaw_deg)])

    def _lift(self, p3: gtsam.Pose3, p2: gtsam.Pose2) -> gtsam.Pose3:
        """The IMU's predicted attitude (roll, pitch) and height with the planar pose ``p2``."""
        r = p3.rotation()
        return gtsam.Pose3(gtsam.Rot3.Ypr(p2.theta(), r.pitch(), r.roll()),
                           np.array([p2.x(), p2.y(), p3.translation()[2]]))

    def _loop_step(self, s: Step, k: int, pose_k: gtsam.Pose2, prev: gtsam.Pose2 | None,
                   prev_cov: NDArray[np.float64] | None, rel: gtsam.Pose2 | None,
                   step_cov: NDArray[np.float64] | None) -> None:
        """Keyframe ``k`` to the loop closer: its predicted pose and world covariance (propagated from
        the solver's marginal of ``k-1`` when online, else from the closer's own chain), its scan."""
        from .loops import propagate

        if k == 0 or prev is None or rel is None or step_cov is None:
            assert self.anchor_sigmas is not None
            cov_w = np.diag(np.square(self.anchor_sigmas))
        else:
            base = prev_cov if prev_cov is not None else self._loop_cov
            cov_w = propagate(base if base is not None else np.zeros((3, 3)), _vec(prev), rel, step_cov)
        self._loop_cov = cov_w
        scan = self.kf_scan.get(k)
        xy = self.loops.points(scan) if isinstance(scan, Scan) else None  # 2D scans only (not 3D clouds)
        oldest = 0
        if self.cfg.solver == "fixed-lag":  # only keyframes still in the window (minus a margin of 10 %)
            oldest = bisect.bisect_left(self.kf_t, self.kf_t[k] - 0.9 * self.cfg.lag)
        self.loops.step(s, k, pose_k, cov_w, rel, step_cov, xy, oldest)

    def step_late(self, est: Callable[[int], gtsam.Pose2], prev_cov: NDArray[np.float64] | None = None) -> Step | None:
        """After :meth:`finish`: the measurements that came after the last keyframe's batch, as a
        batch of their own (``None`` when there are none)."""
        if not self.late:
            return None
        k = len(self.kf_t) - 1
        s = Step(k, self.kf_t[k], gtsam.NonlinearFactorGraph(), gtsam.Values(), {}, new_keyframe=False)
        late, self.late = self.late, []
        self.meas.add(s, k, late, est(k), prev_cov, None, self._offset_motion, est=est)
        for i in self.beacon_ids.values():
            s.stamps[F.L(i)] = self.kf_t[k]
        return s

    def _icp(self, s: Step, k: int, odo_rel: gtsam.Pose2 | None, odo_cov: NDArray[np.float64] | None,
             guess: tuple[Any, NDArray[np.float64], NDArray[np.float64]] | None = None) -> gtsam.Pose2 | None:
        """The weighted-ICP factor of keyframe ``k``'s scan against ``k-1``'s (``None`` when there is
        no usable match); a cloud's GICP factor for clouds (:class:`_CloudPath`). Without odometry
        the IMU's prediction (``guess``: state, relative pose, covariance) is the matcher's guess and
        its gate, and is in the graph already (the ``ImuFactor``): along the directions the match
        cannot see, its factor says nothing and the IMU and GNSS decide."""
        if odo_rel is None and guess is not None:
            odo_rel, odo_cov = gtsam.Pose2(*guess[1]), guess[2]
        cur = self.kf_scan.get(k)
        if isinstance(cur, Cloud):
            got = self.cloud3d.factor(s, k, cur, self.kf_scan.get(k - 1), odo_rel, odo_cov, self.last_rel)
            if got is None:
                return None
            self._icp_cov = got[1]  # the newest accepted match's covariance (the step's fused motion covariance)
            return got[0]
        cfg = self.cfg
        if self.matcher is None or k not in self.kf_scan or (k - 1) not in self.kf_scan:
            return None
        if odo_rel is not None and odo_cov is not None:  # the guess and its covariance: the odometry or IMU ...
            init, init_cov, in_graph = _vec(odo_rel), odo_cov, True
        else:  # ... else the motion model's (constant velocity from the last measured motion, random walk)
            mean, init_cov, _ = self.motion_prior(self.kf_t[k] - self.kf_t[k - 1], self.kf_t[k])
            init, in_graph = _vec(mean), False
        c0 = time.perf_counter()
        ok, mp, mc = self.matcher(self.kf_scan[k], self.kf_scan[k - 1], init, init_cov, in_graph)
        s.icp_ms = (time.perf_counter() - c0) * 1e3
        self.n_icp += 1
        cov = proper_cov(np.asarray(mc, dtype=float), np.zeros(3)) if ok else None  # the match's own, as is
        verdict = screen_match(cfg, ok, mp, cov, init, odo_rel, odo_cov)
        if verdict is not None:
            self.n_icp_failed += verdict == "failed"
            self.n_icp_gated += verdict == "gated"
            return None
        rel = gtsam.Pose2(*mp)
        s.add(self.space.between(F.X(k - 1), F.X(k), mp, cov, robust=cfg.icp_robust), "icp")
        self._icp_cov = cov
        return rel

    def info(self) -> dict[str, Any]:
        return {
            "anchor": self.anchor,
            "keyframes": len(self.kf_t),
            "keyframe_policy": "scan" if self.mode == "scan" else f"grid {self.period:g} s",
            "gnss_rejected": self.meas.n_rejected,
            "icp_pairs": self.n_icp,
            "icp_failed": self.n_icp_failed,
            "icp_gated": self.n_icp_gated,
            "icp": self.matcher is not None,
            "beacons": sorted(self.beacon_ids),
            **self.cloud3d.info(),
            "compass_bias_estimated": self.bias_key is not None,
            "state": self.space.name,
            **({"imu_noise": self.imu.source if self.imu else "none (vessel model)"} if self.imu is not None else {}),
            "defaulted_sigmas": sorted(self.defaulted),
            **(self.loops.info() if self.loops is not None else {}),
            **self.counts,
        }


def _vec(p: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([p.x(), p.y(), p.theta()])
