"""The one configuration of the navigation graph (:class:`SmootherConfig`), in sections, one per
collaborator of :class:`~graphnav.graph.builder.GraphBuilder` (docs/architecture.md "The graph's
options"): keyframes, anchor, odometry, motion model, scans, GNSS, compass, beacons, water, solver,
robust back end. ``-O key=value`` on ``graphnav run`` / ``graphnav live``, TOML ``[options]`` and
``Navigator(config)`` / ``**options`` in Python set them by path (``gnss.gate``, TOML
``[options.gnss] gate = 4``) or by their flat name (``gnss_gate``: the section's prefix + the field's
name, :func:`graphnav.config.option_names`); an unknown key is an error naming the known ones.
docs/smoother.md explains each group."""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

from ..config import Sectioned, config_from_options, option, section
from ..log import odometry_is_rot

MOTION_MODELS = ("constant-velocity", "random-walk")
MOTIONS = ("auto", "odometry", "imu", "vessel")
#: record kinds of a vessel's own instruments that the Pose3 graph uses and the Pose2 graph drops
VESSEL_KINDS = ("gnss_velocity", "water_speed")


def auto_motion(kinds: Collection[str], meta: dict[str, Any] | None = None) -> str:
    """The state space ``motion="auto"`` picks from the record kinds of a log: ``"imu"`` with IMU records;
    ``"vessel"`` (Pose3 + velocity, white-noise acceleration: course and heading differ, the current
    is a state) for a vessel's instruments -- a compass and GNSS velocity or water speed -- without an
    IMU, an odometer or a LiDAR; else ``"odometry"`` (Pose2: odometry, ICP, constant velocity). Without
    a compass nothing tells heading from course, and a lone receiver's track stays the Pose2 graph's
    (the NMEA corpus: 48 of 48 within 1.5 m of their fixes, 41 with the vessel graph; with this rule
    47: hemi.log, a still satellite compass whose fixes jump 3 m against its own 0.00 kn, is held still
    at their HDOP-weighted mean, 1.97 m from them, docs/smoother.md). Measured on
    real boats' logs with their fixes degraded to 2.5 m at 1 Hz, a 60 s outage and a 20 m jump
    (docs/smoother.md, "A real boat's instruments"): the vessel graph 0.22-0.46x the degraded fixes
    interpolated, the Pose2 graph 0.36-0.86x, online 1.9-2.5 m against 3.9-7.8 m.

    Odometry that is a rate of turn paired with the speed over ground (``meta["odometry"] ==``
    :data:`~graphnav.log.ODOMETRY_FROM_ROT`: NMEA ROT, NMEA 2000 127251) is no odometer: the Pose2
    graph would move the boat along its bow at its speed over ground, which a heading that is not the
    course contradicts (the Furuno SCX-20 logs: each receiver alone 0.50-0.84 m from its fixes in the
    Pose2 graph, 0.44-0.54 m in the vessel graph; docs/smoother.md)."""
    k = set(kinds)
    if "imu" in k:
        return "imu"
    if "odometry" in k and odometry_is_rot(meta):
        k.discard("odometry")
    if not k & {"odometry", "scan", "cloud"} and "heading" in k and k & set(VESSEL_KINDS):
        return "vessel"
    return "odometry"
CONVERGE = ("lm", "updates", "none")
LM_DAMPING = ("nielsen", "fixed")
NOISE_ESTIMATION = ("off", "defaulted", "all")
BATCH_INIT = ("incremental", "chained")
ROBUST_BACKEND = ("gnc", "off")
GNC_SCHEDULE = ("superlinear", "linear")
ROBUST_GROUPS = ("icp", "loop", "cloud", "gnss")  # the sensor groups the back end may switch off


def _positive(name: str, val: float | None, *, none: bool = False) -> None:
    """``val`` must be finite and > 0 (``none``: or None); else a ValueError naming ``name``."""
    if none and val is None:
        return
    if val is None or not (math.isfinite(val) and val > 0):
        raise ValueError(f"{name} must be > 0{' or None' if none else ''}, got {val}")


def _choice(name: str, val: Any, allowed: tuple[str, ...]) -> None:
    if val not in allowed:
        raise ValueError(f"{name} must be one of {', '.join(allowed)}; got {val!r}")


