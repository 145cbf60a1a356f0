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

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..geometry import cov_to_world
from ..log import Gnss, KnownBeacon, PosePrior, Record
from .anchor import Anchor
from .fix_gate import gate_info
from .keyframes import Keyframes
from .measurements import Measurements
from .motion import Guess, Motion, NavPrev
from .mounts import parse_mounts
from .scan_factors import (  # noqa: F401  (Matcher, default_matcher, make_loop_closer: the graph's public names)
    Matcher,
    ScanFactors,
    default_matcher,
    make_loop_closer,
)
from .smoother_config import SmootherConfig
from .space import IB, NavSpace, PlanarSpace, V
from .step import Step

__all__ = ["GROUPS", "SCALABLE", "GraphBuilder", "Matcher", "NavPrev", "Step", "default_matcher", "make_loop_closer"]

#: sensor groups of the factors (the noise estimation scales ``SCALABLE`` ones)
GROUPS = ("anchor", "odometry", "motion", "icp", "loop", "gnss", "compass", "bias", "beacon", "chart", "pose_prior",
          "cloud", "imu", "imu_bias", "gnss_velocity", "water_speed", "current", "log_scale", "attitude",
          "level")
SCALABLE = ("odometry", "motion", "icp", "gnss", "compass", "beacon", "cloud")
MEASUREMENTS = ("gnss", "heading", "beacon", "pose_prior", "gnss_velocity", "water_speed", "attitude")
ODOMETRY_FRESH_S = 2.0  # [s] the newest odometry sample gives the speed and yaw rate when at most this old


