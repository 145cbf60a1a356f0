"""Is the weighted ICP's yaw short on small steps? The match's yaw increments against the log's truth,
per pair and summed over windows of consecutive pairs (issue #25, freiburg-079).

    python benchmarks/icp_yaw_slope.py LOG [--pairs N] [--init truth|odometry|zero]

Per window length W (1, 5, 20, 100 pairs): the regression slope (through the origin) of the summed
match yaw on the summed truth yaw, and the RMS of their difference; and the lag-1 autocorrelation of
the per-pair yaw error. A matcher that is short on small steps shows a slope below 1 at every W; a
per-pose jitter (of the truth or of each scan) shows a slope below 1 at W = 1 only, and a negative
lag-1 autocorrelation (consecutive pairs share the jittered pose).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import increment  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import odometry_samples  # noqa: E402
from graphnav.scan.icp_pairs import reference_increments  # noqa: E402
from graphnav.scan.weighted_icp import IcpConfig, match_points, scan_points  # noqa: E402


def _slope(a: np.ndarray, b: np.ndarray) -> float:
    m = np.isfinite(a) & np.isfinite(b)
    return float(np.sum(a[m] * b[m]) / np.sum(b[m] ** 2))


def study(path: Path, pairs: int, init: str) -> dict:
    log = load_log(path)
    scans = log.of("scan")[:pairs + 1]
    t0 = np.array([s.t for s in scans[:-1]])
    t1 = np.array([s.t for s in scans[1:]])
    ref = reference_increments(log, t0, t1)
    odo = odometry_samples(log)
    cfg = IcpConfig()
    pts = [scan_points(s, cfg) for s in scans]
    est = np.full((len(t0), 3), np.nan)
    for k in range(len(t0)):
        inc = increment(odo, t0[k], t1[k]) if init == "odometry" else None
        guess = {"truth": ref[k], "zero": np.zeros(3)}.get(init, inc[0] if inc else np.zeros(3))
        r = match_points(pts[k + 1], pts[k], cfg, init=guess, init_cov=inc[1] if inc else None)
        if r.ok:
            est[k] = r.pose
    e = est[:, 2] - ref[:, 2]
    d = e[np.isfinite(e)]
    out = {"log": path.name, "pairs": len(t0), "init": init, "ok": int(np.isfinite(est[:, 0]).sum()),
           "lag1_autocorrelation": float(np.corrcoef(d[:-1], d[1:])[0, 1]), "windows": []}
    for w in (1, 5, 20, 100):
        n = (len(e) // w) * w
        es = np.nansum(est[:n, 2].reshape(-1, w), 1)
        rs = ref[:n, 2].reshape(-1, w).sum(1)
        out["windows"].append({"pairs": w, "slope": _slope(es, rs), "rms_deg": float(np.degrees(np.nanstd(es - rs)))})
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", type=Path)
    ap.add_argument("--pairs", type=int, default=1000)
    ap.add_argument("--init", choices=("truth", "odometry", "zero"), default="truth")
    args = ap.parse_args()
    print(json.dumps(study(args.log, args.pairs, args.init)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
