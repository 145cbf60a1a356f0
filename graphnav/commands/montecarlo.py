"""graphnav montecarlo solent [--scenario {1,2,3}] [--runs N] [--seed S] [--scheduler ADDR] [--json]

Simulates N Solent missions (seeds S .. S+N-1; scenario 2 unless --scenario says otherwise) and
runs every estimator on each; prints the mean position and heading RMSE per estimator (smoothers:
of the smoothed trajectory, and online_pos_rmse_m of their online estimate) and the position
improvement of fuzzy-ukf over ukf [%]. Estimators of the default list that do not exist in this installation
are listed under "skipped"; an unknown name given with --estimators or -O is an error (exit 2).
"""

from __future__ import annotations

import argparse
import logging
import time

from .. import estimators
from ..estimators.options import check as check_options
from ..evaluation.monte_carlo_trials import PAPER_ESTIMATORS, aggregate, improvement_pct, map_trials, solent_trial
from ._common import (
    add_dashboard_flag,
    add_json_flag,
    emit,
    options_by_estimator,
    parse_options,
    progress_enabled,
    seed_arg,
)

log_ = logging.getLogger("graphnav.montecarlo")


MAX_RUNS = 100_000  # --runs: each run is a task object held in memory


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("montecarlo", help="Monte Carlo estimator comparison on simulated missions",
                       description=__doc__)
    scen = p.add_subparsers(dest="mission", metavar="MISSION", required=True)
    s = scen.add_parser("solent", help="the fuzzy-adaptive-UKF paper's Solent mission", description=__doc__)
    s.add_argument("--scenario", type=int, choices=(1, 2, 3), default=2,
                   help="the paper's scenario: 1 datasheet noise (Table 3), 2 GNSS 20 m and compass 5 deg, "
                        "3 the first then the second from step 300 (default 2)")
    s.add_argument("--runs", type=int, default=50, help="simulated missions (default 50)")
    s.add_argument("--seed", type=seed_arg, default=0, help="first seed: runs use SEED .. SEED+RUNS-1 (default 0)")
    s.add_argument("--scheduler", help="Dask scheduler address, or 'serial' (default: a local cluster)")
    s.add_argument("--workers", type=int, default=2, help="local cluster processes (default 2)")
    add_dashboard_flag(s)
    s.add_argument("--results", help="JSON-lines file of per-run results (makes the sweep resumable; a run is "
                   "reused only if all its parameters are the same; a file written by other code is refused)")
    s.add_argument("--overwrite", action="store_true", help="discard what --results holds and start it afresh")
    s.add_argument("--estimators", help="comma-separated names (default: " + ",".join(PAPER_ESTIMATORS) + ")")
    s.add_argument("--option", "-O", action="append", metavar="ESTIMATOR.KEY=VALUE",
                   help="estimator option, e.g. -O fuzzy-ukf.window=50; repeatable")
    s.add_argument("--sim", action="append", metavar="KEY=VALUE",
                   help="simulator option, e.g. calib_residual=0.0; repeatable")
    add_json_flag(s)
    s.set_defaults(func=run_solent)


def run_solent(args: argparse.Namespace) -> int:
    wanted = args.estimators.split(",") if args.estimators else list(PAPER_ESTIMATORS)
    known = set(estimators.names())
    names = [n for n in wanted if n in known]
    skipped = [n for n in wanted if n not in known]
    if args.estimators and skipped:  # a name the user gave (the default list may name uninstalled ones)
        raise KeyError(f"--estimators {args.estimators}: " + estimators.unknown_name(skipped[0]))
    if not 1 <= args.runs <= MAX_RUNS:
        raise ValueError(f"--runs must be in [1, {MAX_RUNS}], got {args.runs}")
    if not 1 <= args.workers <= 256:
        raise ValueError(f"--workers must be in [1, 256], got {args.workers}")
    opts = options_by_estimator(args)
    for name, given in opts.items():
        if name not in known:
            raise KeyError(f"-O {name}.KEY=VALUE: " + estimators.unknown_name(name))
        check_options(name, given)
    sim_opts = parse_options(args.sim, "--sim")
    tasks = [{"scenario": args.scenario, "seed": args.seed + i, "names": names, "options": opts,
              "sim_options": sim_opts} for i in range(args.runs)]
    log_.info("montecarlo solent scenario %d: %d runs of %s", args.scenario, args.runs, names)
    t0 = time.perf_counter()
    trials = map_trials(solent_trial, tasks, scheduler=args.scheduler, workers=args.workers, out=args.results,
                        dashboard=args.dashboard, overwrite=args.overwrite,
                        progress=progress_enabled(args))
    est = aggregate(trials, names)
    out = {"scenario": args.scenario, "runs": args.runs, "estimators": est,
           "improvement_pct": improvement_pct(est)}
    if skipped:
        out["skipped"] = skipped
    log_.info("montecarlo solent scenario %d: %d runs in %.1f s", args.scenario, args.runs,
              time.perf_counter() - t0)
    if opts:
        out["options"] = opts
    if sim_opts:
        out["sim_options"] = sim_opts
    human = "\n".join(
        [f"Solent scenario {args.scenario}, {args.runs} runs (mean over runs)",
         f"{'estimator':12s} {'pos RMSE [m]':>13s} {'hdg RMSE [deg]':>15s} {'median pos':>11s} {'ok':>4s} "
         f"{'online pos':>11s}"]
        + [f"{n:12s} {d['pos_rmse_m']:13.2f} {d['hdg_rmse_deg']:15.2f} {d['pos_rmse_median_m']:11.2f} "
           f"{d['runs_ok']:4d} " + (f"{d['online_pos_rmse_m']:11.2f}" if "online_pos_rmse_m" in d else f"{'-':>11s}")
           for n, d in est.items()]
        + [f"fuzzy-ukf vs ukf position improvement: {out['improvement_pct']:.1f} %"]
        + ([f"skipped (not installed): {', '.join(skipped)}"] if skipped else []))
    emit(args, out, human)
    return 0
