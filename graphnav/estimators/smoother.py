"""The factor-graph smoothers (:mod:`graphnav.graph.log_runs`) as estimators: ``isam2``, ``batch``, ``fixed-lag``.

Options are the fields of :class:`graphnav.graph.smoother_config.SmootherConfig` (``-O key=value``). One graph
for every log: ``motion`` (default ``auto``) picks its state -- ``Pose3`` + velocity + IMU bias with
GTSAM IMU preintegration when the log has IMU records, ``Pose2`` with odometry / constant velocity
otherwise (docs/smoother.md).
"""

from __future__ import annotations

from typing import Any

from ..graph.log_runs import run_batch, run_fixed_lag, run_isam2, unmet
from ..log import NavLog
from . import EstimatorSpec


def _inputs(log: NavLog, options: dict[str, Any]) -> set[str]:
    """The kinds the graph reads (its state space as :class:`graphnav.graph.builder.GraphBuilder`
    picks it). Keep in step with graphnav/graph/ (tests/estimators/test_inputs.py drops each kind and
    checks the output changes exactly when it is listed)."""
    motion = options.get("motion", "auto")
    has_imu = bool(log.of("imu"))
    nav = motion in ("imu", "vessel") or (motion == "auto" and has_imu)
    kinds = {"scan", "gnss", "heading", "beacon", "pose_prior"}
    if log.of("beacon"):
        kinds.add("beacon_known")  # the chart, for the beacons the log observes
    use_odo = options.get("use_odometry")
    if use_odo or (use_odo is None and not nav):
        kinds.add("odometry")
    if options.get("use_cloud", True):
        kinds.add("cloud")
    if nav:
        kinds |= {"gnss_velocity", "water_speed"} | ({"imu"} if has_imu else set())
    return kinds


ESTIMATORS = {
    "isam2": EstimatorSpec(run_isam2, unmet, "iSAM2 factor-graph smoother: online + smoothed, all sensors", "smoother",
                           _inputs),
    "batch": EstimatorSpec(run_batch, unmet, "batch Levenberg-Marquardt over the whole factor graph", "smoother",
                           _inputs),
    "fixed-lag": EstimatorSpec(run_fixed_lag, unmet, "incremental fixed-lag smoother (bounded memory)", "smoother",
                               _inputs),
}
