"""What estimators return: :class:`RunResult` (batch) and :class:`Estimate` (online, one record at a
time, from an :class:`OnlineEstimator`).

Kernel types: every layer (graphs, estimators, online runners, evaluation) imports them from here,
so no package imports back up the one that runs it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from .log import Record
from .trajectory import Trajectory

OnEstimate = Callable[[float, NDArray[np.float64], NDArray[np.float64] | None], None]


@dataclass
class RunResult:
    """What an estimator returns.

    ``trajectory`` is the final estimate (smoothed, for smoothers); ``online`` the estimate
    that was available at each time (filters: the same as ``trajectory``); ``step_ms`` the
    solver/filter time per step [ms] excluding scan matching, ``icp_ms`` scan-matching time per
    scan pair [ms]; ``info`` configuration and anything worth reporting (JSON-serialisable).
    """

    trajectory: Trajectory
    online: Trajectory | None = None
    step_ms: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    icp_ms: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    info: dict[str, Any] = field(default_factory=dict)

    # -- short summaries (the dataclass repr would print every pose and the whole info) --------------
    def _facts(self) -> dict[str, str]:
        def med(a: NDArray) -> str:
            return f"{float(np.median(a)):.3g} ms (median of {len(a)})" if len(a) else "–"

        online = ("the trajectory" if self.online is self.trajectory else
                  "none" if self.online is None else f"{len(self.online)} poses")
        keys = list(self.info)
        return {"trajectory": repr(self.trajectory), "online": online, "step": med(self.step_ms),
                "scan match": med(self.icp_ms),
                "info": ", ".join(keys[:12]) + (f", … ({len(keys)} keys)" if len(keys) > 12 else "")}

    def __repr__(self) -> str:
        f = self._facts()
        return (f"<RunResult: {len(self.trajectory)} poses"
                + (" with covariance" if self.trajectory.cov is not None else "")
                + f"; online: {f['online']}; step {f['step']}; info keys: {len(self.info)}>")

    def _repr_html_(self) -> str:
        """A small table for notebooks."""
        from html import escape

        rows = "".join(f"<tr><th>{k}</th><td>{escape(v)}</td></tr>" for k, v in self._facts().items())
        return f"<b>RunResult</b><table>{rows}</table>"


@dataclass
class Estimate:
    """The navigation solution at time ``t``: ``vec`` = (x, y, yaw) (``pose`` gives it as a
    ``gtsam.Pose2``), its 3x3 covariance in the world frame, order x, y, yaw (or None) and, when
    known, speed over ground [m/s], course over ground [rad, CCW from east], yaw rate [rad/s].
    ``coasted``: a prediction through a gap without records (the motion model's, no measurement
    since the previous estimate; :meth:`graphnav.graph.navigator.Navigator.coast`).
    ``vec`` may be given as a ``gtsam.Pose2``."""

    t: float
    vec: NDArray[np.float64]
    cov: NDArray[np.float64] | None = None
    sog: float | None = None
    cog: float | None = None
    w: float | None = None
    coasted: bool = False

    def __post_init__(self) -> None:
        v = self.vec
        if hasattr(v, "theta"):  # a gtsam.Pose2
            v = (v.x(), v.y(), v.theta())
        self.vec = np.asarray(v, dtype=float).reshape(3)

    @property
    def pose(self):  # -> gtsam.Pose2 (gtsam imported only when asked: the kernel stays light)
        """The pose as a ``gtsam.Pose2``."""
        import gtsam

        return gtsam.Pose2(float(self.vec[0]), float(self.vec[1]), float(self.vec[2]))


class OnlineEstimator(Protocol):
    """What live mode needs from an estimator."""

    def add(self, record: Record) -> Estimate | None: ...
