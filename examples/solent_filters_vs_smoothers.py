"""Fuzzy adaptive UKF vs UKF vs the smoothers on the Solent missions (Liu, Liu & Bucknall 2019).

Produces, for scenarios 1-3:
* ``OUT/solent_rhat_s{1,2,3}.png``: the diagonal of the adapted R_hat of fuzzy-ukf against the
  true R_a (eq. 31: window mean of the true measurement noise v = z - H x_a, eq. 32) and the fixed
  R of Table 2 (the paper's Figs. 9, 13, 17);
* ``OUT/solent_track_s{1,2,3}.png``: truth, GNSS and the estimates of one run;
* a markdown table per scenario of the Monte Carlo means (``--runs``, default 10) on stdout.

Usage: ``python examples/solent_filters_vs_smoothers.py [--runs 50] [--seed 0] [--out DIR] [--quiet]``
(OUT: ``--out``, default ``out/solent``; ``--out docs/img`` refreshes the documentation's figures);
``--quick`` (one run of the first 150 steps of each mission, serially) checks that it all runs.
Progress (tqdm) on stderr unless ``--quiet``.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure  # (no pyplot: the matplotlib backend is left as it is)
from tqdm import tqdm

from graphnav import estimators
from graphnav.evaluation.monte_carlo_trials import (
    PAPER_ESTIMATORS,
    aggregate,
    improvement_pct,
    map_trials,
    solent_trial,
    trial_scores,
)
from graphnav.geometry import wrap_angle
from graphnav.sim.solent import simulate_solent

QUICK_RUNS, QUICK_STEPS = 1, 150


def true_r(log, window: int) -> np.ndarray:
    """Eq. 31-32: windowed mean of the squared true measurement noise, per channel (n, 3)."""
    tr = log.truth()
    g, h = log.columns("gnss"), log.columns("heading")
    v = np.stack([g["x"] - tr.poses[:, 0], g["y"] - tr.poses[:, 1],
                  wrap_angle(h["yaw"] - tr.poses[:, 2])], axis=1)
    c = np.cumsum(np.vstack([np.zeros(3), v * v]), axis=0)
    k = np.arange(1, len(v) + 1)
    lo = np.maximum(k - window, 0)
    return (c[k] - c[lo]) / (k - lo)[:, None]


def plot_r(log, res, path: Path, scenario: int, window: int) -> None:
    ra = true_r(log, window)
    r_hat = res.info["r_hat"][1:]
    r0 = res.info["r0"]
    t = res.trajectory.t[1:]
    fig = Figure(figsize=(8, 8))
    axes = fig.subplots(3, 1, sharex=True)
    labels = ["GNSS x variance [m^2]", "GNSS y variance [m^2]", "compass variance [deg^2]"]
    for j, ax in enumerate(axes):
        s = 1.0 if j < 2 else (180 / math.pi) ** 2
        ax.plot(t, ra[1:, j] * s, "k", lw=1.2, label="true R_a (eq. 31)")
        ax.plot(t, r_hat[:, j] * s, "r", lw=1.0, label="fuzzy-ukf R_hat")
        ax.axhline(r0[j] * s, color="b", lw=1.0, label="fixed R (Table 2)")
        ax.set_ylabel(labels[j])
        ax.set_yscale("log")
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].set_title(f"Solent scenario {scenario}: measurement noise covariance (cf. paper Fig. "
                      f"{ {1: 9, 2: 13, 3: 17}[scenario]})")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_track(log, results: dict, path: Path, scenario: int) -> None:
    tr = log.truth()
    g = log.columns("gnss")
    fig = Figure(figsize=(7, 6))
    ax = fig.add_subplot()
    ax.plot(g["x"], g["y"], ".", color="0.6", ms=2, label="GNSS")
    ax.plot(tr.poses[:, 0], tr.poses[:, 1], "k", lw=1.5, label="truth")
    for name, res in results.items():
        ax.plot(res.trajectory.poses[:, 0], res.trajectory.poses[:, 1], lw=1.0, label=name)
    ax.set_aspect("equal")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_title(f"Solent scenario {scenario}, one run")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=10, help="Monte Carlo runs per scenario (default 10)")
    ap.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--out", type=Path, default=Path("out/solent"),
                    help="directory for the figures (default out/solent; docs/img: the documentation's)")
    ap.add_argument("--scheduler", help="Dask scheduler address, or 'serial' (default: a local cluster)")
    ap.add_argument("--quiet", action="store_true", help="no progress bars")
    ap.add_argument("--quick", action="store_true",
                    help=f"{QUICK_RUNS} runs of the first {QUICK_STEPS} steps of each mission (a smoke run)")
    args = ap.parse_args(argv)
    sim = {}
    if args.quick:
        args.runs = min(args.runs, QUICK_RUNS)
        args.scheduler = args.scheduler or "serial"  # no Dask cluster start-up for one short trial
        sim = {"max_steps": QUICK_STEPS, "switch_step": QUICK_STEPS // 2}  # scenario 3: noise grows halfway
    args.out.mkdir(parents=True, exist_ok=True)
    names = [n for n in PAPER_ESTIMATORS if n in estimators.names()]
    window = 30
    bar = tqdm(total=3 * (len(names) + args.runs), desc="solent", unit="step", disable=args.quiet)
    for sc in (1, 2, 3):
        bar.set_postfix_str(f"scenario {sc}")
        log = simulate_solent(scenario=sc, seed=args.seed, **sim)
        res, first = {}, {}
        for n in names:
            t0 = time.perf_counter()
            res[n] = estimators.run(n, log)
            first[n] = trial_scores(res[n], log.truth(), time.perf_counter() - t0)  # the first seed's trial
            bar.update(1)
        plot_r(log, res["fuzzy-ukf"], args.out / f"solent_rhat_s{sc}.png", sc, window)
        plot_track(log, res, args.out / f"solent_track_s{sc}.png", sc)
        more = [{"scenario": sc, "seed": args.seed + i, "names": names, "sim_options": sim}
                for i in range(1, args.runs)]
        trials = [first] + (map_trials(solent_trial, more, scheduler=args.scheduler, progress=not args.quiet)
                            if more else [])
        bar.update(args.runs)
        est = aggregate(trials, names)
        runs = f"{args.runs} runs, seeds {args.seed}..{args.seed + args.runs - 1}" if args.runs > 1 else \
            f"1 run, seed {args.seed}"
        print(f"\n### Scenario {sc} ({runs})\n")
        print("| estimator | pos RMSE mean [m] | pos RMSE median [m] | hdg RMSE mean [deg] | step [ms] |")
        print("|---|---:|---:|---:|---:|")
        for n, d in est.items():
            print(f"| {n} | {d['pos_rmse_m']:.2f} | {d['pos_rmse_median_m']:.2f} | {d['hdg_rmse_deg']:.2f} "
                  f"| {d['step_ms_median']:.3f} |")
        print(f"\nfuzzy-ukf vs ukf position improvement: {improvement_pct(est):.1f} %")
    bar.close()


if __name__ == "__main__":
    main()