@dataclass
class KeyframeConfig:
    """Keyframes and attachment (:class:`~graphnav.graph.keyframes.Keyframes`; ``compensate_attachment``:
    Measurements)."""

    prefix = "keyframe_"

    period: float | None = option(None, "None: one pose per scan (a 0.5 s grid without scans)")
    scan_stride: int = option(1, "with scans: a keyframe (and an ICP match) every N-th scan", flat="scan_stride")
    motion: bool | None = option(
        None, "with scans and an IMU: a scan becomes a keyframe only once the motion since the newest keyframe "
        "reaches keyframe_distance or keyframe_angle_deg, or keyframe_max_dt has passed (LIO-SAM's keyframe rule, "
        "Shan et al. 2020: 1 m, 0.2 rad; the IMU carries the motion between keyframes). None: on for the IMU "
        "graph, off (every scan) elsewhere. New harbour, 200 s: ATE 0.172 every scan, 0.172 at every 10th, 3x "
        "less CPU")
    distance: float = option(1.0, "keyframe_motion: the distance that makes a keyframe", unit="m")
    angle_deg: float = option(11.46, "keyframe_motion: the turn that makes a keyframe (0.2 rad)", unit="deg")
    max_dt: float = option(1.0, "keyframe_motion: at least one keyframe this often (the online output rate)",
                           unit="s")
    grid_gap: float = option(5.0, "grid slots inside a gap without any record longer than this are skipped",
                             unit="s", flat="grid_gap")
    compensate_attachment: bool = option(
        True, "move each measurement to its keyframe's time by the motion between", flat="compensate_attachment")

    def __post_init__(self) -> None:
        if self.scan_stride < 1:
            raise ValueError(f"scan_stride must be >= 1, got {self.scan_stride}")
        for name in ("distance", "angle_deg", "max_dt"):
            if not getattr(self, name) > 0:
                raise ValueError(f"keyframe_{name} must be > 0, got {getattr(self, name)}")
        if self.period is not None and not self.period > 0:
            raise ValueError(f"keyframe period must be > 0, got {self.period}")


@dataclass
class AnchorConfig:
    """The first pose's prior (:class:`~graphnav.graph.anchor.Anchor`)."""

    prefix = "anchor_"

    wait: float = option(2.0, "records are held this long (log time) to choose the anchor", unit="s")
    sigma_xy: float | None = option(None, "prior on the first pose when there is no pose_prior record")
    sigma_yaw_deg: float = option(30.0, "... its yaw sigma at the first compass reading")
    sigma_tilt_deg: float = option(5.0,
        "the Pose3 graph with a 6-axis IMU: the first pose's roll and pitch from the gravity direction (the mean "
        "specific force of its first second), within this (a hull's accelerations while it was measured); planar or "
        "no IMU records: level (their frame is the levelled one)")
    sigma_yaw_unknown_deg: float = option(60.0,
        "... at yaw 0 without one: 1 rad, not pi, or iSAM2's Gauss-Newton step diverges where nothing else observes "
        "the yaw (a GNSS-only log); odometry and GNSS recover a start 180 deg off (square loop: online 0.80 m against "
        "0.68 m with pi)")


@dataclass
class OdometryConfig:
    """Odometry records as between factors (:class:`~graphnav.graph.odometry_buffer.OdometryBuffer`). When
    the log gives no sigmas: noise densities [per sqrt(s)], so the integrated error does not depend on the
    sample rate, hypot(floor, rel * abs(v)) and hypot(floor, rel * abs(w))."""

    prefix = "odo_"

    use: bool | None = option(None,
        "odometry records as between factors (false: the motion model ties the poses). None: on the Pose2 graph yes; "
        "on the Pose3 graph (an IMU) no: a record of speed along the bow and rate of turn is a unicycle, wrong for a "
        "boat in a current (Solent s1, 0.85 m/s current: isam2 3.36 m with it, 1.25 m without; the UKF 3.16 m)",
        flat="use_odometry")
    sigma_v: float = option(0.02, "odometry speed noise density floor (when the log gives no sigmas): "
                            "hypot(this, odo_sigma_v_rel * |v|)", unit="m/s sqrt(s)")
    sigma_v_rel: float = option(0.1, "x |v|")
    sigma_w_deg: float = option(1.0, "floor", unit="deg/s sqrt(s)")
    sigma_w_rel: float = option(0.1, "x |w|")
    lateral: float = option(0.1, "lateral (sway, crab, wheel slip) 1-sigma as a fraction of the distance run")


