"""Every estimator on the real logs (issue #12, item 8): one task per log, one row per (log, estimator).

The logs are converted from the raw data in ``shared/data`` by the readers, as the issue's recipe
says (:data:`CARMEN_RECIPE`): the 9 CARMEN logs (:mod:`graphnav.io.carmen`, then simulated wheel
odometry by :mod:`graphnav.sim.degrade`, ``--odometry-noise 0.05,0.05,0.5 --seed 0``), MRCLAM
Dataset 6 robots 1-5 (:mod:`graphnav.io.mrclam`), the marina log (:mod:`graphnav.io.marina`),
marina-degraded (seed 1) and the harbour scenario (``data/harbour.npz``, ours). With ``logs_dir``
the CARMEN and MRCLAM logs are read pre-converted instead (``carmen-NAME.jsonl.gz``,
``mrclam6-rN.jsonl.gz``). :func:`run_log` is the sweep task (module level, so Dask workers import
it); ``benchmarks/real_data.py`` is the command line and writes ``docs/real-data.md``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

CARMEN_LOGS = ("acapulco", "belgioioso", "edmonton", "freiburg-079", "freiburg-101", "freiburg-campus",
               "infinite-corridor", "orebro", "seattle")
CARMEN_RECIPE = {"v": 0.05, "w": 0.05, "w0_deg": 0.5, "seed": 0}
MRCLAM_DATASET = "MRCLAM_Dataset6"
MRCLAM_ROBOTS = (1, 2, 3, 4, 5)
MARINA_DEGRADED_SEED = 1
DATASETS = ("carmen", "mrclam", "marina", "marina-degraded", "harbour")
COST_S = {"carmen": 60.0, "mrclam": 40.0, "marina": 60.0, "marina-degraded": 60.0, "harbour": 120.0}
"""Rough CPU seconds per log with every estimator (for ``scheduler="auto"``)."""
CARMEN_SCANS = {"acapulco": 861, "belgioioso": 395, "edmonton": 340, "freiburg-079": 4791, "freiburg-101": 292,
                "freiburg-campus": 2008, "infinite-corridor": 1941, "orebro": 237, "seattle": 241}
"""Scans per CARMEN log: only to start the longest logs first (the tasks are run in plan order)."""


def find_data(repo: Path) -> Path | None:
    """``shared/data`` beside the repository, or one level further up (git worktrees)."""
    for c in (repo.parent / "shared" / "data", repo.parent.parent / "shared" / "data"):
        if c.is_dir():
            return c
    return None


def plan(datasets: list[str], *, repo: Path, data_dir: Path | None, logs_dir: Path | None = None,
         carmen: list[str] | None = None, robots: list[int] | None = None,
         estimators: list[str] | None = None,
         icp_cache: bool = True) -> tuple[list[dict[str, Any]], list[dict[str, str]]]:
    """The tasks (one per log) and the skipped datasets, each ``{"dataset", "reason"}``."""
    tasks: list[dict[str, Any]] = []
    skipped: list[dict[str, str]] = []

    def add(key: str, dataset: str, source: dict[str, Any]) -> None:
        tasks.append({"key": key, "dataset": dataset, "source": source, "estimators": estimators,
                      "icp_cache": icp_cache})

    for ds in datasets:
        if ds not in DATASETS:
            raise ValueError(f"unknown dataset {ds!r}; known: {', '.join(DATASETS)}")
        if ds == "harbour":
            add("harbour", ds, {"kind": "file", "path": str(repo / "data" / "harbour.npz")})
            continue
        if ds in ("carmen", "mrclam") and logs_dir is not None:
            names = ([f"carmen-{n}" for n in (carmen or CARMEN_LOGS)] if ds == "carmen"
                     else [f"mrclam6-r{r}" for r in (robots or MRCLAM_ROBOTS)])
            for n in names:
                p = logs_dir / f"{n}.jsonl.gz"
                if p.is_file():
                    add(n, ds, {"kind": "file", "path": str(p)})
                else:
                    skipped.append({"dataset": n, "reason": f"{p} not found"})
            continue
        sub = {"carmen": "carmen", "mrclam": "mrclam", "marina": "icp_data_marina",
               "marina-degraded": "icp_data_marina"}[ds]
        if data_dir is None or not (data_dir / sub).is_dir():
            where = data_dir / sub if data_dir is not None else "shared/data (beside the repository)"
            skipped.append({"dataset": ds, "reason": f"{where} not found"})
            continue
        d = data_dir / sub
        if ds == "carmen":
            for n in carmen or CARMEN_LOGS:
                p = d / f"{n}-corrected.log.gz"
                if p.is_file():
                    add(f"carmen-{n}", ds, {"kind": "carmen", "path": str(p), **CARMEN_RECIPE})
                else:
                    skipped.append({"dataset": f"carmen-{n}", "reason": f"{p} not found"})
        elif ds == "mrclam":
            for r in robots or MRCLAM_ROBOTS:
                add(f"mrclam6-r{r}", ds, {"kind": "mrclam", "path": str(d / MRCLAM_DATASET), "robot": r})
        elif ds == "marina":
            add("marina", ds, {"kind": "marina", "path": str(d)})
        else:
            add("marina-degraded", ds, {"kind": "marina-degraded", "path": str(d), "seed": MARINA_DEGRADED_SEED})
    tasks.sort(key=_cost, reverse=True)  # longest first: the last task to finish is a short one
    return tasks, skipped


def _cost(task: dict[str, Any]) -> float:
    if task["dataset"] == "carmen":
        return COST_S["carmen"] * CARMEN_SCANS.get(task["key"].removeprefix("carmen-"), 861) / 861
    return COST_S[task["dataset"]]


def load_source(src: dict[str, Any]):
    """The :class:`~graphnav.log.NavLog` a task's ``source`` describes (converted here)."""
    kind = src["kind"]
    if kind == "file":
        from ..io import load_log

        return load_log(src["path"])
    if kind == "carmen":
        from ..io.carmen import read_carmen
        from ..sim.degrade import DegradeConfig, OdometryNoise, degrade

        noise = OdometryNoise(src["v"], src["w"], math.radians(src["w0_deg"]))
        return degrade(read_carmen(src["path"]), DegradeConfig(odometry=noise), src["seed"])
    if kind == "mrclam":
        from ..io.mrclam import read_mrclam

        return read_mrclam(src["path"], src["robot"])
    if kind == "marina":
        from ..io.marina import read_marina

        return read_marina(src["path"])
    if kind == "marina-degraded":
        from ..sim.marina_degraded import simulate_marina_degraded

        return simulate_marina_degraded(src["path"], src["seed"])
    raise ValueError(f"unknown source kind {kind!r}")


