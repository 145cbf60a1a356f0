"""Weighted ICP (HD by default) against open3d point-to-point, per marina pair, in one process (issue #24).

    python benchmarks/icp_vs_open3d.py [MARINA_DIR] [--variant HD] [--reps 3] [--json]

Both match every consecutive scan pair from their own last increment (the constant-velocity guess;
zero at the start), interleaved pair by pair (alternating which goes first) so machine load hits both
alike; open3d's time includes building its clouds, ours the whole ``match_points`` (covariance,
degeneracy analysis and report included). Prints the median CPU time (``time.process_time``) and wall
time per pair, their ratio, our kernel call's CPU time, the RMSE of both 2D steps against the marina
reference (clean pairs), and the load average. open3d runs on one OpenMP thread (``OMP_NUM_THREADS=1``
unless set: its idle threads spin, and their CPU time would be charged to whichever call runs next).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before anything loads an OpenMP runtime

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import se2_from_matrix  # noqa: E402
from graphnav.io.marina import read_marina  # noqa: E402
from graphnav.scan import _icp_fast  # noqa: E402
from graphnav.scan import weighted_icp as wicp  # noqa: E402
from graphnav.scan.icp_pairs import reference_increments, valid_reference_steps  # noqa: E402


def _mat(pose: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = pose[:2]
    return m


def run(marina: Path, variant: str, reps: int) -> dict:
    import open3d as o3d

    reg = o3d.pipelines.registration

    def cloud(p: np.ndarray):  # noqa: ANN202
        c = o3d.geometry.PointCloud()
        c.points = o3d.utility.Vector3dVector(np.column_stack([p, np.zeros(len(p))]))
        return c

    def theirs(src: np.ndarray, tgt: np.ndarray, g: np.ndarray) -> np.ndarray:
        r = reg.registration_icp(cloud(src), cloud(tgt), 1.0, _mat(g), reg.TransformationEstimationPointToPoint())
        return se2_from_matrix(r.transformation)

    log = read_marina(marina)
    scans = log.of("scan")
    pts = [wicp.scan_points(s) for s in scans]
    cfg = wicp.IcpConfig(variant=variant)
    prm = wicp._params(cfg) if hasattr(_icp_fast, "match") else None  # (None: a checkout before the kernels)
    wicp.match_points(pts[1], pts[0], cfg)  # compile / load the kernels outside the timing
    cpu = {"ours": [], "open3d": [], "kernel": []}
    wall = {"ours": [], "open3d": []}
    poses = {"ours": np.zeros((len(pts) - 1, 3)), "open3d": np.zeros((len(pts) - 1, 3))}
    for _ in range(reps):
        last = {"ours": np.zeros(3), "open3d": np.zeros(3)}
        for k in range(len(pts) - 1):
            if len(pts[k + 1]) < cfg.min_points:
                continue
            for m in ("ours", "open3d") if k % 2 else ("open3d", "ours"):
                c0, w0 = time.process_time(), time.perf_counter()
                if m == "ours":
                    res = wicp.match_points(pts[k + 1], pts[k], cfg, init=last[m])
                    pose = res.pose if res.ok else last[m]
                else:
                    pose = theirs(pts[k + 1], pts[k], last[m])
                cpu[m].append(time.process_time() - c0)
                wall[m].append(time.perf_counter() - w0)
                poses[m][k] = last[m] = pose
            if prm is None:
                continue
            s, t = pts[k + 1].T.copy(), pts[k].T.copy()
            c0 = time.process_time()
            _icp_fast.match(s[0], s[1], wicp._NO_SIGMA, t[0], t[1], wicp._NO_SIGMA, prm,
                            (last["ours"][2], last["ours"][0], last["ours"][1]), wicp._NO_TRI)
            cpu["kernel"].append(time.process_time() - c0)
    t0 = np.array([s.t for s in scans[:-1]])
    t1 = np.array([s.t for s in scans[1:]])
    ref = reference_increments(log, t0, t1)
    ok = valid_reference_steps(ref)
    rmse = {m: float(np.sqrt(np.mean(np.sum((p[ok, :2] - ref[ok, :2]) ** 2, 1)))) for m, p in poses.items()}
    med = {m: 1e3 * float(np.median(v)) if v else float("nan") for m, v in cpu.items()}
    return {"variant": variant, "pairs": int(len(cpu["open3d"]) / reps), "reps": reps,
            "cpu_ms_median": med, "wall_ms_median": {m: 1e3 * float(np.median(v)) for m, v in wall.items()},
            "ratio_cpu": med["ours"] / med["open3d"],
            "ratio_wall": float(np.median(wall["ours"]) / np.median(wall["open3d"])),
            "omp_threads": os.environ.get("OMP_NUM_THREADS"),
            "step_rmse_m": rmse, "scored_pairs": int(ok.sum()), "load_average": os.getloadavg()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    here = [r / "shared" / "data" / "icp_data_marina" for r in (ROOT.parent, ROOT.parent.parent)]
    ap.add_argument("marina", nargs="?", type=Path, default=next((d for d in here if d.is_dir()), here[0]))
    ap.add_argument("--variant", default="HD", choices=wicp.VARIANTS)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = run(args.marina, args.variant, args.reps)
    if args.json:
        print(json.dumps(out))
        return 0
    c, w = out["cpu_ms_median"], out["wall_ms_median"]
    print(f"{out['variant']} vs open3d point-to-point, {out['pairs']} marina pairs x {out['reps']}, "
          f"load {out['load_average'][0]:.1f}")
    print(f"  CPU ms/pair: ours {c['ours']:.3f} (kernel {c['kernel']:.3f}), open3d {c['open3d']:.3f}, "
          f"ratio {out['ratio_cpu']:.2f}")
    print(f"  wall ms/pair: ours {w['ours']:.3f}, open3d {w['open3d']:.3f}, ratio {out['ratio_wall']:.2f}")
    print(f"  2D step error RMSE on {out['scored_pairs']} clean pairs: ours {out['step_rmse_m']['ours']:.4f} m, "
          f"open3d {out['step_rmse_m']['open3d']:.4f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
