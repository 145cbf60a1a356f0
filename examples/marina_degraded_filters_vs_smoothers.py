"""Filters versus smoothers on ``marina-degraded``: real marina scans, degraded simulated GNSS/compass.

``marina-degraded`` (docs/datasets.md) adds to the 177 real marina LiDAR scans a simulated 1 Hz
GNSS (3 m, one 40 s outage, one 10 s jump of 20 m) and a compass (2 deg, constant 3 deg bias).
Every estimator the log can feed runs on the same log (:func:`graphnav.evaluation.comparison.compare`, the
library behind ``graphnav compare``), sharing the weighted-ICP matches (:mod:`graphnav.scan.icp_cache`),
and the table ranks them by ATE against the reference. The last lines check the issue's targets:
the iSAM2 smoother at most 0.7x the best filter's ATE and at most half of scan-to-map's.

Usage: ``python examples/marina_degraded_filters_vs_smoothers.py [MARINA_DIR] [--seed 1]
[--estimators isam2,ekf,...] [--seconds S] [--out DIR]`` (default directory
``../shared/data/icp_data_marina``; exit code 2 when it is absent). ``--out`` also writes the full
report (report.md, PNGs, TUM files) as ``graphnav compare`` does.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from graphnav.evaluation.comparison import compare, ranked
from graphnav.evaluation.report import markdown_table, write_report
from graphnav.io.marina import is_marina_dir
from graphnav.scan.icp_cache import MatchCache
from graphnav.sim.marina_degraded import simulate_marina_degraded

FILTERS = ("ekf", "ukf", "fuzzy-ukf")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("marina", nargs="?", type=Path, default=Path("../shared/data/icp_data_marina"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--estimators", "-e", default=None,
                    help="comma-separated names (default: every estimator the log can feed)")
    ap.add_argument("--seconds", type=float, default=None, help="only the first S seconds of the log")
    ap.add_argument("--out", type=Path, default=None, help="also write report.md, PNGs and TUM files here")
    args = ap.parse_args(argv)
    if not is_marina_dir(args.marina):
        print(f"marina dataset not found at {args.marina}; pass its directory as the first argument",
              file=sys.stderr)
        return 2

    log = simulate_marina_degraded(args.marina, seed=args.seed)
    if args.seconds is not None:
        log = log.sliced(None, log.t0 + args.seconds)
    names = [n.strip() for n in args.estimators.split(",")] if args.estimators else None
    t0 = time.perf_counter()
    cache = MatchCache()  # isam2, batch, fixed-lag, the ICP-driven EKF and icp-dr match the same scan pairs
    entries = compare(log, names, cache=cache,
                      progress=lambda n: print(f"running {n} ...", file=sys.stderr))
    wall = time.perf_counter() - t0

    print(f"marina-degraded, seed {args.seed}: {log.counts()}; {wall:.1f} s for all estimators, "
          f"{cache.hits} weighted-ICP matches shared\n")
    print(markdown_table(entries))
    for e in entries:
        if not e.ok:
            print(f"\n{e.name}: " + (e.error if e.error is not None else f"not run: {e.skipped}"))

    # the targets: smoothers first
    ate = {e.name: e.summary["ate_rmse_m"] for e in ranked(entries) if e.ok}
    filters = {n: a for n, a in ate.items() if n in FILTERS}
    if "isam2" in ate:
        print()
        if filters:
            best = min(filters, key=filters.get)
            ok = ate["isam2"] <= 0.7 * filters[best]
            print(f"isam2 {ate['isam2']:.3f} m vs 0.7 x best filter ({best} {filters[best]:.3f} m) = "
                  f"{0.7 * filters[best]:.3f} m: {'met' if ok else 'NOT met'}")
        if "scan-to-map" in ate:
            ok = ate["isam2"] <= 0.5 * ate["scan-to-map"]
            print(f"isam2 {ate['isam2']:.3f} m vs 0.5 x scan-to-map ({ate['scan-to-map']:.3f} m) = "
                  f"{0.5 * ate['scan-to-map']:.3f} m: {'met' if ok else 'NOT met'}")
    if args.out is not None:
        files = write_report(entries, log, args.out, log_name=f"marina-degraded seed {args.seed}")
        print(f"\nwrote {len(files)} files to {args.out} (report.md, report.html)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