def _first_line(text: str) -> str:
    """An error on one line: its non-empty lines joined up to the first that ends a sentence (GTSAM's
    messages start with a newline and name the variable on the next line; the explanation after
    that is left out), at most 200 characters."""
    kept: list[str] = []
    for ln in text.strip().splitlines():
        if ln.strip():
            kept.append(ln.strip())
            if ln.strip().endswith(".") or len(kept) == 4:
                break
    return " ".join(kept)[:200]


def _one_line(e: BaseException) -> str:
    return _first_line(f"{type(e).__name__}: {e}")


def _num(x: Any) -> float | None:
    return float(x) if isinstance(x, int | float) and math.isfinite(x) else None


def run_log(task: dict[str, Any]) -> dict[str, Any]:
    """The sweep task: convert one log and run every estimator it can feed (or those of
    ``task["estimators"]`` it can feed) through :func:`graphnav.evaluation.comparison.compare`, with a
    shared weighted-ICP match cache unless ``task["icp_cache"]`` is false (then each estimator's
    runtime includes all its own matches). Returns ``{"log", "dataset", "records", "duration_s",
    "load_s", "rows": [...]}`` (or ``"error"`` when the log cannot be read); a row is
    ``{"estimator", "ate", "ate_aligned", "ate_online", "rpe1", "runtime_s"}`` or
    ``{"estimator", "error", "runtime_s"}`` (the error on one line)."""
    from .. import estimators as est
    from ..scan.icp_cache import MatchCache
    from .comparison import compare

    out: dict[str, Any] = {"log": task["key"], "dataset": task["dataset"], "rows": []}
    t0 = time.perf_counter()
    try:
        log = load_source(task["source"])
    except Exception as e:  # a log that cannot be read is reported once, for all estimators
        out["error"] = _one_line(e)
        return out
    out["load_s"] = time.perf_counter() - t0
    out["records"] = len(log)
    out["duration_s"] = log.t1 - log.t0
    names = est.runnable(log)
    if task.get("estimators"):
        names = [n for n in task["estimators"] if n in names]
    cache = MatchCache() if task.get("icp_cache", True) else None
    for e in compare(log, names, cache=cache):
        if not e.ok or e.summary is None:
            out["rows"].append({"estimator": e.name, "error": _first_line(e.error or "failed"),
                                "runtime_s": _num(e.runtime_s)})
            continue
        s = e.summary
        ate = _num(s.get("ate_rmse_m"))
        out["rows"].append({"estimator": e.name, "ate": ate, "ate_aligned": _num(s.get("ate_aligned_rmse_m")),
                            "ate_online": _num(s.get("online_ate_rmse_m", ate)), "rpe1": _num(s.get("rpe_rmse_m")),
                            "runtime_s": _num(e.runtime_s)})
    return out
