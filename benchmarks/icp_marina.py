"""Weighted ICP (K, H, HM, HD, HDL) beside open3d and small_gicp on the marina data.

    /tmp/venvtest/bin/python benchmarks/icp_marina.py [MARINA_DIR] [--init cv|zero] [--no-write]

Every method matches the same consecutive scan pairs with the same initial-guess policy
(``cv``: the method's own last increment; ``zero``: identity) and the same correspondence
gate where the method has one (1 m for the peers). Methods run interleaved pair by pair so that
machine load hits all alike; the time is the wall time of one call, median over the pairs.
Errors are scored on the pairs whose reference is clean (graphnav.scan.icp_pairs.valid_reference_steps,
decided from the reference alone). Prints the table and writes it into docs/benchmarks.md
(between the ``icp_marina`` markers; the rest of the file is left alone).
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import se2_from_matrix  # noqa: E402
from graphnav.io.marina import read_marina  # noqa: E402
from graphnav.scan.icp_pairs import (  # noqa: E402
    PairRun,
    nees,
    reference_increments,
    score_pairs,
    valid_reference_steps,
)
from graphnav.scan.weighted_icp import IcpConfig, line_normals, match_points, scan_points  # noqa: E402

QUAY = (76, 97)  # pairs along the long straight quay (inclusive)
PAPER = {  # Table 1 of the paper (865 scans at 0.2 s): mean, std, max of SOG [m/s] and dCOG [deg]
    "K": (-0.031, 0.08, 0.113, 0.57, -0.524, -3.5),
    "H": (-0.013, 0.05, 0.031, 0.14, -0.319, 0.72),
    "HM": (-0.012, 0.03, 0.031, 0.13, -0.185, -0.48),
    "HD": (-0.007, 0.03, 0.026, 0.11, -0.18, 0.42),
}


def _mat(pose):
    c, s = np.cos(pose[2]), np.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = pose[:2]
    return m


def make_methods():
    import open3d as o3d
    import small_gicp
    reg = o3d.pipelines.registration

    def o3d_cloud(p, normals=False):
        c = o3d.geometry.PointCloud()
        c.points = o3d.utility.Vector3dVector(np.column_stack([p, np.zeros(len(p))]))
        if normals:  # 2D line normals (open3d's own would be (0, 0, 1) for a planar cloud)
            n, _ = line_normals(p, 10)
            c.normals = o3d.utility.Vector3dVector(np.column_stack([n, np.zeros(len(p))]))
        return c

    def o3d_p2p(src, tgt, init):
        r = reg.registration_icp(
            o3d_cloud(src), o3d_cloud(tgt), 1.0, _mat(init), reg.TransformationEstimationPointToPoint()
        )
        return se2_from_matrix(r.transformation), True

    def o3d_p2l(src, tgt, init):
        r = reg.registration_icp(
            o3d_cloud(src),
            o3d_cloud(tgt, normals=True),
            1.0,
            _mat(init),
            reg.TransformationEstimationPointToPlane(),
        )
        return se2_from_matrix(r.transformation), True

    def gicp(src, tgt, init):
        r = small_gicp.align(
            np.column_stack([tgt, np.zeros(len(tgt))]),
            np.column_stack([src, np.zeros(len(src))]),
            _mat(init),
            registration_type="GICP",
            downsampling_resolution=0.05,
            max_correspondence_distance=1.0,
            num_threads=1,
        )
        return se2_from_matrix(r.T_target_source), bool(r.converged)

    methods = {}
    for v in ("K", "H", "HM", "HD", "HDL"):  # the kernels, compiled when numba is importable
        cfg = IcpConfig(variant=v)
        rng = np.random.default_rng(0)
        match_points(rng.normal(0, 5, (50, 2)), rng.normal(0, 5, (50, 2)), cfg)  # compile/load outside the timing

        def ours(src, tgt, init, cfg=cfg):
            res = match_points(src, tgt, cfg, init=init)
            return res, res.ok

        methods[v] = ours
    methods["open3d p2p"] = o3d_p2p
    methods["open3d p2plane"] = o3d_p2l
    methods["small_gicp GICP"] = gicp
    return methods


def run(marina: Path, init: str):
    log = read_marina(marina)
    scans = log.of("scan")
    pts = [scan_points(s) for s in scans]
    methods = make_methods()
    n = len(scans) - 1
    poses = {m: np.zeros((n, 3)) for m in methods}
    oks = {m: np.zeros(n, bool) for m in methods}
    ms = {m: np.zeros(n) for m in methods}
    results = {m: [] for m in methods}
    last = {m: None for m in methods}
    names = list(methods)
    for k in range(n):
        order = names[k % len(names) :] + names[: k % len(names)]  # rotate the order: fair under load
        for m in order:
            guess = last[m] if (init == "cv" and last[m] is not None) else np.zeros(3)
            t0 = time.perf_counter()
            out, ok = methods[m](pts[k + 1], pts[k], guess)
            ms[m][k] = (time.perf_counter() - t0) * 1e3
            pose = out.pose if hasattr(out, "pose") else out
            if hasattr(out, "pose"):
                results[m].append(out)
            poses[m][k] = pose
            oks[m][k] = ok and len(pts[k + 1]) > 0
            if oks[m][k]:
                last[m] = pose
    t0 = np.array([s.t for s in scans[:-1]])
    t1 = np.array([s.t for s in scans[1:]])
    ref = reference_increments(log, t0, t1)
    scored = valid_reference_steps(ref)
    rows = []
    for m in methods:
        if results[m]:
            pr = PairRun(t0, t1, results[m], ms[m], IcpConfig(variant=m.split()[0]), init)
        else:
            from graphnav.scan.weighted_icp import MatchResult

            fake = [MatchResult(p, np.eye(3), bool(o), {}) for p, o in zip(poses[m], oks[m], strict=True)]
            pr = PairRun(t0, t1, fake, ms[m], IcpConfig(), init)
        s, per = score_pairs(pr, ref, scored)
        s["variant"] = m
        q = per["scored"].copy()
        q[: QUAY[0]] = False
        q[QUAY[1] + 1 :] = False
        s["quay_accum_dtheta_err_deg"] = float(np.sum(per["dtheta_err_deg"][q]))
        s["nees_mean"] = float(np.nanmean(nees(pr, ref, scored))) if results[m] else float("nan")
        s["nees_median"] = float(np.nanmedian(nees(pr, ref, scored))) if results[m] else float("nan")
        s["per"] = per
        rows.append(s)
    return rows, scored


def fmt_table(rows, init: str) -> str:
    hdr = (
        "| method | pairs scored | step RMSE (m) | rot RMSE (deg) | quay 76-97 accum. rot err (deg) "
        "| median ms/pair | NEES mean / median |\n|---|---|---|---|---|---|---|\n"
    )
    body = ""
    for s in rows:
        ne = f"{s['nees_mean']:.2f} / {s['nees_median']:.2f}" if np.isfinite(s["nees_mean"]) else "-"
        body += (
            f"| {s['variant']} | {s['pairs_scored']} | {s['step_err_rmse_m']:.4f} | "
            f"{s['dtheta_err_rmse_deg']:.3f} | {s['quay_accum_dtheta_err_deg']:+.2f} | "
            f"{s['ms_per_pair_median']:.2f} | {ne} |\n"
        )
    return f"Initial guess: `{init}`.\n\n" + hdr + body


def fmt_table1(rows) -> str:
    hdr = (
        "| method | mean SOG diff (m/s) | mean dCOG diff (deg) | std SOG | std dCOG | max SOG | max dCOG "
        "| paper mean SOG / dCOG | paper std | paper max |\n|---|---|---|---|---|---|---|---|---|---|\n"
    )
    body = ""
    for s in rows:
        p = PAPER.get(s["variant"])
        pp = (
            f"{p[0]:+.3f} / {p[1]:+.2f} | {p[2]:.3f} / {p[3]:.2f} | {p[4]:+.3f} / {p[5]:+.2f}"
            if p
            else "- | - | -"
        )
        body += (
            f"| {s['variant']} | {s['step_err_mean_m']:+.4f} | {s['dtheta_err_mean_deg']:+.3f} | "
            f"{s['step_err_std_m']:.4f} | {s['dtheta_err_std_deg']:.3f} | "
            f"{s['step_err_max_signed_m']:+.3f} | "
            f"{s['dtheta_err_max_signed_deg']:+.2f} | {pp} |\n"
        )
    return hdr + body


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "marina",
        nargs="?",
        default=os.environ.get("GRAPHNAV_MARINA", str(ROOT.parent / "shared" / "data" / "icp_data_marina")),
    )
    ap.add_argument("--init", choices=("cv", "zero"), nargs="+", default=["cv", "zero"])
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    marina = Path(args.marina)
    if not (marina / "ranges.mat").exists():
        alt = ROOT.parent.parent / "shared" / "data" / "icp_data_marina"
        marina = alt if (alt / "ranges.mat").exists() else marina
    out = [
        "<!-- icp_marina:begin -->",
        "## Weighted ICP on the marina data (benchmarks/icp_marina.py)",
        "",
        "Command: `/tmp/venvtest/bin/python benchmarks/icp_marina.py` "
        f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start; wall time of one call, "
        "methods interleaved pair by pair; ours: the kernels of graphnav.scan._icp_fast, compiled by numba).",
        "",
    ]
    for init in args.init:
        rows, scored = run(marina, init)
        t = fmt_table(rows, init)
        print(t)
        out += [t]
        if init == "cv":
            t1 = fmt_table1(rows)
            print("Table 1 structure (SOG diff = step error / 1 s; dCOG diff = rotation-increment error)\n")
            print(t1)
            out += [
                "Table 1 structure (scored pairs; SOG diff = step error per 1 s; dCOG diff = "
                "rotation-increment "
                "error), beside the paper's Table 1 (865 scans at 0.2 s):",
                "",
                t1,
            ]
    out.append("<!-- icp_marina:end -->")
    if not args.no_write:
        path = ROOT / "docs" / "benchmarks.md"
        text = path.read_text() if path.exists() else "# Benchmarks\n"
        block = "\n".join(out) + "\n"
        if "<!-- icp_marina:begin -->" in text:
            text = re.sub(
                r"<!-- icp_marina:begin -->.*?<!-- icp_marina:end -->\n?", lambda _: block, text, flags=re.S
            )
        else:
            text = text.rstrip("\n") + "\n\n" + block
        path.write_text(text)
        print(f"written to {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