@dataclass
class MotionConfig:
    """The motion model between keyframes (:class:`~graphnav.graph.motion.Motion`): constant velocity or random walk
    without odometry, the floors of every motion factor, the Pose3 graph's first velocity and level constraint."""

    prefix = ""

    model: str = option("constant-velocity", "without odometry: \"constant-velocity\" | \"random-walk\"",
        flat="motion_model")
    cv_sigma_v: float = option(0.5,
        "constant velocity: 1-sigma velocity change -> sigma_xy = cv_sigma_v dt", unit="m/s")
    cv_sigma_w_deg: float = option(10.0, "its yaw counterpart", unit="deg/s")
    cv_accel: float = option(0.3, "the velocity's 1-sigma grows by this per second since it was measured", unit="m/s^2")
    cv_max_age: float = option(60.0, "the last measured motion (or GNSS velocity) is kept this long", unit="s")
    cv_gnss_window: float = option(10.0,
        "GNSS fixes fitted for the speed over ground (no odometry, no scans)", unit="s")
    rw_sigma_v: float = option(2.0, "random walk (no motion known): sigma_xy = rw_sigma_v dt", unit="m/s")
    rw_sigma_w_deg: float = option(30.0, "its yaw counterpart", unit="deg/s")
    floor_xy: float = option(1e-3, "added in quadrature to every motion factor (dt = 0 stays proper)", unit="m",
        flat="motion_floor_xy")
    floor_yaw_deg: float = option(0.01, "its yaw counterpart", unit="deg", flat="motion_floor_yaw_deg")
    v0_sigma: float = option(5.0,
        "the Pose3 graph: prior 1-sigma of the first velocity (at rest; GNSS decides)", unit="m/s")
    level_sigma_deg: float = option(
        1.0, "roll/pitch 1-sigma of the level constraint on every keyframe of the Pose3 graph when the IMU is planar "
        "(3-axis: levelled horizontal specific force and yaw rate) or absent: such records define a level body "
        "frame and observe no roll or pitch, which would otherwise wander freely and rotate the planar motion; "
        "0 turns it off", unit="deg")
    surface_sigma: float = option(
        0.5, "the Pose3 graph with a 6-axis IMU: 1-sigma of every keyframe's height at the sea surface (z = 0: a hull "
        "floats; the waves' heave). Without it the height drifts with the vertical accelerometer, held only by the "
        "fixes' 3-D sigma, and on a heeled hull a height error turns every beacon bearing (harbour heeled 20 deg: "
        "marks at -2.8 to +4.8 m, roll 0.4 deg off); 0 turns it off", unit="m")

    def __post_init__(self) -> None:
        _choice("motion_model", self.model, MOTION_MODELS)


@dataclass
class ScanConfig:
    """Scan factors (:class:`~graphnav.graph.scan_factors.ScanFactors`): weighted ICP between 2D scans, loop closures
    (graphnav.graph.loops, docs/loops.md), 3D clouds (GICP projected to SE(2); docs/scan-matching-3d.md "3D in the
    graph"; the cloud factor's covariance is the match's own, cloud_match.match_covariance, not scaled)."""

    prefix = ""

    use_icp: bool = option(True, "false: no weighted-ICP factors between scans")
    icp_robust: str | None = option(None, "robust kernel on ICP factors (None, \"huber\", \"cauchy\")")
    icp_max_step: float = option(5.0, "an ICP step farther than this from the prediction is rejected", unit="m")
    icp_gate: float | None = option(4.0, "reject a match whose Mahalanobis distance to the odometry exceeds it")
    icp: dict[str, Any] = option(help="options for graphnav.scan.weighted_icp.IcpConfig", factory=dict)
    deskew: bool = option(
        True, "de-skew both scans of a match with the guess's twist (IMU, odometry or motion model) when the log "
        "states the LiDAR's sweep (meta lidar sweep_s > 0; docs/weighted-icp.md \"De-skewing a sweep\")")
    loops: bool = option(True, "close loops when the log has scans")
    loop: dict[str, Any] = option(help="options for graphnav.graph.loops.LoopConfig", factory=dict)
    use_cloud: bool = option(True, "one keyframe per cloud (every scan_stride-th) and a GICP factor to the previous")
    cloud_sigma_floor_xy: float = option(0.005, "added in quadrature to the cloud factor's sigma", unit="m")
    cloud_sigma_floor_yaw_deg: float = option(0.02, "its yaw counterpart", unit="deg")
    cloud: dict[str, Any] = option(help="options for graphnav.scan.cloud_match.CloudMatchConfig", factory=dict)


