"""The one configuration of the navigation graph (:class:`SmootherConfig`): keyframes, sensors,
motion model, robust kernels, solver, noise estimation. ``-O key=value`` on ``graphnav run`` /
``graphnav live`` and ``Navigator(config)`` / ``**options`` in Python set its fields; an unknown
key is an error naming the known ones. docs/smoother.md explains each group."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..config import config_from_options, option

MOTION_MODELS = ("constant-velocity", "random-walk")
MOTIONS = ("auto", "odometry", "imu", "vessel")
CONVERGE = ("lm", "updates", "none")
NOISE_ESTIMATION = ("off", "defaulted", "all")
BATCH_INIT = ("incremental", "chained")
ROBUST_BACKEND = ("gnc", "off")
ROBUST_GROUPS = ("icp", "loop", "cloud", "gnss")  # the sensor groups the back end may switch off


@dataclass
class SmootherConfig:
    """Every tunable of the navigation graph (settable as ``-O key=value``).

    Units: metres, seconds; angles in degrees where the name says ``_deg``, else radians.
    """

    # -- solver ------------------------------------------------------------------------------
    solver: str = option("isam2", "\"isam2\" | \"fixed-lag\" | \"batch\" (set by the estimator's name on the CLI)")
    lag: float = option(20.0, "fixed-lag window", unit="s")
    rebase_every: int | None = option(6000,
        "live mode (no history kept): re-anchor the fixed-lag smoother every N keyframes")
    relinearize_threshold: float = option(0.05, "poses: tangent-space change that triggers relinearization")
    relinearize_threshold_landmarks: float = option(0.05,
        "beacons: as the poses (0.5 m, 5-10 sigma of a beacon sighting at 3-6 m, left the online MRCLAM estimate on "
        "stale linearisations: online 0.46 -> 0.42 m on r2)", unit="m")
    relinearize_threshold_bias_deg: float = option(2.0, "compass-bias frame (one factor per compass reading)")
    relinearize_threshold_velocity: float = option(0.05, "velocities (the Pose3 graph)", unit="m/s")
    relinearize_threshold_imu_acc: float = option(1e-3, "IMU accelerometer biases", unit="m/s^2")
    relinearize_threshold_imu_gyro: float = option(1e-4, "IMU gyro biases", unit="rad/s")
    relinearize_skip: int | None = option(None,
        "iSAM2 checks for relinearization every N updates (None: 1 on the Pose2 graph; 5 on the Pose3 graph, where a "
        "check every update took 5x the step time for the same ATE: harbour without odometry, first 150 s: 6.0 -> 1.1 "
        "ms median step, ATE 0.756 both)")
    isam_extra_updates: int = option(0, "extra ISAM2.update() calls per keyframe")
    final_updates: int = option(2, "extra ISAM2.update() calls after the last keyframe")
    converge: str = option("lm",
        "the smoothed isam2 result: \"lm\" closing Levenberg-Marquardt from the iSAM2 estimate (= batch), \"updates\" "
        "(final_updates only), \"none\"")
    wildfire_threshold: float = option(0.001, "iSAM2 back-substitution stops where the change is below this")
    partial_relinearization_check: bool = option(True, "iSAM2 checks only the cliques the update touched")
    isam_factorization: str = option("QR",
        "iSAM2 clique factorization: \"QR\" (robust) or \"CHOLESKY\" (fails on long chains)")
    isam_optimizer: str = option("gauss-newton",
        "iSAM2 step: \"gauss-newton\" or \"dogleg\" (a trust region; 2-20x the time)")
    lm_tol: float = option(1e-10, "LM relative/absolute decrease tolerance (1e-14: MRCLAM r1 3.8x the time, same ATE)")
    lm_max_iterations: int = option(1000, "(stops at lm_tol first; MRCLAM batch from dead reckoning needs ~300)")
    covariances: bool = option(True, "per-pose marginal covariances on the final trajectory")
    batch_init: str = option("incremental",
        "batch's initial guess: \"incremental\" (LM on the graph so far each time it has grown by batch_init_growth, "
        "later poses chained from that solution) or \"chained\" (dead reckoning)")
    batch_init_growth: float = option(1.5, "... the graph is re-solved at 32, 48, 72, ... keyframes")

    # -- keyframes and attachment ---------------------------------------------------------------
    keyframe_period: float | None = option(None, "None: one pose per scan (a 0.5 s grid without scans)")
    scan_stride: int = option(1, "with scans: a keyframe (and an ICP match) every N-th scan")
    keyframe_motion: bool | None = option(
        None, "with scans and an IMU: a scan becomes a keyframe only once the motion since the newest keyframe "
        "reaches keyframe_distance or keyframe_angle_deg, or keyframe_max_dt has passed (LIO-SAM's keyframe rule, "
        "Shan et al. 2020: 1 m, 0.2 rad; the IMU carries the motion between keyframes). None: on for the IMU "
        "graph, off (every scan) elsewhere. New harbour, 200 s: ATE 0.172 every scan, 0.172 at every 10th, 3x "
        "less CPU")
    keyframe_distance: float = option(1.0, "keyframe_motion: the distance that makes a keyframe", unit="m")
    keyframe_angle_deg: float = option(11.46, "keyframe_motion: the turn that makes a keyframe (0.2 rad)",
                                       unit="deg")
    keyframe_max_dt: float = option(1.0, "keyframe_motion: at least one keyframe this often (the online output "
                                    "rate)", unit="s")
    grid_gap: float = option(5.0, "grid slots inside a gap without any record longer than this are skipped", unit="s")
    compensate_attachment: bool = option(True, "move each measurement to its keyframe's time by the motion between")
    anchor_wait: float = option(2.0, "records are held this long (log time) to choose the anchor", unit="s")

    # -- motion: every new pose is tied to the previous one -------------------------------------
    motion: str = option("auto",
        "the state: \"auto\" (Pose3 + velocity + IMU bias, IMU preintegration, when the log has IMU records; "
        "else Pose2), \"imu\" (that graph), \"odometry\" (Pose2: odometry / constant velocity, the IMU unused), "
        "\"vessel\" (the Pose3 + velocity graph without an IMU: white-noise acceleration)")
    imu: dict[str, Any] = option(help="options for graphnav.graph.imu_chain.ImuConfig", factory=dict)
    v0_sigma: float = option(5.0,
        "the Pose3 graph: prior 1-sigma of the first velocity (at rest; GNSS decides)", unit="m/s")
    use_odometry: bool | None = option(None,
        "odometry records as between factors (false: the motion model ties the poses). None: on the Pose2 graph yes; "
        "on the Pose3 graph (an IMU) no: a record of speed along the bow and rate of turn is a unicycle, wrong for a "
        "boat in a current (Solent s1, 0.85 m/s current: isam2 3.36 m with it, 1.25 m without; the UKF 3.16 m)")
    # when the log gives no odometry sigmas: noise densities [per sqrt(s)], so the integrated error
    # does not depend on the sample rate, hypot(floor, rel * |v|) and hypot(floor, rel * |w|)
    odo_sigma_v: float = option(0.02, "odometry speed noise density floor (when the log gives no sigmas): "
                                "hypot(this, odo_sigma_v_rel * |v|)", unit="m/s sqrt(s)")
    odo_sigma_v_rel: float = option(0.1, "x |v|")
    odo_sigma_w_deg: float = option(1.0, "floor", unit="deg/s sqrt(s)")
    odo_sigma_w_rel: float = option(0.1, "x |w|")
    odo_lateral: float = option(0.1, "lateral (sway, crab, wheel slip) 1-sigma as a fraction of the distance run")
    motion_model: str = option("constant-velocity", "without odometry: \"constant-velocity\" | \"random-walk\"")
    cv_sigma_v: float = option(0.5,
        "constant velocity: 1-sigma velocity change -> sigma_xy = cv_sigma_v dt", unit="m/s")
    cv_sigma_w_deg: float = option(10.0, "its yaw counterpart", unit="deg/s")
    cv_accel: float = option(0.3, "the velocity's 1-sigma grows by this per second since it was measured", unit="m/s^2")
    cv_max_age: float = option(60.0, "the last measured motion (or GNSS velocity) is kept this long", unit="s")
    cv_gnss_window: float = option(10.0,
        "GNSS fixes fitted for the speed over ground (no odometry, no scans)", unit="s")
    rw_sigma_v: float = option(2.0, "random walk (no motion known): sigma_xy = rw_sigma_v dt", unit="m/s")
    rw_sigma_w_deg: float = option(30.0, "its yaw counterpart", unit="deg/s")
    motion_floor_xy: float = option(1e-3, "added in quadrature to every motion factor (dt = 0 stays proper)", unit="m")
    motion_floor_yaw_deg: float = option(0.01, "its yaw counterpart", unit="deg")

    # -- scans (weighted ICP) --------------------------------------------------------------------
    use_icp: bool = option(True, "false: no weighted-ICP factors between scans")
    icp_robust: str | None = option(None, "robust kernel on ICP factors (None, \"huber\", \"cauchy\")")
    icp_max_step: float = option(5.0, "an ICP step farther than this from the prediction is rejected", unit="m")
    icp_gate: float | None = option(4.0, "reject a match whose Mahalanobis distance to the odometry exceeds it")
    icp: dict[str, Any] = option(help="options for graphnav.scan.weighted_icp.IcpConfig", factory=dict)

    # -- loop closures (graphnav.graph.loops, docs/loops.md) ------------------------------------
    loops: bool = option(True, "close loops when the log has scans")
    loop: dict[str, Any] = option(help="options for graphnav.graph.loops.LoopConfig", factory=dict)

    # -- 3D clouds (GICP, projected to SE(2); docs/scan-matching-3d.md "3D in the graph") ---------
    use_cloud: bool = option(True, "one keyframe per cloud (every scan_stride-th) and a GICP factor to the previous")
    # the cloud factor's covariance is the match's own (cloud_match.match_covariance), not scaled
    cloud_sigma_floor_xy: float = option(0.005, "added in quadrature to the cloud factor's sigma", unit="m")
    cloud_sigma_floor_yaw_deg: float = option(0.02, "its yaw counterpart", unit="deg")
    cloud: dict[str, Any] = option(help="options for graphnav.scan.cloud_match.CloudMatchConfig", factory=dict)

    # -- GNSS ------------------------------------------------------------------------------------
    gnss_robust: str | None = option("huber", "gross outliers are gated (online) or dropped (batch)")
    gnss_k: float | None = option(None, "the robust kernel's threshold [sigmas] (None: huber 1.345, cauchy 2.3849)")
    gnss_gate: float | None = option(4.0, "reject fixes whose Mahalanobis distance to the online prediction exceeds it")
    gnss_gate_online: bool | None = option(None,
        "the online gate (the batch's residual drop stays): None = on the Pose2 graph, off on the Pose3 graph, whose "
        "online prediction drifts under a biased IMU and then rejected correct fixes (Solent s2, 20 m fixes: 313 of "
        "555 rejected, ATE 14.2 m; 3.2 m without it; the harbour unchanged); its outliers are left to the robust "
        "kernel and the batch's drop")
    gnss_gate_max_rejects: int = option(15, "...unless this many in a row were rejected (re-acquire after drift)")
    gnss_gate_outage: float = option(5.0, "...and the first fix after a gap this long is not gated (outage)", unit="s")
    attitude_sigma_deg: float = option(
        1.0, "an attitude record's roll/pitch 1-sigma when it states none (a MEMS AHRS datasheet's dynamic "
        "accuracy); attitude records are used on the IMU graph only (Pose3)", unit="deg")
    level_sigma_deg: float = option(
        1.0, "roll/pitch 1-sigma of the level constraint on every keyframe of the Pose3 graph when the IMU is planar "
        "(3-axis: levelled horizontal specific force and yaw rate) or absent: such records define a level body "
        "frame and observe no roll or pitch, which would otherwise wander freely and rotate the planar motion; "
        "0 turns it off", unit="deg")
    gnss_velocity_sigma: float = option(0.1,
        "a GNSS velocity record's 1-sigma per axis when it states none", unit="m/s")

    # -- water speed and current (the Pose3 graph) ----------------------------------------------
    water_speed_sigma: float = option(0.1,
        "a speed log's 1-sigma along the bow when the record states none", unit="m/s")
    water_leeway: float = option(0.05, "... across the bow (leeway, sideslip): hypot(this, rel * |v|)", unit="m/s")
    water_leeway_rel: float = option(0.1, "x |v| (~6 deg of leeway or heading error)")
    current_sigma: float = option(1.0,
        "prior 1-sigma of the water current (per axis) at its first keyframe", unit="m/s")
    current_rw: float = option(0.002, "its random walk: 0.1 m/s in ~40 min (tides turn over hours)", unit="m/s/sqrt(s)")

    # -- compass ---------------------------------------------------------------------------------
    compass_robust: str | None = option("huber", "robust kernel on compass factors (None, \"huber\", \"cauchy\")")
    compass_bias: bool = option(True, "estimate a constant compass bias (a bias-frame variable)")
    compass_bias_sigma_deg: float = option(10.0, "prior 1-sigma of that bias", unit="deg")
    compass_sigma_scale: float = option(1.0, "x every compass sigma")

    # -- beacons ---------------------------------------------------------------------------------
    beacon_robust: str | None = option("huber", "robust kernel on beacon range/bearing factors")
    beacon_k: float | None = option(None, "its threshold [sigmas] (None: huber 1.345, cauchy 2.3849)")
    unknown_beacons: bool = option(True, "SLAM on beacons missing from the chart")
    beacon_sigma_range: float = option(0.1, "when the record gives none: hypot(this, rel * range)", unit="m")
    beacon_sigma_range_rel: float = option(0.03, "x the range")
    beacon_sigma_bearing_deg: float = option(1.0, "when the record gives none", unit="deg")

    # -- anchor ----------------------------------------------------------------------------------
    anchor_sigma_xy: float | None = option(None, "prior on the first pose when there is no pose_prior record")
    anchor_sigma_yaw_deg: float = option(30.0, "... its yaw sigma at the first compass reading")
    anchor_sigma_yaw_unknown_deg: float = option(60.0,
        "... at yaw 0 without one: 1 rad, not pi, or iSAM2's Gauss-Newton step diverges where nothing else observes "
        "the yaw (a GNSS-only log); odometry and GNSS recover a start 180 deg off (square loop: online 0.80 m against "
        "0.68 m with pi)")

    # -- a back end that cannot lose to its inputs (graphnav.graph.gnc) ------------------------
    robust_backend: str = option(
        "gnc", "batch / isam2's closing step: scan-match and GNSS factors the data switch off (graduated "
        "non-convexity, truncated least squares) when any lies beyond its chi-square bound; \"off\"")
    robust_prob: float = option(0.99, "that bound's probability (and the odometry consistency check's)")
    robust_groups: list[str] = option(
        help="the groups GNC may switch off (every other factor is a known inlier). \"loop\" too: the loop "
        "closer's own pairwise check and Cauchy kernel did as well or better (CARMEN acapulco 0.366 m without, "
        "0.374 m with 9 of 267 loops off)", factory=lambda: ["icp", "cloud", "gnss"])

    # -- sensor mounts (lever arms and rotations; graphnav.graph.mounts, docs/mounts.md) -----------------
    mounts: dict[str, Any] = option(
        help="{sensor: {x, y, z [m], roll, pitch, yaw [rad]}} in the body frame for gnss (antenna), lidar "
        "(extrinsics), imu, water_speed; over the log meta's \"mounts\"", factory=dict)

    # -- noise the log does not give --------------------------------------------------------------
    noise_estimation: str = option("defaulted",
        "variance scale per sensor group after the batch solution: \"defaulted\" (the groups whose sigmas came "
        "from the defaults above), \"all\", \"off\"")
    noise_iterations: int = option(3, "re-solves of the variance-component estimation")

    def __post_init__(self) -> None:
        from .solver import KINDS

        for name, val, allowed in (("solver", self.solver, KINDS), ("motion_model", self.motion_model, MOTION_MODELS),
                                   ("converge", self.converge, CONVERGE), ("motion", self.motion, MOTIONS),
                                   ("noise_estimation", self.noise_estimation, NOISE_ESTIMATION),
                                   ("batch_init", self.batch_init, BATCH_INIT),
                                   ("robust_backend", self.robust_backend, ROBUST_BACKEND)):
            if val not in allowed:
                raise ValueError(f"{name} must be one of {', '.join(allowed)}; got {val!r}")
        if not self.batch_init_growth > 1.0:
            raise ValueError(f"batch_init_growth must be > 1, got {self.batch_init_growth}")
        if not isinstance(self.robust_groups, list | tuple) or any(
                not isinstance(g, str) or g not in ROBUST_GROUPS for g in self.robust_groups):
            raise ValueError(f"robust_groups must be a list of {', '.join(ROBUST_GROUPS)}; got {self.robust_groups!r}")
        if not 0.5 < self.robust_prob < 1.0:
            raise ValueError(f"robust_prob must be in (0.5, 1), got {self.robust_prob}")
        if self.scan_stride < 1:
            raise ValueError(f"scan_stride must be >= 1, got {self.scan_stride}")
        for name in ("keyframe_distance", "keyframe_angle_deg", "keyframe_max_dt"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.keyframe_period is not None and not self.keyframe_period > 0:
            raise ValueError(f"keyframe period must be > 0, got {self.keyframe_period}")
        from .mounts import parse_mounts

        parse_mounts(self.mounts)  # an OptionError naming mounts.SENSOR.FIELD

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> SmootherConfig:
        return config_from_options(cls, options, "smoother")
