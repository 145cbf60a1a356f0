"""Sweeps on Dask distributed: one picklable function over many task dicts, resumable from disk.

API
---
``run_sweep(fn, tasks, *, out=None, scheduler=None, workers=2, progress=True) -> list``

* ``fn(task: dict) -> result`` must be picklable (a module-level function) and its result
  JSON-serialisable (floats survive JSON exactly, so a resumed sweep equals an uninterrupted one).
* ``tasks``: a list of dicts, each with a unique string ``"key"``; everything else is ``fn``'s.
  Make tasks coarse (e.g. a chunk of configurations each) so scheduling overhead stays small.
* ``out``: a JSON-lines file. Every finished task is appended as ``{"key": ..., "result": ...}``
  and flushed as soon as it completes; tasks whose key is already in the file are not recomputed
  (an interrupted sweep resumes). A torn last line (killed mid-write) is ignored.
* ``scheduler``: ``None`` starts an embedded ``LocalCluster`` of ``workers`` processes (one thread
  each) for the duration of the call; ``"tcp://host:8786"`` uses an existing cluster (its workers
  must be able to import ``fn``'s module); a ``distributed.Client`` is used as is (several sweeps
  on one cluster); ``"serial"`` runs in this process (no Dask).
* ``progress``: a tqdm bar on stderr.

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
              progress: bool = True, desc: str = "sweep") -> list[Any]:
    """Run ``fn`` over ``tasks`` (see the module docstring); results in task order."""
    keys = _check_keys(tasks)
    done = load_done(out)
    pending = [t for t, k in zip(tasks, keys, strict=True) if k not in done]
    if done:
        log.info("resuming: %d of %d tasks already in %s", len(tasks) - len(pending), len(tasks), out)
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
        elif scheduler == "serial":
            for t in pending:
                finish(str(t["key"]), _roundtrip(fn(t)))
        else:
            _run_dask(fn, pending, scheduler, workers, finish)
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