@dataclass
class GnssConfig:
    """GNSS fixes and velocities (:class:`~graphnav.graph.measurements.Measurements`)."""

    prefix = "gnss_"

    robust: str | None = option("huber", "gross outliers are gated (online) or dropped (batch)")
    k: float | None = option(None, "the robust kernel's threshold [sigmas] (None: huber 1.345, cauchy 2.3849)")
    gate: float | None = option(4.0, "reject fixes whose Mahalanobis distance to the online prediction exceeds it")
    gate_online: bool = option(True,
        "the online gate (the batch's residual drop stays), on both graphs: the Pose3 graph's prediction is pose "
        "k-1's marginal plus the motion's covariance (with k-1's alone, Solent s2 rejected 313 of 555 correct fixes; "
        "with it the gate keeps a 20 m GNSS jump out of the online track of a real boat: psaros33 degraded online "
        "1.72/1.61/1.81 -> 1.61/1.57/1.58 m)")
    gate_max_rejects: int = option(15, "...unless this many in a row were rejected (re-acquire after drift)")
    gate_outage: float = option(5.0, "...and the first fix after a gap this long is not gated (outage)", unit="s")
    velocity_sigma: float = option(0.1,
        "a GNSS velocity record's 1-sigma per axis when it states none", unit="m/s")


@dataclass
class CompassConfig:
    """Compass headings and attitude records (:class:`~graphnav.graph.measurements.Measurements`)."""

    prefix = "compass_"

    robust: str | None = option("huber", "robust kernel on compass factors (None, \"huber\", \"cauchy\")")
    bias: bool = option(True, "estimate a constant compass bias (a bias-frame variable)")
    bias_sigma_deg: float = option(10.0, "prior 1-sigma of that bias", unit="deg")
    bias_segment_s: float | None = option(
        60.0, "the bias frame is one variable per this many seconds of compass readings, consecutive ones tied "
        "by bias_drift_deg: the same constant bias without one variable in every keyframe's clique, which "
        "doubled iSAM2's cost on long logs (a 2400 s boat: 118 -> 67 s CPU; the harbour's figures equal). "
        "None: one variable for the whole log", unit="s")
    bias_drift_deg: float = option(
        1e-4, "the bias's random walk between those variables (1e-4: constant; larger: a deviation that "
        "drifts)", unit="deg/sqrt(s)")

    def __post_init__(self) -> None:
        _positive("compass.bias_segment_s", self.bias_segment_s, none=True)
        _positive("compass.bias_drift_deg", self.bias_drift_deg)
    sigma_scale: float = option(1.0, "x every compass sigma")
    attitude_sigma_deg: float = option(
        1.0, "an attitude record's roll/pitch 1-sigma when it states none (a MEMS AHRS datasheet's dynamic "
        "accuracy); attitude records are used on the IMU graph only (Pose3)", unit="deg", flat="attitude_sigma_deg")


@dataclass
class BeaconConfig:
    """Beacon range/bearing factors (:class:`~graphnav.graph.measurements.Measurements`)."""

    prefix = "beacon_"

    robust: str | None = option("huber", "robust kernel on beacon range/bearing factors")
    k: float | None = option(None, "its threshold [sigmas] (None: huber 1.345, cauchy 2.3849)")
    unknown: bool = option(True, "SLAM on beacons missing from the chart", flat="unknown_beacons")
    sigma_range: float = option(0.1, "when the record gives none: hypot(this, rel * range)", unit="m")
    sigma_range_rel: float = option(0.03, "x the range")
    sigma_bearing_deg: float = option(1.0, "when the record gives none", unit="deg")


