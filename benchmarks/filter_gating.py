"""The filters' innovation gate (graphnav/estimators/gating.py) on the project's logs: the figures of
docs/ekf.md, *Gating*.

    python benchmarks/filter_gating.py            # table on stdout
    python benchmarks/filter_gating.py --json     # one JSON object

* ATE RMSE of ``ekf`` on ``data/harbour.npz`` and marina-degraded seeds 1-3 (skipped without the
  marina dataset), the mean position RMSE of ``ekf``, ``ukf``, ``fuzzy-ukf`` over Solent seeds 0-4
  per scenario (``graphnav.evaluation.monte_carlo_trials.solent_trial``);
* a 1 km GNSS jump for 60 s: the turning drive of tests/test_ekf.py (jump 60-120 s) and Solent
  scenarios 1-2 seed 0 (fixes +1 km east from 200 s to 260 s): the maximum position error inside
  and around the jump beside the same log without it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "estimators"))

from graphnav import estimators  # noqa: E402
from graphnav.evaluation.metrics import ate  # noqa: E402
from graphnav.evaluation.monte_carlo_trials import solent_trial  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import Gnss, NavLog  # noqa: E402
from graphnav.sim.solent import simulate_solent  # noqa: E402

FILTERS = ("ekf", "ukf", "fuzzy-ukf")


def max_error(res, log: NavLog, t0: float, t1: float) -> float:
    tr = log.truth()
    idx = np.clip(np.searchsorted(tr.t, res.trajectory.t - 1e-6), 0, len(tr.t) - 1)
    e = np.hypot(*(res.trajectory.poses[:, :2] - tr.poses[idx, :2]).T)
    t = res.trajectory.t - log.t0
    return float(e[(t >= t0) & (t < t1)].max())


def jumped(log: NavLog, t0: float, t1: float, dx: float) -> NavLog:
    return NavLog([dataclasses.replace(r, x=r.x + dx) if isinstance(r, Gnss) and t0 <= r.t - log.t0 < t1 else r
                   for r in log.records], meta=log.meta)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--seeds", type=int, default=5, help="Solent seeds per scenario (default 5)")
    args = ap.parse_args(argv)
    out: dict[str, float] = {}
    h = load_log(ROOT / "data" / "harbour.npz")
    out["harbour ekf ATE"] = ate(estimators.run("ekf", h).trajectory, h.truth())["rmse"]
    from conftest import find_marina

    md = find_marina()
    if md is not None:
        from graphnav.sim.marina_degraded import simulate_marina_degraded

        for seed in (1, 2, 3):
            lg = simulate_marina_degraded(md, seed=seed)
            out[f"marina-degraded s{seed} ekf ATE"] = ate(estimators.run("ekf", lg).trajectory, lg.truth())["rmse"]
    for sc in (1, 2, 3):
        trials = [solent_trial(sc, s, list(FILTERS)) for s in range(args.seeds)]
        for name in FILTERS:
            out[f"solent s{sc} {name} pos RMSE"] = float(np.mean([t[name]["pos_rmse_m"] for t in trials]))
    from test_ekf import drive

    for label, log, (a, b) in [("drive", drive(2, T=200.0), (60.0, 120.0))] + [
            (f"solent s{sc}", simulate_solent(scenario=sc, seed=0), (200.0, 260.0)) for sc in (1, 2)]:
        bad = jumped(log, a, b, 1000.0)
        for name in ("ekf",) if label == "drive" else FILTERS:
            clean, res = estimators.run(name, log), estimators.run(name, bad)
            lo, hi = a - 50.0, b + 140.0
            out[f"{label} 1 km jump {name} max error (clean)"] = max_error(clean, log, lo, hi)
            out[f"{label} 1 km jump {name} max error"] = max_error(res, bad, lo, hi)
    if args.json:
        print(json.dumps({k: round(v, 4) for k, v in out.items()}))
    else:
        for k, v in out.items():
            print(f"{k:52s} {v:10.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
