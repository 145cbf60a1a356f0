"""The scan-matching paper's comparison (issue #16) with KISS-ICP as the reference odometry: every
method of ``graphnav scan-matching`` on the same frames of

* the 3D harbour (``graphnav simulate harbour --lidar 3d --seed S --duration D``), and
* the KITTI pair (``../shared/data/kitti_pair``, when present): its two clouds as a two-frame log with
  the reference transform as truth (planar part; the pair is 0.50 m forward, 0.7 deg of yaw).

    python benchmarks/scan_matching_3d.py [--seed 0] [--duration 120] [--frames 300] [--log LOG]
                                          [--kitti DIR] [--json]

The table in docs/scan-matching-3d.md ("The comparison on the 3D harbour") comes from it. Times are
wall-clock on whatever machine runs it (one thread per method); KISS-ICP runs its Python pipeline
(``kiss_icp.kiss_icp.KissICP``, the ``[bench]`` extra), voxel 1 m, no deskewing, one thread.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from graphnav.evaluation.scan_matching3d import compare
from graphnav.io import load_log
from graphnav.log import NavLog, Truth, make_cloud

REPO = Path(__file__).resolve().parents[1]


def kitti_log(d: Path) -> NavLog:
    """The pair as a log: target at t = 0 (pose 0), source at t = 0.1 at the reference's planar pose."""
    from graphnav.io.cloudfile import read_cloud, read_transform

    T = read_transform(d / "T_target_source.txt")
    yaw = float(np.arctan2(T[1, 0], T[0, 0]))
    recs = [make_cloud(0.0, read_cloud(d / "target.ply")), Truth(0.0, 0.0, 0.0, 0.0),
            make_cloud(0.1, read_cloud(d / "source.ply")), Truth(0.1, float(T[0, 3]), float(T[1, 3]), yaw)]
    return NavLog(recs, meta={"name": "kitti_pair"})


def table(res: dict) -> str:
    rows = ["| method | 1-frame trans. RMSE [m] | 1-frame rot. RMSE [deg] | ms (median) | chained ATE [m] | ms/frame "
            "| CPU ms/frame |", "|---|---|---|---|---|---|---|"]
    for name, m in res["methods"].items():
        if "skipped" in m:
            rows.append(f"| {name} | skipped: {m['skipped']} | | | | | |")
            continue
        rows.append(f"| {name} | {m['single_trans_rmse_m']:.4f} | {m['single_rot_rmse_deg']:.4f} | "
                    f"{m['single_ms_median']:.1f} | {m['continuous_ate_m']:.4f} | {m['continuous_ms_per_frame']:.1f} | "
                    f"{m['continuous_cpu_ms_per_frame']:.1f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--log", type=Path, help="an existing 3D harbour log (else one is simulated)")
    ap.add_argument("--kitti", type=Path, default=REPO.parent / "shared" / "data" / "kitti_pair")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    out: dict = {}
    if a.log is not None:
        log = load_log(a.log)
    else:
        from graphnav.sim.harbour3d import simulate_harbour3d

        log = simulate_harbour3d(a.seed, duration=a.duration)
    out["harbour3d"] = compare(log, a.frames)
    kitti = a.kitti if (a.kitti / "source.ply").exists() else REPO.parent.parent / "shared" / "data" / "kitti_pair"
    if (kitti / "source.ply").exists():
        out["kitti_pair"] = compare(kitti_log(kitti), 2, cloud={"min_range": 3.0, "max_range": 120.0})
    else:
        out["kitti_pair"] = {"skipped": f"no KITTI pair at {a.kitti}"}
    if a.json:
        print(json.dumps(out))
    else:
        for name, res in out.items():
            print(f"## {name}\n")
            print(table(res) if "methods" in res else res["skipped"], end="\n\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
