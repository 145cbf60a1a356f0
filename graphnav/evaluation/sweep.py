"""Sweeps on Dask distributed: one picklable function over many task dicts, resumable from disk.

API
---
``run_sweep(fn, tasks, *, out=None, scheduler=None, workers=2, progress=True, task_cost_s=None,
report=None, dashboard=None) -> list``

* ``fn(task: dict) -> result`` must be picklable (a module-level function) and its result
  JSON-serialisable (floats survive JSON exactly, so a resumed sweep equals an uninterrupted one).
* ``tasks``: a list of dicts, each with a unique string ``"key"``; everything else is ``fn``'s.
  Make tasks coarse (e.g. a chunk of configurations each) so scheduling overhead stays small.
* ``out``: a JSON-lines results file. Its first line is a header naming the code that wrote it,
  ``{"graphnav_results": 2, "code": "VERSION+SOURCEHASH"}`` (:func:`code_version`: the package
  version and a hash of every graphnav/factors source file). Every finished task is appended as
  ``{"key": KEY#HASH, "result": ...}`` and flushed as soon as it completes, ``HASH`` being a hash
  of the task's whole content (every parameter it carries, :func:`task_key`). A task whose
  ``KEY#HASH`` is in the file is not recomputed (an interrupted sweep resumes); a task whose
  parameters changed has another hash and is computed afresh (the file keeps both; results of
  other parameters are never returned). A file written by other code (another version or
  changed sources, or the format before the header) is refused with a :class:`GraphnavError`
  unless ``overwrite``, which starts the file afresh. A torn last line (killed mid-write) is
  ignored.
* ``scheduler``: ``None`` or ``"local"`` starts an embedded ``LocalCluster`` of ``workers``
  processes (one thread each) for the duration of the call; ``"tcp://host:8786"`` uses an
  existing cluster (its workers must be able to import ``fn``'s module); a ``distributed.Client``
  is used as is (several sweeps on one cluster); ``"serial"`` runs in this process (no Dask);
  ``"auto"`` runs in this process when starting a cluster costs more than it saves (see
  :func:`resolve_scheduler`; needs ``task_cost_s``, the estimated CPU seconds of one task),
  else the ``LocalCluster``.
  The embedded ``LocalCluster`` listens on 127.0.0.1 only (scheduler and workers) and has no
  dashboard unless ``dashboard`` gives its address (e.g. ``"127.0.0.1:8787"``; ``:0`` picks a
  free port); the link is then logged and put in ``report["dashboard"]``.
* ``progress``: a tqdm bar on stderr.
* ``report``: a dict, filled with ``scheduler`` (what ran: ``"serial"``, ``"local"`` or the
  address), ``tasks`` and ``pending`` (tasks not already on disk).

Returns the results in task order. :func:`load_done` reads a results file.
Monte Carlo runs and parameter studies use the same runner (e.g. :mod:`graphnav.commands.beacons`).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.util
import json
import logging
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from ..errors import AddressError, GraphnavError, require
from ..io.outputs import write_text_atomic

log = logging.getLogger("graphnav.sweep")

SCHEDULER_TIMEOUT_S = 5.0
"""Seconds to wait for an existing scheduler (``"tcp://host:8786"``) to answer before giving up
with an error naming it (Dask's own default is 30 s)."""

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


RESULTS_FORMAT = 2


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """``graphnav.__version__ + "+" +`` the first 12 hex digits of a SHA-256 over every ``*.py`` of the
    ``graphnav`` and ``factors`` packages (relative path and content, sorted): any change to the
    code that computes a result changes it."""
    import factors

    from .. import __version__

    h = hashlib.sha256()
    for pkg in (Path(__file__).resolve().parents[1], Path(factors.__file__).resolve().parent):
        for f in sorted(pkg.rglob("*.py")):
            h.update(f"{pkg.name}/{f.relative_to(pkg).as_posix()}\0".encode())
            h.update(f.read_bytes())
    return f"{__version__}+{h.hexdigest()[:12]}"


def _canonical(obj: Any) -> Any:
    """JSON fallback for task content: functions by qualified name, numpy values as Python ones."""
    if callable(obj) and hasattr(obj, "__qualname__"):
        return f"{getattr(obj, '__module__', '?')}.{obj.__qualname__}"
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return obj.tolist()
    if isinstance(obj, set | frozenset):
        return sorted(obj, key=repr)
    if isinstance(obj, Path):
        return str(obj)
    return repr(obj)


def task_key(task: dict[str, Any]) -> str:
    """``KEY#HASH``: the task's key and a 16-hex-digit SHA-256 of everything else it carries
    (canonical JSON: sorted keys, floats exact), so two tasks share a results line only if every
    parameter agrees."""
    body = {k: v for k, v in task.items() if k != "key"}
    text = json.dumps(body, sort_keys=True, default=_canonical, separators=(",", ":"))
    return f"{task['key']}#{hashlib.sha256(text.encode()).hexdigest()[:16]}"


def read_header(out: Path | str) -> dict[str, Any] | None:
    """The header of a results file (None if the file is missing, empty or has none)."""
    p = Path(out)
    if not p.exists():
        return None
    _check_file(p)
    with open(p, encoding="utf-8") as f:
        first = f.readline().strip()
    try:
        obj = json.loads(first) if first else None
    except json.JSONDecodeError:
        return None
    return obj if isinstance(obj, dict) and "graphnav_results" in obj else None


def load_done(out: Path | str | None) -> dict[str, Any]:
    """Finished results in a JSON-lines results file, by stored key (``KEY#HASH``; missing file: empty)."""
    done: dict[str, Any] = {}
    if out is None or not Path(out).exists():
        return done
    _check_file(out)
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


def _prepare_results(out: Path, overwrite: bool) -> None:
    """Make ``out`` a results file of this code: created with a header when missing or empty, or
    when ``overwrite``; a file written by other code is an error naming the flag that discards it."""
    code = code_version()
    if out.exists() and out.stat().st_size > 0 and not overwrite:
        head = read_header(out)
        if head is not None and head.get("code") == code and head.get("graphnav_results") == RESULTS_FORMAT:
            return
        other = f"graphnav {head.get('code')}" if head else "an earlier graphnav (no header)"
        raise GraphnavError(f"holds results computed by {other}, not by this code ({code}), so they may differ; "
                            "pass --overwrite to discard them and start afresh, or give another --results file",
                            where=str(out))
    if out.exists() and out.stat().st_size > 0:
        log.warning("%s: --overwrite: discarding its %d results", out, len(load_done(out)))
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out, json.dumps({"graphnav_results": RESULTS_FORMAT, "code": code}) + "\n")


