"""Is the quay rotation drift in the matcher or in the reference? Long-baseline check.

    /tmp/venvtest/bin/python benchmarks/icp_marina_baseline.py [MARINA_DIR] [--variant HDL]

For stretches of 10 scans (12.5 m) the rotation obtained by chaining the 10 consecutive matches
is compared with ONE direct match of the first scan to the last (seeded with the chain), and with
the reference. A per-pair matcher bias accumulates 10x in the chain but not in the direct match;
if both agree and differ from the reference, the reference drifts.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import se2_between, se2_compose  # noqa: E402
from graphnav.io.marina import read_marina  # noqa: E402
from graphnav.scan.icp_pairs import run_pairs  # noqa: E402
from graphnav.scan.weighted_icp import IcpConfig, match_points, scan_points  # noqa: E402

STRETCHES = [(3, 13), (13, 23), (20, 30), (76, 86), (86, 96), (100, 110), (110, 120), (120, 130), (130, 140)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = os.environ.get("GRAPHNAV_MARINA", str(ROOT.parent / "shared" / "data" / "icp_data_marina"))
    ap.add_argument("marina", nargs="?", default=default)
    ap.add_argument("--variant", default="HDL")
    args = ap.parse_args()
    marina = Path(args.marina)
    if not (marina / "ranges.mat").exists():
        marina = ROOT.parent.parent / "shared" / "data" / "icp_data_marina"
    log = read_marina(marina)
    scans = log.of("scan")
    pts = [scan_points(s) for s in scans]
    truth = {r.t: np.array([r.x, r.y, r.yaw]) for r in log.of("truth")}
    cfg = IcpConfig(variant=args.variant)
    pr = run_pairs(log, cfg, init="cv")
    print(f"variant {args.variant}; rotation over 10 scans [deg]\n")
    print("| scans | chained ICP | direct ICP (one match) | reference | chained - reference |")
    print("|---|---|---|---|---|")
    for a, b in STRETCHES:
        chain = np.zeros(3)
        for k in range(a, b):
            chain = se2_compose(chain, pr.results[k].pose)
        res = match_points(pts[b], pts[a], cfg, init=chain)
        ref = se2_between(truth[scans[a].t], truth[scans[b].t])
        flag = "" if res.ok else " (flagged)"
        print(f"| {a}-{b} | {np.degrees(chain[2]):+.2f} | {np.degrees(res.pose[2]):+.2f}{flag} | "
              f"{np.degrees(ref[2]):+.2f} | {np.degrees(chain[2] - ref[2]):+.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