class GraphBuilder:
    """Records in, per-keyframe factor batches out (see the module docstring): the coordinator of the
    anchor (:class:`~graphnav.graph.anchor.Anchor`), the keyframes and attachment
    (:class:`~graphnav.graph.keyframes.Keyframes`), the motion between keyframes
    (:class:`~graphnav.graph.motion.Motion`), the scan factors and loops
    (:class:`~graphnav.graph.scan_factors.ScanFactors`) and the measurement factors
    (:class:`~graphnav.graph.measurements.Measurements`).

    ``chart``: charted beacons; ``lidar``: the log's LiDAR error model (``sigma_r_rel``,
    ``sigma_alpha``); ``scans``: whether the log has scans (``None``: decided by the first scan --
    a grid until then); ``matcher``: replaces the weighted ICP (tests); ``imu``: whether the log has
    an IMU; ``imu_model``: its noise and initial velocity (``meta``); ``odometry``: whether the log has
    odometry (the robot at rest before its first sample; ``None``: decided by the first sample).
    """

    def __init__(self, cfg: SmootherConfig, *, matcher: Matcher | None = None,
                 chart: Iterable[KnownBeacon] = (), lidar: dict[str, Any] | None = None,
                 scans: bool | None = None, lidar3d: dict[str, Any] | None = None,
                 imu: bool | None = None, imu_model: dict[str, Any] | None = None,
                 odometry: bool | None = None) -> None:
        self.cfg = cfg
        # the state space: Pose3 + velocity + IMU bias when the log has an IMU (motion "auto") or
        # when asked ("imu"; "vessel": the same without an IMU, a white-noise acceleration model)
        nav = cfg.motion in ("imu", "vessel") or (cfg.motion == "auto" and bool(imu))
        self.space: PlanarSpace = NavSpace() if nav else PlanarSpace()
        mounts = parse_mounts(cfg.mounts)
        self.motion = Motion(cfg, self.space, nav, imu_model, mounts["imu"].pose3() if "imu" in mounts else None,
                             odometry=bool(odometry))
        self.scans = ScanFactors(cfg.scan, self.space, matcher=matcher, lidar=lidar, lidar3d=lidar3d,
                                 mount=mounts.get("lidar"))
        self.charted = {b.id: b for b in chart}
        self.keyframes = Keyframes(cfg.keyframe, scans)
        self.keyframes.imu = self.motion.imu
        if self.keyframes.mode == "scan":
            self.scans.want_matcher()
        self.anchor = Anchor(cfg.anchor, cfg.mounts)
        self.counts = {"records": 0, "late": 0, "ignored": 0, "motion_fallback": 0}
        self.defaulted: set[str] = set()  # groups whose sigmas came from the configuration
        # the measurement factors and their state (beacons, compass-bias frame, GNSS gate, water current)
        self.meas = Measurements(cfg, self.space, nav, self.charted, self.keyframes.t, self.defaulted, self.counts,
                                 mounts)

    # -- what the navigator reads ----------------------------------------------------------------
    @property
    def nav(self) -> bool:
        """The Pose3 graph (velocity and IMU-bias states)."""
        return self.motion.imu is not None

    @property
    def kf_t(self) -> list[float]:
        """The keyframes' times so far."""
        return self.keyframes.t

    @property
    def stepped(self) -> int:
        """Keyframes ``[0, stepped)`` have their batch."""
        return self.keyframes.stepped

    @property
    def finished(self) -> bool:
        return self.keyframes.finished

    @property
    def loops(self) -> Any:
        """The loop closer (:class:`~graphnav.graph.loops.LoopCloser`), ``None`` without scans or loops."""
        return self.scans.loops

    @property
    def wants_velocity_cov(self) -> bool:
        """Whether the next step wants the velocity's marginal (the scan matcher's IMU guess)."""
        return self.scans.matcher is not None

    @property
    def rejected_fixes(self) -> list[gtsam.NonlinearFactor]:
        """The factors of the fixes the online GNSS gate rejected (the closing batch step reconsiders them)."""
        return self.meas.rejected

    def assume_sigmas(self, group: str) -> None:
        """The log's sigmas of ``group`` are assumed, known only up to scale: the noise estimation
        rescales the group like a defaulted one."""
        self.defaulted.add(group)

    def carried_keys(self, k: int) -> list[int]:
        """The variables besides the pose ``X(k)`` a re-anchored fixed-lag smoother keeps at keyframe ``k``."""
        return self.meas.carried_keys(k) + ([V(k), IB(k)] if self.nav else [])

    def water_keys(self, k: int) -> list[int]:
        """The newest water current (when keyframe ``k``'s) and speed-log scale variables."""
        return self.meas.water.keys(k)

    def observe_water(self, key: int, value: NDArray[np.float64]) -> None:
        """The solver's newest estimate of a :meth:`water_keys` variable (the next ones' initial value)."""
        self.meas.water.observe(key, value)

    def recent_odometry(self, t: float) -> tuple[float, float] | None:
        """The newest odometry sample's speed and yaw rate when recent at ``t``."""
        return self.motion.recent_odometry(t, ODOMETRY_FRESH_S)

    def report(self, values: gtsam.Values) -> dict[str, Any]:
        """The non-pose states of a solution: compass bias, beacons, final IMU bias, water current."""
        out = self.meas.report(values)
        n = len(self.keyframes)
        if self.nav and values.exists(IB(n - 1)):
            bias = values.atConstantBias(IB(n - 1))
            out["imu_bias_final"] = [*np.asarray(bias.accelerometer()).tolist(), *np.asarray(bias.gyroscope()).tolist()]
        return {**out, **self.meas.water.report(values, np.array(self.keyframes.t))}

    # -- records in ------------------------------------------------------------------------------
    def push(self, rec: Record | KnownBeacon) -> None:
        """Take one record (time-ordered; one older than the newest is counted and dropped). Until
        the anchor is chosen (once the records of a time stamp are all in) records are held."""
        if isinstance(rec, KnownBeacon):
            self.charted[rec.id] = rec
            return
        self.counts["records"] += 1
        if not self.anchor.chosen:
            if self.anchor.ready_for(rec, self.charted):
                self._start()
            else:
                self.anchor.hold(rec)
                if isinstance(rec, PosePrior):
                    self._start()
                return
        self._ingest(rec)

    def push_quiet(self, recs: Sequence[Record]) -> bool:
        """IMU and truth records that can make no keyframe ready, taken as :meth:`push` of each would
        (:meth:`Keyframes.quiet <graphnav.graph.keyframes.Keyframes.quiet>`); ``False`` (nothing done) before
        the anchor, on the planar graph, before the first of either kind, or when they might."""
        imu, counts = self.motion.imu, self.counts
        samples = [r for r in recs if r.kind == "imu"]
        n_truth, ts = len(recs) - len(samples), [r.t for r in recs]
        if (imu is None or not self.anchor.chosen or (samples and "imu" not in counts) or (n_truth and "truth" not in
                counts) or not self.keyframes.quiet(min(ts), max(ts), max(r.t for r in samples) if samples else None)):
            return False
        counts["records"] += len(recs)
        for kind, m in (("imu", len(samples)), ("truth", n_truth), ("ignored", n_truth)):  # (truth: a reference)
            if m:
                counts[kind] += m
        imu.extend(samples)
        return True

    def finish(self) -> None:
        """End of the records: every keyframe becomes ready; measurements after the last keyframe
        join it (in a batch of their own when its batch is already out)."""
        if self.keyframes.finished:
            return
        if not self.anchor.chosen:
            self._start()
        self.keyframes.finish()

    def ready(self) -> list[int]:
        """Keyframes whose batch can be built now (in order)."""
        kf = self.keyframes
        if kf.stepped >= len(kf.t):  # (asked after every record: mostly none waits)
            return []
        return kf.ready(self.motion.imu_until(kf.t_last))

    def _start(self) -> None:
        t0, replay = self.anchor.choose(self.charted)
        if t0 is not None:  # the grid starts at the first record, whatever it is
            self.keyframes.start(t0)
        for r in replay:
            self._ingest(r)

    def _ingest(self, rec: Record) -> None:
        """One record. Records may come a little out of order (two sockets): a record is late, and
        dropped, only when its keyframe's batch is already out (a scan: when it is older than the
        newest keyframe)."""
        kf, kind = self.keyframes, rec.kind
        if kf.behind(rec):
            self.counts["late"] += 1
            return
        kf.clock(rec)
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind == "scan" or (kind == "cloud" and self.cfg.scan.use_cloud):
            self._lidar(rec)
        elif kind == "odometry":
            if self.motion.uses_odometry:
                if self.motion.add_odometry(rec):
                    self.defaulted.add("odometry")
            elif not self.motion.add_rot(rec):  # (a rate of turn: the vessel model's yaw rate; its SOG unused)
                self.counts["odometry_unused"] = self.counts.get("odometry_unused", 0) + 1
        elif kind in MEASUREMENTS:
            if isinstance(rec, Gnss) and self.motion.add_fix(rec):
                self.meas.after_outage.add(id(rec))  # the first fix after an outage is not gated
            if not kf.attach(rec):
                self.counts["late"] += 1
        elif kind == "imu" and self.nav:
            self.motion.add_imu(rec)
        else:  # truth (a reference, not a measurement); imu on the planar graph; water speed, attitude
            self.counts["ignored"] += 1

    def _lidar(self, rec: Record) -> None:
        """A scan or cloud: the first makes the keyframes follow the scans; a keyframe when due."""
        kf = self.keyframes
        if not kf.is_lidar(rec.kind):  # a log with 2D scans and 3D clouds: the first kind is the LiDAR
            self.counts["ignored"] += 1  # (-O use_cloud=false picks the 2D scans)
            self.counts["lidar_other"] = self.counts.get("lidar_other", 0) + 1
            return
        if kf.to_scans():
            self.scans.want_matcher()
        if kf.mode == "scan":
            if kf.scan_is_keyframe(rec.t, self.motion.speed, self.motion.imu):
                kf.add(rec.t, rec)
            kf.n_scans += 1

    # -- one keyframe ----------------------------------------------------------------------------
    def step(self, k: int, prev: gtsam.Pose2 | None, prev_cov: NDArray[np.float64] | None = None,
             state: NavPrev | None = None) -> Step:
        """Factors and new values of keyframe ``k`` (the next one, in order). ``prev`` is the current
        estimate of pose ``k-1``, ``prev_cov`` its world covariance (the online GNSS gate; ``None``
        turns the gate off); ``state`` (the Pose3 graph) its full state: pose, velocity, IMU bias and
        the velocity's covariance. The pipeline: the anchor (keyframe 0) or the motion (odometry,
        IMU, scan match, else the motion model), the loop closer, the measurements due."""
        kf = self.keyframes
        due = kf.take(k)
        t = kf.t[k]
        s = Step(k, t, gtsam.NonlinearFactorGraph(), gtsam.Values(), {F.X(k): t}, space=self.space)
        rel = step_cov = None
        if k == 0:
            pose_k, value_k = self._anchor_step(s)
        else:
            assert prev is not None
            pose_k, value_k, rel, step_cov = self._motion_step(s, k, prev, state)
        s.values.insert(F.X(k), value_k if value_k is not None else self.space.value(pose_k))
        if self.scans.loops is not None:
            oldest = 0
            if self.cfg.solver == "fixed-lag":  # only keyframes still in the window (minus a margin of 10 %)
                oldest = kf.first_after(kf.t[k] - 0.9 * self.cfg.optimizer.lag)
            self.scans.close_loops(s, k, pose_k, prev, prev_cov, rel, step_cov, self.anchor.cov(),
                                   kf.scans.get(k), oldest)
        gate_cov = prev_cov
        if self.nav and k > 0 and prev_cov is not None and step_cov is not None:
            # the Pose3 graph: the gate's prediction is the pose at k, with the motion's covariance added
            # (rotated to the world); k-1's alone let a drifting online estimate reject correct fixes
            # (Solent s2, 20 m fixes: 15.9 m ATE with the gate on k-1's covariance, 3.2 m without a gate)
            assert prev is not None
            gate_cov = prev_cov + cov_to_world(prev.theta(), step_cov)
        if self.nav:  # the beacon factors' elevation (space.beacon): the keyframe's roll and pitch as estimated
            self.meas.tilt_of = lambda key: keyframe_tilt(s, state, key)
        self.meas.step(s, k, due, pose_k, gate_cov, prev if k > 0 else None, self._offset)
        kf.done(k)
        self.motion.prune(t)
        return s

    def _anchor_step(self, s: Step) -> tuple[gtsam.Pose2, None]:
        """Keyframe 0: the anchor's prior (and the Pose3 graph's velocity and bias priors)."""
        a = self.anchor
        assert a.pose is not None and a.sigmas is not None
        rp = self.motion.imu.tilt(s.t) if self.nav and self.motion.imu is not None else None
        a.tilt = tilt = None if rp is None else (*rp, math.radians(self.cfg.anchor.sigma_tilt_deg))
        s.add(self.space.prior(F.X(0), a.pose, a.sigmas, tilt), "anchor")
        if self.nav:
            self.motion.start(s)
        return gtsam.Pose2(*a.pose), None if rp is None else self.space.tilted(a.pose, *rp)

    def _motion_step(self, s: Step, k: int, prev: gtsam.Pose2, state: NavPrev | None
                     ) -> tuple[gtsam.Pose2, gtsam.Pose3 | None, gtsam.Pose2, NDArray[np.float64]]:
        """Keyframe ``k``'s motion factors: the odometry, the IMU, the scan match, else the motion model;
        returns the predicted pose (planar, and the Pose3 graph's value), the interval's relative
        motion and its fused covariance."""
        kf, motion = self.keyframes, self.motion
        t_prev, t = kf.t[k - 1], kf.t[k]
        dt = t - t_prev
        odo_rel, odo_cov, guess = motion.measured(s, k, t_prev, t, state)
        match = self.scans.match(s, k, kf.scans.get(k), kf.scans.get(k - 1), odo_rel, odo_cov, guess,
                                 motion.last_rel, lambda: motion.prior(dt, t))
        rel, step_cov, fallback = motion.close(s, k, dt, t, (odo_rel, odo_cov), match, guess)
        self.counts["motion_fallback"] += fallback
        pose_k = prev.compose(rel)
        return pose_k, self._lifted(guess, pose_k), rel, step_cov

    @staticmethod
    def _lifted(guess: Guess | None, pose_k: gtsam.Pose2) -> gtsam.Pose3 | None:
        return None if guess is None else Motion.lift(guess[0].pose(), pose_k)

    def _offset(self, a: int, t: float, k: int) -> gtsam.Pose2 | None:
        """Motion from keyframe ``a`` to time ``t`` (the attachment's compensation)."""
        kt = self.keyframes.t
        return self.motion.offset(kt[a], t, kt[k] - kt[k - 1] if k > 0 else None)

    def step_late(self, est: Callable[[int], gtsam.Pose2], prev_cov: NDArray[np.float64] | None = None) -> Step | None:
        """After :meth:`finish`: the measurements that came after the last keyframe's batch, as a
        batch of their own (``None`` when there are none)."""
        if not self.keyframes.late:
            return None
        k = len(self.keyframes) - 1
        s = Step(k, self.keyframes.t[k], gtsam.NonlinearFactorGraph(), gtsam.Values(), {}, new_keyframe=False)
        self.meas.step_late(s, k, self.keyframes.take_late(), self._offset, est, prev_cov)
        return s

    def info(self) -> dict[str, Any]:
        """Counts and settings of the graph so far (:func:`builder_info`)."""
        return builder_info(self)