@dataclass
class WaterConfig:
    """Water speed and current on the Pose3 graph (:class:`~graphnav.graph.measurements.Measurements`)."""

    prefix = "water_"

    speed_sigma: float = option(0.1,
        "a speed log's 1-sigma along the bow when the record states none", unit="m/s")
    leeway: float = option(0.05, "... across the bow (leeway, sideslip): hypot(this, rel * |v|)", unit="m/s")
    leeway_rel: float = option(0.1, "x |v| (~6 deg of leeway or heading error)")
    current_sigma: float = option(1.0,
        "prior 1-sigma of the water current (per axis) at its first keyframe", unit="m/s", flat="current_sigma")
    current_rw: float = option(0.002, "its random walk: 0.1 m/s in ~40 min (tides turn over hours)",
        unit="m/s/sqrt(s)", flat="current_rw")
    scale_sigma: float | None = option(0.1,
        "prior 1-sigma of the speed log's scale (true speed through water per unit of reading; a log's "
        "calibration within 10 %): estimated with the current (graph.water). None: readings taken as true")
    scale_rw: float = option(5e-4, "the scale's random walk between its variables (a calibration holds "
        "over a voyage: 0.03 in an hour)", unit="1/sqrt(s)")
    scale_segment_s: float | None = option(60.0,
        "one scale variable per this many seconds of readings, consecutive ones tied by scale_rw (as "
        "compass.bias_segment_s); None: one for the whole log", unit="s")
    stall_speed: float | None = option(None, "below this the speed log reads zero (a paddle wheel stalls; a zero "
        "reading is censored: graph.water); None: the smallest non-zero reading so far", unit="m/s")
    reaim_online: bool = option(True, "iSAM2 and fixed-lag: a water-speed factor whose keyframe's yaw estimate "
        "moved beyond relinearize_threshold from the bow it was made with is re-made about the estimate "
        "(graph.water_aim); false: kept as made until the closing step")

    def __post_init__(self) -> None:
        _positive("water.scale_sigma", self.scale_sigma, none=True)
        _positive("water.scale_rw", self.scale_rw)
        _positive("water.scale_segment_s", self.scale_segment_s, none=True)
        _positive("water.stall_speed", self.stall_speed, none=True)

    def leeway_sigma(self, v: float) -> float:
        """[m/s] a water-speed reading's sigma across the bow at speed ``v``: ``hypot(leeway, leeway_rel |v|)``."""
        return math.hypot(self.leeway, self.leeway_rel * abs(v))