def _check_file(out: Path | str) -> None:
    """A results path must be a file (or not exist yet): a directory is an input error naming it."""
    if Path(out).is_dir():
        raise GraphnavError("is a directory; the results file must be a file name (it is created if "
                            "missing)", where=str(out))


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
              report: dict[str, Any] | None = None, dashboard: str | None = None,
              overwrite: bool = False) -> list[Any]:
    """Run ``fn`` over ``tasks`` (see the module docstring); results in task order."""
    stored = dict(zip(_check_keys(tasks), (task_key(t) for t in tasks), strict=True))  # KEY -> KEY#HASH
    keys = list(stored.values())
    if out is not None:
        _check_file(out)
        _prepare_results(Path(out), overwrite)
    done = load_done(out)
    pending = [t for t, k in zip(tasks, keys, strict=True) if k not in done]
    if done:
        reused = len(tasks) - len(pending)
        log.info("resuming: %d of %d tasks already in %s", reused, len(tasks), out)
        other = len(done) - reused
        if other:
            log.warning("%s also holds %d result(s) computed with other parameters: not used (kept in the file)",
                        out, other)
    chosen = resolve_scheduler(scheduler, len(pending), task_cost_s, workers)
    if scheduler in (None, "auto") and chosen == "local" and importlib.util.find_spec("distributed") is None:
        log.info("Dask is not installed (pip install 'graphnav[dask]'): running the %d tasks in this process",
                 len(pending))
        chosen = "serial"
    if scheduler == "auto":
        log.info("scheduler auto: %s (%d tasks, estimated %s s CPU)", chosen, len(pending),
                 "?" if task_cost_s is None else f"{len(pending) * task_cost_s:.1f}")
    if report is not None:
        name = chosen if isinstance(chosen, str) else "client"
        report.update({"scheduler": name, "tasks": len(tasks), "pending": len(pending)})
    sink = None
    if out is not None:
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

    def finish(user_key: str, result: Any) -> None:
        key = stored[user_key]
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
            _run_dask(fn, pending, None if chosen == "local" else chosen, workers, finish, dashboard=dashboard,
                      report=report)
    except KeyboardInterrupt:
        if sink is not None:
            log.warning("interrupted: %d of %d tasks are in %s; the same command resumes from there",
                        len([k for k in keys if k in done]), len(tasks), out)
        raise
    finally:
        if sink is not None:
            sink.close()
        if bar is not None:
            bar.close()
    return [done[k] for k in keys]


