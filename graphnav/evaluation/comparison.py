"""Run several estimators on one log and score them the same way: one loop.

Pure: no files, no printing. :mod:`graphnav.evaluation.report` turns the result into report.md and figures,
:mod:`graphnav.commands.compare` is the CLI.
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import estimators
from ..log import NavLog
from ..result import RunResult
from ..scan import icp_cache
from .evaluate import summarize


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
            cache: icp_cache.MatchCache | None = None) -> list[Entry]:
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
    """
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
        _run_all(out, todo, log, progress, workers)
    return out


def _run_group(entries: list[Entry], ests: list[str], log: NavLog) -> list[Entry]:
    """Run several estimators one after another (in one worker process: they share its cache)."""
    return [_run(e, est, log) for e, est in zip(entries, ests, strict=True)]


def groups(todo: Sequence[tuple[int, str]]) -> list[list[tuple[int, str]]]:
    """The parallel work units: every smoother in one (they share their weighted-ICP matches through
    the cache, so they run in one process, in order), every other estimator alone; the smoothers first
    (the longest unit on a log with scans)."""
    shared = [(i, est) for i, est in todo if estimators.get(est).kind == "smoother"]
    return ([shared] if shared else []) + [[(i, est)] for i, est in todo if (i, est) not in shared]


def _run_all(out: list[Entry], todo: list[tuple[int, str]], log: NavLog,
             progress: Callable[[str], None] | None, workers: int) -> None:
    units = groups(todo)
    if workers > 1 and len(units) > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("fork")  # children inherit the registry as it is here
        with ProcessPoolExecutor(max_workers=min(workers, len(units)), mp_context=ctx) as pool:
            futures = [(u, pool.submit(_run_group, [out[i] for i, _ in u], [est for _, est in u], log))
                       for u in units]
            for u, fut in futures:
                for i, _ in u:
                    if progress:
                        progress(out[i].name)
                for (i, _), entry in zip(u, fut.result(), strict=True):
                    out[i] = entry
    else:
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
