"""The factor-graph smoothers (:mod:`graphnav.graph.smoother`) as estimators: ``isam2``, ``batch``, ``fixed-lag``.

Options are the fields of :class:`graphnav.graph.smoother.SmootherConfig` (``-O key=value``), or with the
IMU motion model those of :class:`graphnav.graph.imu_motion.ImuGraphConfig`. ``-O motion=imu|odometry``
picks the graph; by default (``auto``) a log with IMU records and GNSS but no scans or beacons gets
the IMU graph (:func:`graphnav.graph.imu_motion.wants_imu_graph`), every other log the odometry/ICP graph.
"""

from __future__ import annotations

from typing import Any

from ..graph import imu_motion
from ..graph.smoother import run_batch, run_fixed_lag, run_isam2, unmet
from ..log import NavLog
from . import EstimatorSpec, OnEstimate, RunResult

MOTIONS = ("auto", "odometry", "imu")


def _dispatch(name: str, odometry_run):
    def run(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
        motion = options.pop("motion", "auto")
        if motion not in MOTIONS:
            raise ValueError(f"motion must be one of {MOTIONS}, not {motion!r}")
        if motion == "imu" or (motion == "auto" and imu_motion.wants_imu_graph(log)):
            return imu_motion.RUNNERS[name](log, on_estimate=on_estimate, **options)
        return odometry_run(log, on_estimate=on_estimate, **options)

    run.__doc__ = f"``{name}`` on the IMU graph or the odometry/ICP graph (``motion`` option)."
    return run


def _inputs(log: NavLog, options: dict[str, Any]) -> set[str]:
    """The kinds the graph :func:`_dispatch` picks reads. Keep in step with graphnav/graph/ (the test
    tests/estimators/test_inputs.py drops each kind and checks the output changes exactly when it is listed)."""
    motion = options.get("motion", "auto")
    if motion == "imu" or (motion == "auto" and imu_motion.wants_imu_graph(log)):
        return {"imu", "gnss", "heading", "pose_prior"}
    kinds = {"scan", "gnss", "heading", "beacon", "pose_prior"}
    if log.of("beacon"):
        kinds.add("beacon_known")  # the chart, for the beacons the log observes
    if options.get("use_odometry", True):
        kinds.add("odometry")
    if options.get("use_cloud", True):
        kinds.add("cloud")
    return kinds


ESTIMATORS = {
    "isam2": EstimatorSpec(
        _dispatch("isam2", run_isam2), unmet, "iSAM2 factor-graph smoother: online + smoothed, all sensors",
        "smoother", _inputs
    ),
    "batch": EstimatorSpec(
        _dispatch("batch", run_batch), unmet, "batch Levenberg-Marquardt over the whole factor graph", "smoother",
        _inputs
    ),
    "fixed-lag": EstimatorSpec(
        _dispatch("fixed-lag", run_fixed_lag), unmet, "incremental fixed-lag smoother (bounded memory)", "smoother",
        _inputs
    ),
}