def keyframe_tilt(s: Step, state: NavPrev | None, key: int) -> tuple[float, float] | None:
    """Roll and pitch of keyframe ``key`` as now estimated: this step's value, or the previous state's."""
    if s.values.exists(key):
        r = s.values.atPose3(key).rotation()
    elif state is not None:
        r = state[0].rotation()
    else:
        return None
    return float(r.roll()), float(r.pitch())


def builder_info(b: GraphBuilder) -> dict[str, Any]:
    """A builder's counts and settings so far: anchor, keyframes, gate, scans, beacons, state, IMU, loops."""
    kf, imu = b.keyframes, b.motion.imu
    return {
        "anchor": b.anchor.name,
        "keyframes": len(kf),
        "keyframe_policy": "scan" if kf.mode == "scan" else f"grid {kf.period:g} s",
        **gate_info(b.meas.gate),
        "gnss_online_scale": {"final": b.meas.gnss_scale.scale, "max": b.meas.gnss_scale.max_scale},
        **b.scans.info(),
        "beacons": sorted(b.meas.beacon_ids),
        **b.scans.cloud3d.info(),
        "compass_bias_estimated": b.meas.bias_key is not None,
        "state": b.space.name,
        **({"imu_noise": imu.source if imu else "none (vessel model)"} if imu is not None else {}),
        **({"vessel_position_walk": {"walk": imu.vessel_walk, "estimate": imu.walk_estimate}}
           if imu is not None and not imu else {}),
        **({"vessel_rot": {"source": imu.rot.source, "rate_hz": 1.0 / imu.rot.period(),
                           "other_sources_ignored": imu.rot.ignored, "implausible": imu.rot.implausible}}
           if imu is not None and not imu and imu.rot is not None else {}),
        "defaulted_sigmas": sorted(b.defaulted),
        **(b.scans.loops.info() if b.scans.loops is not None else {}),
        **b.counts,
    }
