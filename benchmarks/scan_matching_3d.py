"""The scan-matching paper's comparison (issue #16) with KISS-ICP as the reference odometry: every
method of ``graphnav scan-matching`` on the same frames of

* the 3D harbour (``graphnav simulate harbour --lidar 3d --seed S --duration D``), and
* the KITTI pair (``../shared/data/kitti_pair``, when present): its two clouds as a two-frame log with
  the reference transform as truth (planar part; the pair is 0.50 m forward, 0.7 deg of yaw).

    python benchmarks/scan_matching_3d.py [--seed 0] [--duration 120] [--frames 300] [--log LOG]
                                          [--kitti DIR] [--json] [--figure PNG [--methods M,...]]

``--figure`` draws the scan-to-map methods against KISS-ICP on the harbour frames (docs/figures/
scan_to_map_vs_kiss.png): the chained tracks' position error per frame and the cumulative CPU
time, all from the same run; ``--methods`` limits the run (default: every one).

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

from graphnav.evaluation.scan_matching3d import METHODS, compare
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


FIGURE_METHODS = {"s2m-gicp": "#d62728", "s2m": "#ff7f0e", "kiss-icp": "#1f77b4", "gicp-graph": "#7f7f7f"}


def figure(res: dict, path: Path) -> None:
    """Position error per frame and cumulative CPU time of the scan-to-map methods and KISS-ICP."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = np.asarray(res["reference"])
    fig, (ax_e, ax_c) = plt.subplots(1, 2, figsize=(12, 4.2), layout="constrained")
    for name, colour in FIGURE_METHODS.items():
        m = res["methods"].get(name)
        if not m or "track" not in m:
            continue
        tr = np.asarray(m["track"])
        lab = f"{name}: ATE {m['continuous_ate_m']:.3f} m, {m['continuous_cpu_ms_per_frame']:.1f} CPU ms/frame"
        ax_e.plot(np.hypot(*(tr[:, :2] - ref[:, :2]).T), color=colour, lw=1.2, label=lab)
        ax_c.plot(np.arange(1, len(tr)), np.cumsum(m["cpu_ms"]) / 1e3, color=colour, lw=1.2, label=name)
    ax_e.set(xlabel="frame", ylabel="position error [m]",
             title=f"3D harbour, {res['frames']} frames ({res['t1'] - res['t0']:.1f} s): chained track's error")
    ax_c.set(xlabel="frame", ylabel="CPU [s]", title="cumulative CPU time (one thread each, same run)")
    for ax in (ax_e, ax_c):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--log", type=Path, help="an existing 3D harbour log (else one is simulated)")
    ap.add_argument("--kitti", type=Path, default=REPO.parent / "shared" / "data" / "kitti_pair")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--figure", type=Path, help="write the scan-to-map vs KISS-ICP figure (PNG) here")
    ap.add_argument("--methods", help="comma-separated methods (default: all)")
    a = ap.parse_args(argv)
    methods = tuple(m for m in (a.methods or "").split(",") if m) or METHODS
    out: dict = {}
    if a.log is not None:
        log = load_log(a.log)
    else:
        from graphnav.sim.harbour3d import simulate_harbour3d

        log = simulate_harbour3d(a.seed, duration=a.duration)
    out["harbour3d"] = compare(log, a.frames, methods, tracks=a.figure is not None)
    if a.figure is not None:
        figure(out["harbour3d"], a.figure)
        for m in out["harbour3d"]["methods"].values():  # the figure's data stay out of the table/JSON
            m.pop("track", None), m.pop("cpu_ms", None)
        out["harbour3d"].pop("reference", None)
    kitti = a.kitti if (a.kitti / "source.ply").exists() else REPO.parent.parent / "shared" / "data" / "kitti_pair"
    if (kitti / "source.ply").exists():
        out["kitti_pair"] = compare(kitti_log(kitti), 2, methods, cloud={"min_range": 3.0, "max_range": 120.0})
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
