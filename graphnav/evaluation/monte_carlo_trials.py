"""Monte Carlo comparison of estimators on simulated Solent missions (the fuzzy-UKF paper's section V).

One trial = one simulated mission (scenario, seed) run through every estimator by name with
:func:`graphnav.estimators.run`; trials are independent, so they are mapped over a sweep runner
(:func:`graphnav.evaluation.sweep.run_sweep`, see :func:`map_trials`).
Pure functions; the CLI is :mod:`graphnav.commands.montecarlo`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .. import estimators
from .metrics import ate, heading_error

PAPER_ESTIMATORS = ("ukf", "fuzzy-ukf", "ukf-bias", "ekf", "isam2", "batch")


def solent_trial(scenario: int, seed: int, names: Sequence[str], options: dict[str, dict] | None = None,
                 sim_options: dict[str, Any] | None = None) -> dict[str, dict[str, float]]:
    """Simulate one mission and score each estimator: position RMSE [m] and heading RMSE [deg]
    over every estimate (unaligned, in the log's frame), median step time [ms]; for smoothers with
    an online estimate also its position RMSE (``online_pos_rmse_m``: what was known at each time,
    the filters' situation). An estimator that raises is reported with ``error``."""
    from ..sim.solent import simulate_solent

    log = simulate_solent(scenario=scenario, seed=seed, **(sim_options or {}))
    ref = log.truth()
    out: dict[str, dict[str, Any]] = {}
    for name in names:
        t0 = time.perf_counter()
        try:
            res = estimators.run(name, log, **(options or {}).get(name, {}))
        except Exception as err:  # noqa: BLE001 - a failing estimator is a result, not a crash
            out[name] = {"error": f"{type(err).__name__}: {err}"}
            continue
        out[name] = trial_scores(res, ref, time.perf_counter() - t0)
    return out


def trial_scores(res: Any, ref: Any, runtime_s: float) -> dict[str, float]:
    """One estimator's figures in a trial (:func:`solent_trial`): ``pos_rmse_m``, ``hdg_rmse_deg``,
    ``step_ms_median``, ``runtime_s`` and, with an online estimate, ``online_pos_rmse_m``."""
    out = {
        "pos_rmse_m": ate(res.trajectory, ref)["rmse"],
        "hdg_rmse_deg": heading_error(res.trajectory, ref)["rmse"],
        "step_ms_median": float(np.median(res.step_ms)) if len(res.step_ms) else math.nan,
        "runtime_s": runtime_s,
    }
    if res.online is not None and res.online is not res.trajectory:
        out["online_pos_rmse_m"] = ate(res.online, ref)["rmse"]
    return out


def _task_call(task: dict[str, Any]) -> Any:
    """Adapter for :func:`graphnav.evaluation.sweep.run_sweep`: ``task = {"key", "fn", "kwargs"}``."""
    return task["fn"](**task["kwargs"])


def map_trials(fn: Callable, kwargs_list: list[dict[str, Any]], *, scheduler: str | None = None,
               workers: int = 2, out: str | None = None, progress: bool = False,
               dashboard: str | None = None, overwrite: bool = False) -> list[Any]:
    """Run ``fn(**kw)`` for every ``kw`` on the sweep runner (:func:`graphnav.evaluation.sweep.run_sweep`:
    an embedded Dask ``LocalCluster`` of ``workers`` processes, an existing cluster at
    ``scheduler``, or ``scheduler="serial"``); results in order. ``out`` makes the sweep resumable.
    Without :mod:`graphnav.evaluation.sweep` the trials run serially."""
    try:
        from .sweep import run_sweep
    except ImportError:
        return [fn(**kw) for kw in kwargs_list]
    tasks = [{"key": f"{fn.__name__}:{json.dumps(kw, sort_keys=True)}", "fn": fn, "kwargs": kw}
             for kw in kwargs_list]
    return run_sweep(_task_call, tasks, out=out, scheduler=scheduler, workers=workers, progress=progress,
                     desc="montecarlo", dashboard=dashboard, overwrite=overwrite)


def aggregate(trials: list[dict[str, dict[str, float]]], names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Mean (and median) over trials of each estimator's figures; trials with an error are counted."""
    out: dict[str, dict[str, Any]] = {}
    for name in names:
        ok = [t[name] for t in trials if name in t and "error" not in t[name]]
        errs = [t[name]["error"] for t in trials if name in t and "error" in t[name]]
        pos = np.array([r["pos_rmse_m"] for r in ok])
        hdg = np.array([r["hdg_rmse_deg"] for r in ok])
        d: dict[str, Any] = {
            "pos_rmse_m": float(pos.mean()) if len(pos) else math.nan,
            "hdg_rmse_deg": float(hdg.mean()) if len(hdg) else math.nan,
            "pos_rmse_median_m": float(np.median(pos)) if len(pos) else math.nan,
            "hdg_rmse_median_deg": float(np.median(hdg)) if len(hdg) else math.nan,
            "step_ms_median": float(np.median([r["step_ms_median"] for r in ok])) if ok else math.nan,
            "runs_ok": len(ok),
        }
        online = [r["online_pos_rmse_m"] for r in ok if "online_pos_rmse_m" in r]
        if online and len(online) == len(ok):
            d["online_pos_rmse_m"] = float(np.mean(online))
        if errs:
            d["errors"] = sorted(set(errs))[:3]
        out[name] = d
    return out


def improvement_pct(est: dict[str, dict[str, Any]], base: str = "ukf", new: str = "fuzzy-ukf") -> float:
    """Position-RMSE improvement of ``new`` over ``base`` [%] (positive = ``new`` is better)."""
    if base not in est or new not in est:
        return math.nan
    b, n = est[base]["pos_rmse_m"], est[new]["pos_rmse_m"]
    return 100.0 * (b - n) / b if b and math.isfinite(b) and math.isfinite(n) else math.nan
