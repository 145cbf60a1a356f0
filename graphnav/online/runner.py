"""Record-by-record (online) estimation: estimators by name and the loop that feeds them.

The interface (:class:`graphnav.result.OnlineEstimator`) is one method: ``add(record) -> Estimate | None``
(and optionally ``flush() -> Estimate | None`` at the end of the input, ``info() -> dict``).
Records arrive in time order (late ones are the estimator's business); an
:class:`~graphnav.result.Estimate` is returned whenever the navigation solution changed enough to be
published. Estimators plug into live mode by implementing this protocol and registering a factory in
:data:`ONLINE_ESTIMATORS`: ``fixed-lag`` and ``isam2`` (the navigation graph,
:class:`graphnav.graph.navigator.Navigator`, the same one ``graphnav run -e isam2`` runs; options are
the fields of :class:`graphnav.graph.smoother_config.SmootherConfig`), ``ekf``
(:class:`graphnav.online.ekf_online.EkfOnline`, the batch ``ekf`` step for step).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..log import NavLog
from ..result import OnlineEstimator
from ..trajectory import Trajectory


def _navigator(solver: str) -> Callable[..., OnlineEstimator]:
    def make(**options: Any) -> OnlineEstimator:
        from ..graph.navigator import Navigator

        if options.get("solver", solver) != solver:
            raise ValueError(f"option solver={options['solver']!r} contradicts the estimator ({solver!r})")
        options["solver"] = solver
        return Navigator(history=False, **options)

    make.__doc__ = f"The navigation graph with the {solver} solver (bounded memory: no history kept)."
    return make


def _ekf(**options: Any) -> OnlineEstimator:
    from .ekf_online import EkfOnline

    return EkfOnline(**options)


#: name -> factory(**options)
ONLINE_ESTIMATORS: dict[str, Callable[..., OnlineEstimator]] = {
    "fixed-lag": _navigator("fixed-lag"),
    "isam2": _navigator("isam2"),
    "ekf": _ekf,
}


def make_online(name: str, **options: Any) -> OnlineEstimator:
    """An online estimator by name (``fixed-lag`` (default for unbounded runs), ``isam2``, ``ekf``)."""
    if name not in ONLINE_ESTIMATORS:
        import difflib

        have = ", ".join(sorted(ONLINE_ESTIMATORS))
        close = difflib.get_close_matches(name, sorted(ONLINE_ESTIMATORS), n=2, cutoff=0.6)
        hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
        raise ValueError(f"no online adapter for estimator {name!r} yet ({hint}have: {have});"
                         " estimators plug in through graphnav.result.OnlineEstimator")
    try:
        return ONLINE_ESTIMATORS[name](**options)
    except TypeError as exc:  # an unknown -O option
        raise ValueError(f"estimator {name!r}: {exc}") from None


def run_online(log: NavLog, estimator: OnlineEstimator) -> Trajectory:
    """Feed a log's records in order (then ``flush()``, when the estimator has it); the trajectory
    of the estimates as they were produced."""
    t, poses = [], []
    for r in log.records:
        e = estimator.add(r)
        if e is not None:
            t.append(e.t)
            poses.append(e.vec)
    flush = getattr(estimator, "flush", None)
    if callable(flush):
        e = flush()
        if e is not None:
            t.append(e.t)
            poses.append(e.vec)
    return Trajectory(np.array(t), np.array(poses).reshape(-1, 3), name="online")
