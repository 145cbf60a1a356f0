"""Record-by-record (online) estimation: estimators by name and the loop that feeds them.

The interface (:class:`graphnav.result.OnlineEstimator`) is one method: ``add(record) -> Estimate | None``.
Records arrive in time order (late ones are the estimator's business); an
:class:`~graphnav.result.Estimate` is returned whenever the navigation solution changed enough to be
published. Estimators plug into live mode by implementing this protocol and registering a factory in
:data:`ONLINE_ESTIMATORS`: ``fixed-lag`` and ``isam2``
(:class:`graphnav.graph.graph_online.GraphOnline`), ``ekf``
(:class:`graphnav.online.ekf_online.EkfOnline`, the batch ``ekf`` step for step); the full smoother
of :mod:`graphnav.graph.smoother` has no adapter yet.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..graph.graph_online import GraphOnline
from ..log import NavLog
from ..result import OnlineEstimator
from ..trajectory import Trajectory


def _graph_fixed_lag(**options: Any) -> GraphOnline:
    return GraphOnline(**options)


def _graph_isam2(**options: Any) -> GraphOnline:
    options["lag"] = None
    return GraphOnline(**options)


def _ekf(**options: Any) -> OnlineEstimator:
    from .ekf_online import EkfOnline

    return EkfOnline(**options)


#: name -> factory(**options). The full smoother adapter registers here when it lands.
ONLINE_ESTIMATORS: dict[str, Callable[..., OnlineEstimator]] = {
    "fixed-lag": _graph_fixed_lag,
    "isam2": _graph_isam2,
    "ekf": _ekf,
}


def make_online(name: str, **options: Any) -> OnlineEstimator:
    """An online estimator by name (``fixed-lag`` (default for unbounded runs), ``isam2``, ``ekf``)."""
    if name not in ONLINE_ESTIMATORS:
        have = ", ".join(sorted(ONLINE_ESTIMATORS))
        raise ValueError(f"no online adapter for estimator {name!r} yet (have: {have});"
                         " estimators plug in through graphnav.result.OnlineEstimator")
    try:
        return ONLINE_ESTIMATORS[name](**options)
    except TypeError as exc:  # an unknown -O option
        raise ValueError(f"estimator {name!r}: {exc}") from None


def run_online(log: NavLog, estimator: OnlineEstimator) -> Trajectory:
    """Feed a log's records in order; the trajectory of the estimates as they were produced."""
    t, poses = [], []
    for r in log.records:
        e = estimator.add(r)
        if e is not None:
            t.append(e.t)
            poses.append(e.pose)
    return Trajectory(np.array(t), np.array(poses).reshape(-1, 3), name="online")
