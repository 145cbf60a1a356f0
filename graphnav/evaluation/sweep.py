"""Sweeps on Dask distributed: one picklable function over many task dicts, resumable from disk.

API
---
``run_sweep(fn, tasks, *, out=None, scheduler=None, workers=2, progress=True, task_cost_s=None,
report=None) -> list``

* ``fn(task: dict) -> result`` must be picklable (a module-level function) and its result
  JSON-serialisable (floats survive JSON exactly, so a resumed sweep equals an uninterrupted one).
* ``tasks``: a list of dicts, each with a unique string ``"key"``; everything else is ``fn``'s.
  Make tasks coarse (e.g. a chunk of configurations each) so scheduling overhead stays small.
* ``out``: a JSON-lines file. Every finished task is appended as ``{"key": ..., "result": ...}``
  and flushed as soon as it completes; tasks whose key is already in the file are not recomputed
  (an interrupted sweep resumes). A torn last line (killed mid-write) is ignored.
* ``scheduler``: ``None`` or ``"local"`` starts an embedded ``LocalCluster`` of ``workers``
  processes (one thread each) for the duration of the call; ``"tcp://host:8786"`` uses an
  existing cluster (its workers must be able to import ``fn``'s module); a ``distributed.Client``
  is used as is (several sweeps on one cluster); ``"serial"`` runs in this process (no Dask);
  ``"auto"`` runs in this process when starting a cluster costs more than it saves (see
  :func:`resolve_scheduler`; needs ``task_cost_s``, the estimated CPU seconds of one task),
  else the ``LocalCluster``.
* ``progress``: a tqdm bar on stderr.
* ``report``: a dict, filled with ``scheduler`` (what ran: ``"serial"``, ``"local"`` or the
  address), ``tasks`` and ``pending`` (tasks not already on disk).

Returns the results in task order. :func:`load_done` reads a results file.
Monte Carlo runs and parameter studies use the same runner (e.g. :mod:`graphnav.commands.beacons`).
"""

from __future__ import annotations

import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

log = logging.getLogger("graphnav.sweep")

CLUSTER_STARTUP_S = 3.0
"""Wall seconds to start a ``LocalCluster`` of 2 processes and import the task's modules in its
workers (1-3 s measured on an idle 2-core machine, more under load); ``"auto"`` weighs it."""


def resolve_scheduler(scheduler: Any, pending: int, task_cost_s: float | None, workers: int) -> Any:
    """What ``scheduler="auto"`` means for ``pending`` tasks of ``task_cost_s`` CPU seconds each:
    ``"serial"`` when a cluster of ``workers`` processes would save at most its start-up
    (:data:`CLUSTER_STARTUP_S`): total * (1 - 1/w) <= start-up, w = min(workers, pending);
    else ``"local"``. Unknown cost (``None``): ``"local"``. Other values are returned as they are
    (``None`` as ``"local"``)."""
    if scheduler is None:
        return "local"
    if scheduler != "auto":
        return scheduler
    w = min(max(1, workers), pending)
    if w <= 1:
        return "serial"
    if task_cost_s is None:
        return "local"
    saved = pending * task_cost_s * (1.0 - 1.0 / w)
    return "serial" if saved <= CLUSTER_STARTUP_S else "local"


def load_done(out: Path | str | None) -> dict[str, Any]:
    """Finished results in a JSON-lines results file, by key (missing file: empty)."""
    done: dict[str, Any] = {}
    if out is None or not Path(out).exists():
        return done
    with open(out, encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line torn by an interrupted write: that task is simply redone
            if isinstance(rec, dict) and "key" in rec and "result" in rec:
                done[str(rec["key"])] = rec["result"]
    return done


def _check_keys(tasks: Sequence[dict[str, Any]]) -> list[str]:
    keys = []
    for i, t in enumerate(tasks):
        if "key" not in t:
            raise ValueError(f"task {i} has no 'key'")
        keys.append(str(t["key"]))
    if len(set(keys)) != len(keys):
        raise ValueError("task keys must be unique")
    return keys


def run_sweep(fn: Callable[[dict[str, Any]], Any], tasks: Sequence[dict[str, Any]], *,
              out: Path | str | None = None, scheduler: Any = None, workers: int = 2,
              progress: bool = True, desc: str = "sweep", task_cost_s: float | None = None,
              report: dict[str, Any] | None = None) -> list[Any]:
    """Run ``fn`` over ``tasks`` (see the module docstring); results in task order."""
    keys = _check_keys(tasks)
    done = load_done(out)
    pending = [t for t, k in zip(tasks, keys, strict=True) if k not in done]
    if done:
        log.info("resuming: %d of %d tasks already in %s", len(tasks) - len(pending), len(tasks), out)
    chosen = resolve_scheduler(scheduler, len(pending), task_cost_s, workers)
    if scheduler == "auto":
        log.info("scheduler auto: %s (%d tasks, estimated %s s CPU)", chosen, len(pending),
                 "?" if task_cost_s is None else f"{len(pending) * task_cost_s:.1f}")
    if report is not None:
        name = chosen if isinstance(chosen, str) else "client"
        report.update({"scheduler": name, "tasks": len(tasks), "pending": len(pending)})
    sink = None
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        p = Path(out)
        torn = p.exists() and p.stat().st_size > 0 and not p.read_bytes().endswith(b"\n")
        sink = open(out, "a", encoding="utf-8")
        if torn:
            sink.write("\n")  # end a line torn by an interrupted write; load_done skipped it
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), initial=len(tasks) - len(pending), desc=desc, file=sys.stderr,
                   unit="task", leave=False)

    def finish(key: str, result: Any) -> None:
        done[key] = result
        if sink is not None:
            sink.write(json.dumps({"key": key, "result": result}) + "\n")
            sink.flush()
        if bar is not None:
            bar.update(1)

    try:
        if not pending:
            pass
        elif chosen == "serial":
            for t in pending:
                finish(str(t["key"]), _roundtrip(fn(t)))
        else:
            _run_dask(fn, pending, None if chosen == "local" else chosen, workers, finish)
    finally:
        if sink is not None:
            sink.close()
        if bar is not None:
            bar.close()
    return [done[k] for k in keys]


def _roundtrip(result: Any) -> Any:
    """What a result looks like after a trip through the results file (so all paths agree)."""
    return json.loads(json.dumps(result))


def _run_dask(fn: Callable, pending: list[dict[str, Any]], scheduler: Any, workers: int,
              finish: Callable[[str, Any], None]) -> None:
    from distributed import Client, LocalCluster, as_completed

    for name in ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.core",
                 "distributed.http.proxy", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.WARNING)
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.WARNING)
        client = Client(cluster)
    elif isinstance(scheduler, str):
        client = Client(scheduler)
    else:  # an existing distributed.Client: used, not closed
        client = scheduler
    try:
        futures = client.map(fn, pending, pure=False)
        key_of = {f.key: str(t["key"]) for f, t in zip(futures, pending, strict=True)}
        for fut in as_completed(futures):
            finish(key_of[fut.key], _roundtrip(fut.result()))
            fut.release()
    finally:
        if client is not scheduler:
            client.close()
        if cluster is not None:
            cluster.close()
