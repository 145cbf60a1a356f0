"""The factor-graph smoothers (:mod:`graphnav.graph.smoother`) as estimators: ``isam2``, ``batch``, ``fixed-lag``.

Options are the fields of :class:`graphnav.graph.config.SmootherConfig` (``-O key=value``). One graph
for every log: ``motion`` (default ``auto``) picks its state -- ``Pose3`` + velocity + IMU bias with
GTSAM IMU preintegration when the log has IMU records, ``Pose2`` with odometry / constant velocity
otherwise (docs/smoother.md).
"""

from __future__ import annotations

from ..graph.smoother import run_batch, run_fixed_lag, run_isam2, unmet
from . import EstimatorSpec

ESTIMATORS = {
    "isam2": EstimatorSpec(run_isam2, unmet, "iSAM2 factor-graph smoother: online + smoothed, all sensors", "smoother"),
    "batch": EstimatorSpec(run_batch, unmet, "batch Levenberg-Marquardt over the whole factor graph", "smoother"),
    "fixed-lag": EstimatorSpec(run_fixed_lag, unmet, "incremental fixed-lag smoother (bounded memory)", "smoother"),
}