@dataclass
class SolverConfig:
    """The solvers' numerics (:class:`~graphnav.graph.navigator.Navigator`, :class:`~graphnav.graph.solver.Solver`,
    :class:`~graphnav.graph.solution.Closing`)."""

    prefix = ""

    lag: float = option(20.0, "fixed-lag window", unit="s")
    rebase_every: int | None = option(6000,
        "live mode (no history kept): re-anchor the fixed-lag smoother every N keyframes")
    isam2_segment: int | None = option(4000,
        "isam2 without a loop closer, or with one while GNSS fixes hold the track: the online iSAM2 starts afresh "
        "every N keyframes from the joint marginal of the variables still in use (the smoothed result solves the "
        "whole graph as before). GTSAM 4.3.0 walks its whole "
        "Bayes tree after every update (ISAM2Result::treeNnz), so an update's cost grows with the log "
        "(docs/performance.md, Session 8); None: one iSAM2 for the whole log")
    isam2_segment_gnss: int | None = option(500,
        "with GNSS fixes holding the track, a segment is the smaller of this and isam2_segment: the fixes re-anchor "
        "each segment, so a short one costs the online track almost nothing (2 h harbour 4000 -> 500: update CPU "
        "64 -> 17 s, online ATE 0.195 -> 0.198 m, smoothed 0.127 m both), while an update's cost grows with the "
        "segment (relinearisation of the old states the fixes move, loops across it); None: as isam2_segment")
    relinearize_threshold: float = option(0.05, "poses: tangent-space change that triggers relinearization")
    relinearize_threshold_landmarks: float = option(0.05,
        "beacons: as the poses (0.5 m, 5-10 sigma of a beacon sighting at 3-6 m, left the online MRCLAM estimate on "
        "stale linearisations: online 0.46 -> 0.42 m on r2)", unit="m")
    relinearize_threshold_bias_deg: float = option(2.0, "compass-bias frame (one factor per compass reading)")
    relinearize_threshold_velocity: float = option(0.05, "velocities (the Pose3 graph)", unit="m/s")
    relinearize_threshold_imu_acc: float = option(
        1e-2, "IMU accelerometer biases: the IMU factor is first order in its bias (preintegration's bias correction "
        "about the bias it was integrated with), so relinearising it gains nothing below a MEMS IMU's turn-on bias "
        "(1e-3 until 2026-12-07: harbour, Solent s1/s2, marina-degraded smoothed ATE equal, online within 0.1 %)",
        unit="m/s^2")
    relinearize_threshold_imu_gyro: float = option(1e-3, "IMU gyro biases (as the accelerometer's; was 1e-4)",
                                                   unit="rad/s")
    relinearize_skip: int | None = option(None,
        "iSAM2 checks for relinearization every N updates (None: 1 on the Pose2 graph; 5 on the Pose3 graph, where a "
        "check every update took 5x the step time for the same ATE: harbour without odometry, first 150 s: 6.0 -> 1.1 "
        "ms median step, ATE 0.756 both)")
    isam_extra_updates: int = option(0, "extra ISAM2.update() calls per keyframe")
    final_updates: int = option(2, "extra ISAM2.update() calls after the last keyframe")
    converge: str = option("lm",
        "the smoothed isam2 result: \"lm\" closing Levenberg-Marquardt from the iSAM2 estimate (= batch), \"updates\" "
        "(final_updates only), \"none\"")
    wildfire_threshold: float | None = option(None,
        "iSAM2 back-substitution stops where the change is below this (None: 0.01 on the Pose3 graph, a fifth of "
        "its pose and velocity relinearisation thresholds; GTSAM's 0.001 on the Pose2 graph). The newest state is "
        "read exactly from its marginal, so this bounds only how stale an older variable's delta may be. Pose3 "
        "0.001 -> 0.01 (2026-12-07): harbour, Solent s1/s2, marina-degraded ATE and NEES equal to 5 digits; the "
        "back-substitution was ~7 % of the harbour run's CPU")
    partial_relinearization_check: bool = option(True, "iSAM2 checks only the cliques the update touched")
    isam_factorization: str = option("QR",
        "iSAM2 clique factorization: \"QR\" (robust) or \"CHOLESKY\" (fails on long chains)")
    isam_optimizer: str = option("gauss-newton",
        "iSAM2 step: \"gauss-newton\" or \"dogleg\" (a trust region; 2-20x the time)")
    lm_tol: float = option(1e-10, "LM relative/absolute decrease tolerance (1e-14: MRCLAM r1 3.8x the time, same ATE)")
    lm_max_iterations: int = option(1000, "(stops at lm_tol first; MRCLAM batch from dead reckoning needs ~300)")
    lm_abs_tol: float = option(
        1e-3, "LM ends when an iteration lowers the cost (1/2 chi^2) by less than this: a change of chi^2 by 0.002 "
        "is statistically nothing (one sigma along any one direction is chi^2 + 1). The vessel graph's closing LM "
        "otherwise crawls along its weakly observed common yaw: psaros33, 1200 s, 117 iterations in 21 s, the cost "
        "0.005 lower than after 10 (positions within 1 mm)")
    lm_stall_tol: float = option(
        0.5, "LM also ends when ten iterations in a row lowered the cost (1/2 chi^2) by less than this together "
        "(0: off). Where the Gauss-Newton step fails (a bilinear coupling: the vessel model's body-frame "
        "acceleration and a yaw no sensor measures) LM crawls with its damping on: psaros33-20140627-0006's 924 s "
        "without a heading took 841 iterations after the 30th for 1.9 of 3540 (positions within 5 mm RMS, those "
        "yaws by up to 40 deg, their sigma 19-43 deg; docs/smoother.md)")
    lm_damping: str = option(
        "nielsen", "how every LM solve updates its damping lambda: \"nielsen\" from each step's gain ratio "
        "(Nielsen 1999; GTSAM's useFixedLambdaFactor false), \"fixed\" GTSAM's default (x10 after a failed try, "
        "/10 after a success). Where the Gauss-Newton step fails the fixed factor pays two solves an iteration and "
        "crawls at lambda 0.1: psaros33-20140627-0006's first 4500 s, 20 iterations from the same point lowered "
        "the cost by 0.11 in 6.3 s CPU with it, by 1.53 in 4.9 s with Nielsen's (docs/smoother.md)")
    covariances: bool = option(True, "per-pose marginal covariances on the final trajectory")
    coast_hz: float | None = option(
        None, "the online output's rate through a gap without records: predicted estimates (the motion model's, "
        "covariance grown by its process noise; flagged coasted) on this grid from the newest estimate, where the "
        "next estimate is more than 1.5 periods away. None: the median rate of the estimates so far, and a gap is "
        "twice their 90th-percentile interval (the keyframe policy's spread is no gap); 0: off (the output then has "
        "a hole wherever the records do)", unit="Hz")
    coast_max_s: float | None = option(
        None, "coasting stops this long after the newest real estimate (no output until a record comes; counted in "
        "coast_stopped). None: no limit -- the predictions' covariance grows with the motion model's process noise "
        "and is published with them (GGA HDOP, Signal K uncertainty), flagged as dead reckoning", unit="s")
    batch_init: str = option("incremental",
        "batch's initial guess: \"incremental\" (LM on the graph so far each time it has grown by batch_init_growth; "
        "between those solves each new keyframe's state solved against its own factors with the earlier ones held, "
        "graphnav.graph.newest_guess) or \"chained\" (dead reckoning)")
    batch_init_growth: float = option(1.5, "... the graph is re-solved at 32, 48, 72, ... keyframes")

    def __post_init__(self) -> None:
        _choice("converge", self.converge, CONVERGE)
        _choice("lm_damping", self.lm_damping, LM_DAMPING)
        _choice("batch_init", self.batch_init, BATCH_INIT)
        if not self.batch_init_growth > 1.0:
            raise ValueError(f"batch_init_growth must be > 1, got {self.batch_init_growth}")
        if self.coast_hz is not None and not (self.coast_hz >= 0 and math.isfinite(self.coast_hz)):
            raise ValueError(f"coast_hz must be >= 0 (0: off) or None (the estimates' rate), got {self.coast_hz}")
        if self.coast_max_s is not None and not self.coast_max_s > 0:
            raise ValueError(f"coast_max_s must be > 0 or None (no limit), got {self.coast_max_s}")


