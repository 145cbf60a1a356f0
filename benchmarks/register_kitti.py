"""3D registration on the KITTI pair (issue #16): error against the reference and time per registration
of every method of ``graphnav.scan.register3d`` (small_gicp, open3d, our NDT), same settings for all.

Each method is run once to warm up (imports, numba's load of the compiled NDT kernels), then
``--repeat`` times, interleaved (method A, B, ..., A, B, ...) so that the load of a shared machine
falls on all alike; the table gives the median wall time and the median process CPU time of one
registration, preprocessing of both clouds included (small_gicp and NDT run one thread; open3d's
ICP is OpenMP-parallel, so its CPU time can exceed its wall time on an idle machine).

    python benchmarks/register_kitti.py [DIR] [--repeat N] [--json]

DIR holds source.ply, target.ply, T_target_source.txt (default ../shared/data/kitti_pair).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from graphnav.io.cloudfile import read_cloud, read_transform
from graphnav.scan.register3d import pose_error, register

ROWS = [  # label, method, parameters (beyond the defaults: voxel 0.25 m, max_corr 1 m, knn 10, 1 thread)
    ("icp", "icp", {}),
    ("p2plane", "p2plane", {}),
    ("gicp", "gicp", {}),
    ("vgicp", "vgicp", {}),
    ("ndt (DIRECT7)", "ndt", {}),
    ("ndt (DIRECT1)", "ndt", {"neighbors": 1}),
    ("o3d-icp", "o3d-icp", {}),
    ("o3d-p2plane", "o3d-p2plane", {}),
    ("o3d-gicp", "o3d-gicp", {}),
]


def default_dir() -> Path:
    here = Path(__file__).resolve().parents[1]
    for c in (here.parent / "shared" / "data" / "kitti_pair", here.parent.parent / "shared" / "data" / "kitti_pair"):
        if c.exists():
            return c
    return here.parent / "shared" / "data" / "kitti_pair"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", nargs="?", type=Path, default=default_dir())
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    src, tgt = read_cloud(args.dir / "source.ply"), read_cloud(args.dir / "target.ply")
    ref = read_transform(args.dir / "T_target_source.txt")
    rows = ROWS
    runs: dict[str, list] = {label: [] for label, _, _ in rows}
    for _label, method, prm in rows:  # warm-up
        register(src, tgt, method, **prm)
    for _ in range(args.repeat):
        for label, method, prm in rows:
            r = register(src, tgt, method, **prm)
            runs[label].append((r, r.extra["cpu_ms"]))
    load = os.getloadavg()
    table = {}
    for label, method, prm in rows:
        rs = [r for r, _ in runs[label]]
        r = rs[-1]
        dt, dr = pose_error(r.T, ref)
        table[label] = {
            "method": method, "params": prm, "translation_error_m": dt, "rotation_error_deg": dr,
            "fitness": r.fitness, "rmse_m": r.rmse, "iterations": r.iterations, "runs": len(rs),
            "ms_median": float(np.median([x.ms for x in rs])),
            "cpu_ms_median": float(np.median([c for _, c in runs[label]])),
            "ms_prep_median": float(np.median([x.extra["ms_prep"] for x in rs])),
            "ms_align_median": float(np.median([x.extra["ms_align"] for x in rs])),
            "source_used": r.extra["source_used"],
            "sigma_rot_deg": np.degrees(np.sqrt(np.diag(r.cov)[:3])).tolist(),
            "sigma_trans_m": np.sqrt(np.diag(r.cov)[3:]).tolist(),
        }
    if args.json:
        json.dump({"data": str(args.dir), "points": [len(src), len(tgt)], "load_average": load, "methods": table},
                  sys.stdout, indent=1)
        print()
        return 0
    print(f"KITTI pair {args.dir}: {len(src)} / {len(tgt)} points; {args.repeat} runs per method; "
          f"load average {load[0]:.1f} on {os.cpu_count()} cores\n")
    print("| method | library | translation error [m] | rotation error [deg] | fitness | iterations "
          "| ms (wall, median) | ms CPU | prep / align ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, v in table.items():
        lib = ("open3d" if v["method"].startswith("o3d") else "graphnav (numba)" if v["method"] == "ndt"
               else "small_gicp")
        it = "-" if v["iterations"] is None else v["iterations"]
        print(f"| {label} | {lib} | {v['translation_error_m']:.4f} | {v['rotation_error_deg']:.3f} | "
              f"{v['fitness']:.3f} | {it} | {v['ms_median']:.1f} | {v['cpu_ms_median']:.1f} | "
              f"{v['ms_prep_median']:.1f} / {v['ms_align_median']:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
