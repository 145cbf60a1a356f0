"""Weighted ICP on real logs against open3d point-to-plane and the odometry, pair by pair.

    python benchmarks/icp_real.py [LOG ...] [--variant HDL] [--json] [--max-pairs N]

Every consecutive scan pair of each log is matched three ways from the SAME initial guess, the
odometry increment (``graphnav icp LOG --init odometry``, :class:`graphnav.scan.motion_guess.MotionGuess`):
ours (:func:`graphnav.scan.icp_pairs.run_pairs`, default settings), open3d point-to-plane
(:func:`graphnav.scan.registration.align`, ``open3d:point_to_plane``, its default parameters: 2 m
correspondence gate, 2D line normals) and the odometry increment itself. Each increment is scored
against the log's truth (on the CARMEN logs the SLAM-corrected laser poses, themselves accurate to
a few cm only) by ``e = Log(ref^-1 est)``: the translation RMSE ``sqrt(mean(ex^2 + ey^2))`` and the
rotation RMSE over the pairs whose scans both have truth. Ours is scored on every pair, flagged
or not (a flagged match returns the guess along its weak directions). Default logs: the converted
CARMEN logs (``/work/cache/logs/carmen-*.jsonl.gz``, see HELPERS.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import increment, se2_between, wrap_angle  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import odometry_samples  # noqa: E402
from graphnav.scan.icp import IcpConfig, scan_points  # noqa: E402
from graphnav.scan.icp_pairs import reference_increments, run_pairs  # noqa: E402


def default_logs() -> list[Path]:
    for base in (ROOT.parent / "cache" / "logs", ROOT.parent.parent / "cache" / "logs"):
        found = sorted(base.glob("carmen-*.jsonl.gz"))
        if found:
            return found
    return []


def errors(est: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation [m] and |rotation| [deg] of ``Log(ref^-1 est)`` per pair (NaN without truth)."""
    e = np.array([se2_between(r, p) for r, p in zip(ref, est, strict=True)]).reshape(-1, 3)
    return np.hypot(e[:, 0], e[:, 1]), np.degrees(np.abs(np.asarray(wrap_angle(e[:, 2]), float).reshape(-1)))


def rmse(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


def run_log(path: Path, variant: str, max_pairs: int | None) -> dict:
    from graphnav.scan.registration import align

    log = load_log(path)
    if max_pairs is not None:
        scans = log.of("scan")[: max_pairs + 1]
        t_end = scans[-1].t
        log = type(log)([r for r in log.records if r.t <= t_end], log.beacons_known, log.meta)
    cfg = IcpConfig(variant=variant)
    t0 = time.perf_counter()
    pr = run_pairs(log, cfg, init="odometry")
    t_ours = time.perf_counter() - t0
    ref = reference_increments(log, pr.t0, pr.t1)
    odo = odometry_samples(log)
    guess = np.array([increment(odo, a, b)[0] for a, b in zip(pr.t0, pr.t1, strict=True)]).reshape(-1, 3)
    pts = [scan_points(s, cfg) for s in log.of("scan")]
    o3d = np.empty_like(guess)
    t0 = time.perf_counter()
    for k in range(len(guess)):
        src, tgt = pts[k + 1], pts[k]
        if len(src) < 10 or len(tgt) < 10:
            o3d[k] = guess[k]
            continue
        o3d[k] = align(src, tgt, guess[k], "open3d:point_to_plane").pose
    t_o3d = time.perf_counter() - t0
    have = np.all(np.isfinite(ref), axis=1)
    row = {"log": path.name.removesuffix(".jsonl.gz"), "pairs": len(guess), "scored": int(have.sum()),
           "flagged": int((~pr.ok).sum()), "s_ours": t_ours, "s_o3d": t_o3d}
    for name, est in (("ours", pr.poses), ("o3d", o3d), ("odo", guess)):
        et, er = errors(est[have], ref[have])
        row[f"{name}_t"] = rmse(et)
        row[f"{name}_r"] = rmse(er)
        row[f"{name}_t_med"] = float(np.median(et)) if len(et) else float("nan")
    return row


def fmt(rows: list[dict], variant: str) -> str:
    out = [f"| log | pairs (flagged) | {variant} t / rot RMSE (m / deg) | open3d p2plane | odometry | "
           f"{variant} t median (m) | open3d t median |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        win = "**" if r["ours_t"] <= r["o3d_t"] and r["ours_r"] <= r["o3d_r"] else ""
        out.append(f"| {r['log']} | {r['scored']} ({r['flagged']}) | {win}{r['ours_t']:.4f} / {r['ours_r']:.3f}{win} "
                   f"| {r['o3d_t']:.4f} / {r['o3d_r']:.3f} | {r['odo_t']:.4f} / {r['odo_r']:.3f} "
                   f"| {r['ours_t_med']:.4f} | {r['o3d_t_med']:.4f} |")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="*", type=Path)
    ap.add_argument("--variant", default="HDL")
    ap.add_argument("--max-pairs", type=int, default=None, help="first N pairs of each log only")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args()
    logs = args.logs or default_logs()
    if not logs:
        print("no logs given and none found at ../cache/logs/carmen-*.jsonl.gz", file=sys.stderr)
        return 2
    rows = []
    for p in logs:
        rows.append(run_log(p, args.variant, args.max_pairs))
        if not args.json:
            print(f"{rows[-1]['log']}: done ({rows[-1]['s_ours']:.1f} s ours, {rows[-1]['s_o3d']:.1f} s open3d)",
                  file=sys.stderr)
    if args.json:
        print(json.dumps({"variant": args.variant, "rows": rows}))
    else:
        print(fmt(rows, args.variant))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
