"""The factor-graph smoothers ``isam2``, ``batch`` and ``fixed-lag`` on a whole log: thin loops over
the record-by-record :class:`~graphnav.graph.navigator.Navigator` (one graph builder,
:mod:`graphnav.graph.builder`; one solver wrapper, :mod:`graphnav.graph.solver`), so the three
and every online user solve exactly the same problem. Options are the fields of
:class:`~graphnav.graph.smoother_config.SmootherConfig`.
"""

from __future__ import annotations

from typing import Any

from ..log import NavLog
from ..result import OnEstimate, RunResult
from .builder import Matcher, default_matcher
from .navigator import Navigator, world_cov
from .smoother_config import SmootherConfig

__all__ = ["SmootherConfig", "default_matcher", "run", "run_batch", "run_fixed_lag", "run_isam2", "unmet",
           "world_cov"]


def run(log: NavLog, solver: str, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None,
        **options: Any) -> RunResult:
    """Every record of ``log`` through a :class:`Navigator` with ``solver``; its :class:`RunResult`."""
    if options.get("solver", solver) != solver:
        raise ValueError(f"option solver={options['solver']!r} contradicts the estimator ({solver!r})")
    options["solver"] = solver
    nav = Navigator.for_log(log, SmootherConfig.from_options(options), matcher=matcher, on_estimate=on_estimate)
    for rec, checked in log.checked_records():  # a reader's records are not checked twice
        nav.add(rec, checked=checked)
    return nav.result()


def run_isam2(log: NavLog, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None,
              **options: Any) -> RunResult:
    """One ``ISAM2.update`` per keyframe; online = the newest pose + its marginal; smoothed = the
    closing LM step from the iSAM2 estimate (``converge``)."""
    return run(log, "isam2", on_estimate=on_estimate, matcher=matcher, **options)


def run_batch(log: NavLog, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None,
              **options: Any) -> RunResult:
    """Levenberg-Marquardt over the whole log (initialised by chaining the relative measurements);
    GNSS fixes left with a residual beyond ``gnss_gate`` sigmas are dropped and LM re-run."""
    return run(log, "batch", on_estimate=on_estimate, matcher=matcher, **options)


def run_fixed_lag(log: NavLog, *, on_estimate: OnEstimate | None = None, matcher: Matcher | None = None,
                  **options: Any) -> RunResult:
    """``IncrementalFixedLagSmoother`` with a ``lag`` [s] window: bounded memory on long runs. The
    final trajectory holds each pose's estimate (and marginal) as it leaves the window."""
    return run(log, "fixed-lag", on_estimate=on_estimate, matcher=matcher, **options)


def unmet(log: NavLog) -> str | None:
    """Why the smoother cannot run on ``log`` (``None`` if it can)."""
    if not len(log):
        return "the log is empty"
    kinds = log.counts()
    if not any(kinds.get(k) for k in ("scan", "cloud", "odometry", "gnss", "beacon")):
        return "needs scans, clouds, odometry, GNSS or beacon observations"
    return None
