"""Record-by-record (online) estimation: the loop that feeds an online estimator.

The interface (:class:`graphnav.result.OnlineEstimator`) is one method: ``add(record) -> Estimate | None``
(and optionally ``flush() -> Estimate | None`` at the end of the input, ``info() -> dict``).
Records arrive in time order (late ones are the estimator's business); an
:class:`~graphnav.result.Estimate` is returned whenever the navigation solution changed enough to be
published. Estimators come from the one registry, :func:`graphnav.estimators.make_online` (re-exported
here): those whose class has a live form (``Estimator.online``): ``fixed-lag`` and ``isam2`` (the
navigation graph, :class:`graphnav.graph.navigator.Navigator`, the same one ``graphnav run -e isam2``
runs), ``ekf`` (:class:`graphnav.estimators.ekf_online.EkfOnline`, the batch ``ekf`` step for step).
"""

from __future__ import annotations

import numpy as np

from ..estimators import make_online, online_names
from ..log import NavLog
from ..result import Estimate, OnlineEstimator
from ..trajectory import Trajectory

__all__ = ["make_online", "online_names", "run_online"]


def run_online(log: NavLog, estimator: OnlineEstimator) -> Trajectory:
    """Feed a log's records in order (then ``flush()``, when the estimator has it); the trajectory
    of the estimates as they were produced, with the predictions an estimator coasted through a gap
    without records before each (its ``coasted_out``; ``meta["coasted"]`` flags them)."""
    t, poses, coasted = [], [], []

    def put(e: Estimate) -> None:
        t.append(e.t)
        poses.append(e.vec)
        coasted.append(e.coasted)

    for r in log.records:
        e = estimator.add(r)
        for c in getattr(estimator, "coasted_out", ()):  # predictions through the gap before it
            put(c)
        if e is not None:
            put(e)
    flush = getattr(estimator, "flush", None)
    if callable(flush):
        e = flush()
        if e is not None:
            put(e)
    return Trajectory(np.array(t), np.array(poses).reshape(-1, 3), name="online",
                      meta={"coasted": np.array(coasted, dtype=bool)})
