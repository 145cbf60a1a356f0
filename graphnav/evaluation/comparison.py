"""Run several estimators on one log and score them the same way: one loop.

Pure: no files, no printing. :mod:`graphnav.evaluation.report` turns the result into report.md and figures,
:mod:`graphnav.commands.compare` is the CLI.
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np

from .. import estimators
from ..log import NavLog
from ..result import RunResult
from ..scan import icp_cache
from ..trajectory import Trajectory
from .datacheck import data_checks
from .evaluate import summarize
from .holdout import Holdout, HoldoutSpec, ranking, withhold
from .metrics import associate


@dataclass
class Entry:
    """One estimator's outcome: ``summary`` (the shared JSON keys of :func:`summarize`) and the
    ``result``; or ``skipped`` (why the log cannot feed it: it was not run), or ``error`` (it failed,
    or the name is unknown)."""

    name: str
    kind: str = ""
    description: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    result: RunResult | None = None
    summary: dict[str, Any] | None = None
    error: str | None = None
    runtime_s: float = float("nan")
    traceback: str | None = None
    skipped: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None and self.skipped is None


@dataclass
class Comparison(Sequence[Entry]):
    """What :func:`compare` returns: the entries (a sequence of them, in the order asked) and what
    they were run on. ``log`` is the log the estimators saw (under a hold-out: without the withheld
    GNSS), ``whole_log`` the log as read; ``checks`` its gaps and GNSS jumps
    (:func:`~graphnav.evaluation.datacheck.data_checks`); ``holdout`` the plan, when one was asked."""

    entries: list[Entry]
    log: NavLog
    log_name: str = ""
    whole_log: NavLog | None = None
    holdout: Holdout | None = None
    dropped: list[str] = field(default_factory=list)
    checks: dict[str, Any] = field(default_factory=dict)
    workers: int = 1
    runtime_s: float = float("nan")
    icp_cache_hits: int | None = None

    @overload
    def __getitem__(self, i: int) -> Entry: ...
    @overload
    def __getitem__(self, i: slice) -> list[Entry]: ...
    def __getitem__(self, i: int | slice) -> Entry | list[Entry]:
        return self.entries[i]

    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self) -> Iterator[Entry]:
        return iter(self.entries)

    @property
    def ran(self) -> list[Entry]:
        """The entries that ran and gave a trajectory."""
        return [e for e in self.entries if e.ok and e.result is not None]

    def trajectories(self) -> dict[str, Trajectory]:
        return {e.name: e.result.trajectory for e in self.ran}

    def holdout_ranking(self) -> list[str]:
        """Estimator names by hold-out RMSE (smallest first); empty without a hold-out."""
        return ranking({e.name: e.summary["holdout"] for e in self.ran if "holdout" in (e.summary or {})})

    def same_tracks(self, tol_m: float = 1e-3) -> dict[str, tuple[str, float]]:
        """Estimators whose track equals an earlier one's (by the order given) within ``tol_m``
        metres at every common time stamp: ``{name: (earlier name, largest difference [m])}``."""
        out: dict[str, tuple[str, float]] = {}
        ran = self.ran
        for i, e in enumerate(ran):
            for f in ran[:i]:
                d = track_difference(e.result.trajectory, f.result.trajectory)
                if d is not None and d <= tol_m and f.name not in out:
                    out[e.name] = (f.name, d)
                    break
        return out


def track_difference(a: Trajectory, b: Trajectory, max_dt: float = 1e-6) -> float | None:
    """The largest position difference [m] between two tracks at their common time stamps (``None``
    when they share fewer than 90 % of the shorter one's stamps)."""
    ia, ib = associate(a, b, max_dt)
    if len(ia) < max(2, 0.9 * min(len(a), len(b))):
        return None
    return float(np.max(np.hypot(a.x[ia] - b.x[ib], a.y[ia] - b.y[ib])))


def _run(entry: Entry, est: str, log: NavLog) -> Entry:
    """Run one estimator into ``entry`` (timing, summary, or the error)."""
    cache = icp_cache.current()
    hits0, n0 = (cache.hits, len(cache.ms)) if cache is not None else (0, 0)
    t0 = time.perf_counter()
    try:
        res = estimators.run(est, log, **entry.options)
        entry.runtime_s = time.perf_counter() - t0
        entry.result = res
        entry.summary = summarize(entry.name, res, log, runtime_s=entry.runtime_s)
        entry.summary["inputs"] = estimators.inputs(est, log, entry.options, res.info)
        if cache is not None:
            entry.summary["icp_cache_hits"] = cache.hits - hits0
            if cache.hits > hits0:  # a shared match costs what it cost its first computation
                entry.summary["icp_ms_median"] = float(np.median(cache.ms[n0:]))
    except Exception as exc:  # an estimator that fails is reported, not fatal
        entry.runtime_s = time.perf_counter() - t0
        entry.error = f"{type(exc).__name__}: {exc}"
        entry.result = None
        entry.summary = None
        entry.traceback = traceback.format_exc()
    return entry


def compare(log: NavLog, names: Sequence[str] | None = None, *,
            options: dict[str, dict[str, Any]] | None = None,
            progress: Callable[[str], None] | None = None, workers: int = 1,
            cache: icp_cache.MatchCache | None = None, holdout: HoldoutSpec | None = None,
            log_name: str = "", dropped: Sequence[str] = (),
            meanwhile: Callable[[], None] | None = None) -> Comparison:
    """Run ``names`` (default: every registered estimator) on ``log``; each with its own
    ``options[name]``. An estimator the log cannot feed is not run but kept, with ``skipped`` saying
    why (its ``unmet(log)``); a failing one is recorded with its ``error``, not raised.

    A name ``LABEL=ESTIMATOR`` runs ``ESTIMATOR`` under the label ``LABEL`` (options keyed by the
    label), so one estimator can appear twice, e.g. ``["scan-to-map", "s2m-gicp=scan-to-map"]``
    with ``options={"s2m-gicp": {"backend": "gicp"}}``.

    ``workers > 1`` runs the estimators in that many processes at once (results in the same
    order); each ``runtime_s`` is then measured while the others run, so it includes contention.
    The estimators that share weighted-ICP matches through ``cache`` (the factor-graph smoothers,
    ``kind == "smoother"``: one builder, the same matches) run one after another in one process,
    so the sharing holds in parallel too; the others take the remaining processes.
    ``workers=0``: one process per core (``os.cpu_count()``).

    ``cache`` (:class:`graphnav.scan.icp_cache.MatchCache`) shares weighted-ICP matches between the
    estimators: a match already computed by an earlier estimator (same scans, config and initial
    guess) is reused, so the later ones' ``runtime_s`` excludes it; each summary then carries
    ``icp_cache_hits``, and ``icp_ms_median`` is the matches' computation time (for a shared one,
    its first computation's). With ``workers > 1`` every process has its own copy.

    ``holdout`` (:class:`~graphnav.evaluation.holdout.HoldoutSpec`) withholds GNSS windows from every
    estimator and scores each against the withheld fixes (``summary["holdout"]``). ``meanwhile()``,
    when given, is called once while the worker processes run (with one process, before the
    estimators), e.g. to import what comes next: this process is idle then. Returns a
    :class:`Comparison` (a sequence of the entries, in the order of ``names``).
    """
    t_start = time.perf_counter()
    whole = log
    plan = withhold(log, holdout) if holdout is not None else None
    if plan is not None:
        log = plan.log
    names = list(names) if names is not None else estimators.names()
    options = options or {}
    out: list[Entry] = []
    todo: list[tuple[int, str]] = []
    for name in names:
        label, _, est = name.partition("=") if "=" in name else (name, "", name)
        entry = Entry(label, options=dict(options.get(label, {})))
        out.append(entry)
        if any(e.name == label for e in out[:-1]):
            entry.error = f"label {label!r} given twice"
            continue
        try:
            spec = estimators.get(est)
        except KeyError as exc:
            entry.error = str(exc.args[0])
            continue
        entry.kind, entry.description = spec.kind, spec.description
        if est != label:
            entry.description = f"{spec.description} (estimator {est!r})"
        why = spec.unmet(log)
        if why:
            entry.skipped = why
            continue
        todo.append((len(out) - 1, est))
    if workers <= 0:
        workers = os.cpu_count() or 1
    with icp_cache.active(cache):
        _run_all(out, todo, log, progress, workers, meanwhile)
    if plan is not None:
        for e in out:
            if e.ok and e.summary is not None and e.result is not None:
                e.summary["holdout"] = plan.score(e.result.trajectory, smoothed=e.kind == "smoother")
                e.summary["holdout_rmse_m"] = e.summary["holdout"]["rmse_m"]
                if e.result.online is not None and e.result.online is not e.result.trajectory:
                    e.summary["holdout"].update(plan.score_online(e.result.online))
    hits = sum((e.summary or {}).get("icp_cache_hits", 0) for e in out) if cache is not None else None
    return Comparison(out, log, log_name=log_name or str(whole.meta.get("name", "log")), whole_log=whole,
                      holdout=plan, dropped=list(dropped), checks=data_checks(whole), workers=workers,
                      runtime_s=time.perf_counter() - t_start, icp_cache_hits=hits)


def _run_group(entries: list[Entry], ests: list[str], log: NavLog) -> list[Entry]:
    """Run several estimators one after another (in one worker process: they share its cache)."""
    return [_run(e, est, log) for e, est in zip(entries, ests, strict=True)]


_FORKED: dict[str, NavLog] = {}
"""The log of the comparison running in worker processes: set before they fork, so that each inherits it
(pickling it for every work unit cost the parent ~0.5 s of CPU per unit on a 100 Hz IMU log)."""


def _run_forked(entries: list[Entry], ests: list[str]) -> list[Entry]:
    """:func:`_run_group` in a worker, on the log it inherited (:data:`_FORKED`)."""
    return _run_group(entries, ests, _FORKED["log"])


def groups(todo: Sequence[tuple[int, str]]) -> list[list[tuple[int, str]]]:
    """The parallel work units, heaviest first (by the sum of their estimators' ``cost``, so that a long one
    does not start last): the smoothers that match their scans from the same iSAM2 estimate
    (``shares_matches``: isam2, batch) in one unit (they share their weighted-ICP matches through the cache,
    so they run in one process, in order), every other estimator alone."""
    shared = [(i, est) for i, est in todo
              if estimators.get(est).kind == "smoother" and getattr(estimators.get(est), "shares_matches", False)]
    units = ([shared] if shared else []) + [[(i, est)] for i, est in todo if (i, est) not in shared]
    return sorted(units, key=lambda u: -sum(estimators.get(est).cost for _, est in u))


def _run_all(out: list[Entry], todo: list[tuple[int, str]], log: NavLog,
             progress: Callable[[str], None] | None, workers: int,
             meanwhile: Callable[[], None] | None = None) -> None:
    units = groups(todo)
    if workers > 1 and len(units) > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("fork")  # children inherit the registry and the log as they are here
        _FORKED["log"] = log
        try:
            with ProcessPoolExecutor(max_workers=min(workers, len(units)), mp_context=ctx) as pool:
                futures = [(u, pool.submit(_run_forked, [out[i] for i, _ in u], [est for _, est in u]))
                           for u in units]
                if meanwhile is not None:
                    meanwhile()
                for u, fut in futures:
                    for i, _ in u:
                        if progress:
                            progress(out[i].name)
                    for (i, _), entry in zip(u, fut.result(), strict=True):
                        out[i] = entry
        finally:
            _FORKED.clear()
    else:
        if meanwhile is not None:
            meanwhile()
        for i, est in todo:
            if progress:
                progress(out[i].name)
            _run(out[i], est, log)


def ranked(entries: Sequence[Entry], key: str = "ate_rmse_m") -> list[Entry]:
    """Successful entries by ``key`` (smallest first; missing values last), then the failures, then
    the skipped ones."""
    def k(e: Entry) -> tuple[int, float]:
        v = (e.summary or {}).get(key)
        return (0, float(v)) if isinstance(v, int | float) and v == v else (1, 0.0)

    return (sorted((e for e in entries if e.ok), key=k) + [e for e in entries if e.error is not None]
            + [e for e in entries if e.skipped is not None and e.error is None])