@dataclass
class RobustConfig:
    """The closing step's robust back end (graphnav.graph.gnc) and noise estimation
    (:class:`~graphnav.graph.solution.Closing`)."""

    prefix = "robust_"

    backend: str = option(
        "gnc", "batch / isam2's closing step: scan-match and GNSS factors the data switch off (graduated "
        "non-convexity, truncated least squares) when any lies beyond its chi-square bound; \"off\"")
    prob: float = option(0.99, "that bound's probability (and the odometry consistency check's)")
    gnc_schedule: str = option(
        "superlinear", "how GNC's mu grows from its convex start (GTSAM's GncScheduler): \"superlinear\" "
        "(sqrt(mu) x 1.4 a step while mu < 1, then x 1.4) or \"linear\" (x 1.4 a step, the GNC paper's); the same "
        "decisions in half the steps (graphnav.graph.gnc.SCHEDULES)")
    groups: list[str] = option(
        help="the groups GNC may switch off (every other factor is a known inlier). \"loop\" too: the loop "
        "closer's own pairwise check and Cauchy kernel did as well or better (CARMEN acapulco 0.366 m without, "
        "0.374 m with 9 of 267 loops off)", factory=lambda: ["icp", "cloud", "gnss"])
    noise_estimation: str = option("defaulted",
        "variance scale per sensor group after the batch solution: \"defaulted\" (the groups whose sigmas came "
        "from the defaults above), \"all\", \"off\"", flat="noise_estimation")
    noise_iterations: int = option(3, "re-solves of the variance-component estimation", flat="noise_iterations")
    odometry_scale: bool = option(
        False, "estimate the odometry's scale factors on v and w in the closing step, before the noise "
        "estimation, where the other sensors observe them (graphnav.graph.odometry_scale)", flat="odometry_scale")

    def __post_init__(self) -> None:
        _choice("noise_estimation", self.noise_estimation, NOISE_ESTIMATION)
        _choice("robust_backend", self.backend, ROBUST_BACKEND)
        _choice("robust_gnc_schedule", self.gnc_schedule, GNC_SCHEDULE)
        if not isinstance(self.groups, list | tuple) or any(
                not isinstance(g, str) or g not in ROBUST_GROUPS for g in self.groups):
            raise ValueError(f"robust_groups must be a list of {', '.join(ROBUST_GROUPS)}; got {self.groups!r}")
        if not 0.5 < self.prob < 1.0:
            raise ValueError(f"robust_prob must be in (0.5, 1), got {self.prob}")