def _roundtrip(result: Any) -> Any:
    """What a result looks like after a trip through the results file (so all paths agree)."""
    return json.loads(json.dumps(result))


@contextlib.contextmanager
def _workers_ignore_sigint() -> Iterator[None]:
    """SIGINT ignored while the LocalCluster spawns its worker processes, which inherit that: Ctrl-C
    reaches the whole process group, and only this process should act on it (stop, close the
    cluster, keep the finished results); otherwise every worker prints a KeyboardInterrupt
    traceback. A Ctrl-C during the 1-3 s start-up itself is therefore ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _run_dask(fn: Callable, pending: list[dict[str, Any]], scheduler: Any, workers: int,
              finish: Callable[[str, Any], None], *, dashboard: str | None = None,
              report: dict[str, Any] | None = None) -> None:
    require("distributed", "a Dask cluster (--scheduler local or an address)")
    from distributed import Client, LocalCluster, as_completed

    for name in ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.core",
                 "distributed.http.proxy", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.WARNING)
    cluster = None
    if scheduler is None:
        if dashboard is not None and importlib.util.find_spec("bokeh") is None:
            log.warning("--dashboard: the Dask dashboard needs bokeh, which is not installed; running without it")
            dashboard = None
        # loopback only; no dashboard unless asked for (the scheduler's HTTP server, health checks
        # only then, on a free loopback port rather than 8787)
        http = {"dashboard_address": "127.0.0.1:0"} if dashboard is None else None
        with _workers_ignore_sigint():
            cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=dashboard, scheduler_kwargs=http,
                                   silence_logs=logging.CRITICAL)
        # (workers' logs: a task's error reaches this process through its future and a dead worker as
        # KilledWorker; what a worker logs at ERROR on its own is the shutdown race -- a heartbeat to the
        # scheduler that a Ctrl-C just closed -- printed with its traceback under load)
        client = Client(cluster)
        if dashboard is not None:
            log.info("Dask dashboard: %s", cluster.dashboard_link)
            if report is not None:
                report["dashboard"] = cluster.dashboard_link
    elif isinstance(scheduler, str):
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (ValueError, TypeError) as exc:
            raise AddressError(scheduler, f"not a Dask scheduler address ({exc}); expected tcp://HOST:PORT, "
                                          "'local', 'auto' or 'serial'") from None
        except OSError as exc:  # unreachable or refused (distributed raises OSError on its timeout)
            raise AddressError(scheduler, f"no Dask scheduler answered within {SCHEDULER_TIMEOUT_S:g} s "
                                          f"({exc})") from None
    else:  # an existing distributed.Client: used, not closed
        client = scheduler
    try:
        futures = client.map(fn, pending, pure=False)
        key_of = {f.key: str(t["key"]) for f, t in zip(futures, pending, strict=True)}
        for fut in as_completed(futures):
            finish(key_of[fut.key], _roundtrip(fut.result()))
            fut.release()
    except KeyboardInterrupt:
        # closing a cluster a Ctrl-C stopped mid-call: distributed's sync() can then fail in its own cancel
        # callback (NameError on an unbound `future`, logged by tornado with a traceback); nothing of ours
        logging.getLogger("tornado.application").setLevel(logging.CRITICAL)
        raise
    finally:
        if client is not scheduler:
            client.close()
        if cluster is not None:
            cluster.close()
