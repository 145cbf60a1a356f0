"""The factor-graph smoothers as estimators: ``isam2``, ``batch``, ``fixed-lag``, each the
record-by-record :class:`~graphnav.graph.navigator.Navigator` with its solver.

Options are the fields of :class:`graphnav.graph.smoother_config.SmootherConfig` (``-O key=value``). One graph
for every log: ``motion`` (default ``auto``) picks its state -- ``Pose3`` + velocity + IMU bias with
GTSAM IMU preintegration when the log has IMU records, ``Pose2`` with odometry / constant velocity
otherwise (docs/smoother.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

from ..config import config_from_options, given_option
from ..graph.log_runs import unmet
from ..graph.navigator import Navigator, feed
from ..graph.smoother_config import SmootherConfig, auto_motion
from ..log import NavLog, Record
from ..result import Estimate, OnEstimate, RunResult
from .base import Estimator


def _inputs(log: NavLog, options: dict[str, Any]) -> set[str]:
    """The kinds the graph reads (its state space as :class:`graphnav.graph.builder.GraphBuilder`
    picks it). Keep in step with graphnav/graph/ (tests/estimators/test_inputs.py drops each kind and
    checks the output changes exactly when it is listed)."""
    motion = given_option(SmootherConfig, options, "motion", "auto")
    has_imu = bool(log.of("imu"))
    nav = motion in ("imu", "vessel") or (motion == "auto" and auto_motion(log.counts(), log.meta) != "odometry")
    kinds = {"scan", "gnss", "heading", "beacon", "pose_prior"}
    if log.of("beacon"):
        kinds.add("beacon_known")  # the chart, for the beacons the log observes
    use_odo = given_option(SmootherConfig, options, "odometry.use")
    if use_odo or (use_odo is None and not nav):
        kinds.add("odometry")
    if given_option(SmootherConfig, options, "scan.use_cloud", True):
        kinds.add("cloud")
    if nav:
        kinds |= {"gnss_velocity", "water_speed", "attitude"} | ({"imu"} if has_imu else set())
    return kinds


def _solver_options(solver: str, options: dict[str, Any]) -> dict[str, Any]:
    if options.get("solver", solver) != solver:
        raise ValueError(f"option solver={options['solver']!r} contradicts the estimator ({solver!r})")
    return {**options, "solver": solver}


class Smoother(Estimator):
    """The navigation graph with one solver (``solver``): every record into the
    :class:`~graphnav.graph.navigator.Navigator`, its result at the end."""

    kind = "smoother"
    Config = SmootherConfig
    live = True
    what = "smoother"
    solver: ClassVar[str] = "isam2"
    #: its scans are matched from the iSAM2 estimate (batch's loop front end is one), so its weighted-ICP
    #: matches are the other such smoothers' (:mod:`graphnav.scan.icp_cache`; compare runs them in one process)
    shares_matches: ClassVar[bool] = True
    cost: ClassVar[int] = 2

    def __init__(self, log: NavLog | None = None, *, on_estimate: OnEstimate | None = None, **options: Any) -> None:
        super().__init__(log, on_estimate=on_estimate, **_solver_options(self.solver, options))
        if log is not None:
            self.nav = Navigator.for_log(log, self.config, on_estimate=on_estimate)
        else:
            self.nav = Navigator(self.config, on_estimate=on_estimate)
        # records that come in the order of the log's: those its reader checked are not checked again
        self._checked = log.checked_records() if log is not None else None

    unmet = staticmethod(unmet)
    inputs = staticmethod(_inputs)

    @classmethod
    def online(cls, **options: Any) -> Navigator:
        """The navigation graph with this solver, bounded memory (no history kept). The options make its
        config (``imu={...}`` is the config's section, not the navigator's ``imu`` flag)."""
        return Navigator(config_from_options(SmootherConfig, _solver_options(cls.solver, options), "smoother"),
                         history=False)

    def add(self, record: Record) -> Estimate | None:
        return self.nav.add(record, checked=self._was_checked(record))

    def feed(self, records: Sequence[Record]) -> None:
        """:meth:`add` of each record; runs of IMU samples and truth poses at once
        (:func:`graphnav.graph.navigator.feed`)."""
        feed(self.nav, records, [self._was_checked(rec) for rec in records])

    def _was_checked(self, record: Record) -> bool:
        """Whether ``record`` is the log's next one and its reader checked it."""
        if self._checked is not None:
            nxt = next(self._checked, None)
            if nxt is not None and nxt[0] is record:
                return nxt[1]
            self._checked = None  # not the log's next record: every record from here on is checked
        return False

    def finish(self) -> RunResult:
        return self.nav.result()


class Isam2(Smoother):
    """One ``ISAM2.update`` per keyframe; online = the newest pose + its marginal; smoothed = the
    closing LM step from the iSAM2 estimate (``converge``)."""

    description = "iSAM2 factor-graph smoother: online + smoothed, all sensors"
    solver = "isam2"


class Batch(Smoother):
    """Levenberg-Marquardt over the whole log (initialised by chaining the relative measurements);
    GNSS fixes left with a residual beyond ``gnss_gate`` sigmas are dropped and LM re-run."""

    description = "batch Levenberg-Marquardt over the whole factor graph"
    solver = "batch"
    live = False


class FixedLag(Smoother):
    """``IncrementalFixedLagSmoother`` with a ``lag`` [s] window: bounded memory on long runs. The
    final trajectory holds each pose's estimate (and marginal) as it leaves the window."""

    description = "incremental fixed-lag smoother (bounded memory)"
    solver = "fixed-lag"
    shares_matches = False  # its window's estimates guess the matches: never those of isam2 / batch


ESTIMATORS = {"isam2": Isam2, "batch": Batch, "fixed-lag": FixedLag}