@dataclass(init=False)
class SmootherConfig(Sectioned):
    """Every tunable of the navigation graph (settable as ``-O key=value``): the state (``solver``,
    ``motion``, ``imu``, ``mounts``) and one section per collaborator. ``SmootherConfig(gnss_gate=3)``,
    ``SmootherConfig(**{"gnss.gate": 3})``, ``SmootherConfig(gnss={"gate": 3})`` and
    ``SmootherConfig(gnss=GnssConfig(gate=3))`` are the same; ``cfg.gnss.gate`` reads it
    (``cfg.value("gnss_gate")`` by any name).

    Units: metres, seconds; angles in degrees where the name says ``_deg``, else radians.
    """

    what = "smoother"

    solver: str = option("isam2", "\"isam2\" | \"fixed-lag\" | \"batch\" (set by the estimator's name on the CLI)")
    motion: str = option("auto",
        "the state: \"auto\" (Pose3 + velocity + IMU bias, IMU preintegration, when the log has IMU records; "
        "\"vessel\" for a compass with GNSS velocity or water speed, no IMU, odometer or LiDAR; else Pose2: "
        "auto_motion), "
        "\"imu\" (that graph), \"odometry\" (Pose2: odometry / constant velocity, the IMU unused), "
        "\"vessel\" (the Pose3 + velocity graph without an IMU: white-noise acceleration)")
    imu: dict[str, Any] = option(help="options for graphnav.graph.imu_chain.ImuConfig", factory=dict)
    mounts: dict[str, Any] = option(
        help="{sensor: {x, y, z [m], roll, pitch, yaw [rad]}} in the body frame for gnss (antenna), lidar "
        "(extrinsics), imu, water_speed; over the log meta's \"mounts\"", factory=dict)
    keyframe: KeyframeConfig = section(KeyframeConfig, "when a pose is made and what attaches to it (Keyframes, "
                                                       "Anchor's hold)")
    anchor: AnchorConfig = section(AnchorConfig, "the first pose's prior (Anchor)")
    odometry: OdometryConfig = section(OdometryConfig, "odometry records as between factors (Motion's OdometryBuffer)")
    dynamics: MotionConfig = section(MotionConfig, "the motion model between keyframes without odometry; the Pose3 "
                                                   "graph's first velocity and level (Motion)")
    scan: ScanConfig = section(ScanConfig, "scan matching: weighted ICP on 2D scans, loop closures, GICP on 3D clouds "
                                           "(ScanFactors)")
    gnss: GnssConfig = section(GnssConfig, "GNSS fixes and velocities (Measurements; gate_outage: Motion; gate: the "
                                           "closing step)")
    compass: CompassConfig = section(CompassConfig, "compass headings and AHRS attitude records (Measurements)")
    beacon: BeaconConfig = section(BeaconConfig, "beacon range/bearing factors and beacon SLAM (Measurements)")
    water: WaterConfig = section(WaterConfig, "water speed and current, the Pose3 graph (Measurements)")
    optimizer: SolverConfig = section(SolverConfig, "iSAM2, fixed-lag and batch numerics: relinearization, LM, "
                                                    "covariances, batch's initial guess (Navigator, Solver, Closing)")
    robust: RobustConfig = section(RobustConfig, "a back end that cannot lose to its inputs (GNC) and noise the log "
                                                 "does not give (Closing)")

    def __post_init__(self) -> None:
        from .solver import KINDS

        _choice("solver", self.solver, KINDS)
        _choice("motion", self.motion, MOTIONS)
        from .mounts import parse_mounts

        parse_mounts(self.mounts)  # an OptionError naming mounts.SENSOR.FIELD

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> SmootherConfig:
        return config_from_options(cls, options, "smoother")
