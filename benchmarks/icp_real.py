"""Weighted ICP on real logs against open3d point-to-plane and the odometry, pair by pair.

    python benchmarks/icp_real.py [LOG ...] [--variant HDL] [--json] [--max-pairs N]

Every consecutive scan pair of each log is matched from the SAME initial guess, the odometry
increment (``graphnav icp LOG --init odometry``, :class:`graphnav.scan.motion_guess.MotionGuess`):

* ``ours``: :func:`graphnav.scan.icp_pairs.run_pairs` with the default settings, as ``graphnav icp``
  and ``icp-dr`` run it: the guess comes with the odometry's covariance, and a match beyond its
  99.9 % bound, not converged, with too few inliers or degenerate is flagged and returns the guess
  (along its weak directions only, when degenerate);
* ``ours, guess w/o cov``: the same without the guess's covariance (no consistency test with the
  odometry; the matcher's own flags only);
* ``open3d p2plane``: :func:`graphnav.scan.registration.align` (``open3d:point_to_plane``, its
  default parameters: 2 m correspondence gate, 2D line normals, kept in SE(2));
* ``odometry``: the guess itself.

Each increment is scored against the log's truth by ``e = Log(ref^-1 est)``: translation RMSE
``sqrt(mean(ex^2 + ey^2))`` and rotation RMSE over the pairs whose scans both have truth, every
pair (flagged or not). On the CARMEN logs the truth is the SLAM-corrected laser pose, itself off by
cm and tenths of a degree per step (docs/weighted-icp.md), and the odometry is simulated FROM that
truth (``graphnav simulate degrade``): the odometry column does not contain the truth's own error,
the matchers' columns do. Default logs: the converted CARMEN logs (``../cache/logs/carmen-*.jsonl.gz``).
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
from graphnav.scan.icp_pairs import reference_increments, run_pairs  # noqa: E402
from graphnav.scan.weighted_icp import IcpConfig, scan_points  # noqa: E402

METHODS = ("ours", "ours_nocov", "o3d", "odo")
LABELS = {"ours": "ours", "ours_nocov": "ours, guess w/o cov", "o3d": "open3d p2plane", "odo": "odometry"}


def default_logs() -> list[Path]:
    for base in (ROOT.parent / "cache" / "logs", ROOT.parent.parent / "cache" / "logs"):
        found = sorted(base.glob("carmen-*.jsonl.gz"))
        if found:
            return found
    return []


def errors(est: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation [m] and |rotation| [deg] of ``Log(ref^-1 est)`` per pair."""
    e = np.array([se2_between(r, p) for r, p in zip(ref, est, strict=True)]).reshape(-1, 3)
    return np.hypot(e[:, 0], e[:, 1]), np.degrees(np.abs(np.asarray(wrap_angle(e[:, 2]), float).reshape(-1)))


def rmse(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


def truncated(log, max_pairs: int | None):  # noqa: ANN001, ANN201
    if max_pairs is None:
        return log
    t_end = log.of("scan")[: max_pairs + 1][-1].t
    return type(log)([r for r in log.records if r.t <= t_end], log.beacons_known, log.meta)


def run_log(path: Path, variant: str, max_pairs: int | None) -> dict:
    from graphnav.scan.registration import align

    log = truncated(load_log(path), max_pairs)
    cfg = IcpConfig(variant=variant)
    est, ms, flagged = {}, {}, {}
    for name, with_cov in (("ours", True), ("ours_nocov", False)):
        t0 = time.perf_counter()
        pr = run_pairs(log, cfg, init="odometry", guess_cov=with_cov)
        ms[name] = (time.perf_counter() - t0) * 1e3 / max(len(pr.results), 1)
        est[name], flagged[name] = pr.poses, int((~pr.ok).sum())
    ref = reference_increments(log, pr.t0, pr.t1)
    odo = odometry_samples(log)
    guess = np.array([increment(odo, a, b)[0] for a, b in zip(pr.t0, pr.t1, strict=True)]).reshape(-1, 3)
    pts = [scan_points(s, cfg) for s in log.of("scan")]
    o3d = guess.copy()
    t0 = time.perf_counter()
    for k in range(len(guess)):
        if len(pts[k + 1]) >= 10 and len(pts[k]) >= 10:
            o3d[k] = align(pts[k + 1], pts[k], guess[k], "open3d:point_to_plane").pose
    ms["o3d"] = (time.perf_counter() - t0) * 1e3 / max(len(guess), 1)
    est["o3d"], est["odo"] = o3d, guess
    have = np.all(np.isfinite(ref), axis=1)
    row = {"log": path.name.removesuffix(".jsonl.gz"), "pairs": len(guess), "scored": int(have.sum()),
           "flagged": flagged["ours"], "flagged_nocov": flagged["ours_nocov"],
           "ms_per_pair": {k: round(v, 2) for k, v in ms.items()}}
    for name in METHODS:
        et, er = errors(est[name][have], ref[have])
        row[f"{name}_t"], row[f"{name}_r"] = rmse(et), rmse(er)
    return row


def fmt(rows: list[dict], variant: str) -> str:
    head = " | ".join(f"{LABELS[m]} t (m) / rot (deg)" for m in METHODS)
    out = [f"| log | pairs (flagged; w/o cov) | {head} |", "|---" * (2 + len(METHODS)) + "|"]
    for r in rows:
        cells = []
        for m in METHODS:
            c = f"{r[f'{m}_t']:.4f} / {r[f'{m}_r']:.3f}"
            if m.startswith("ours") and r[f"{m}_t"] <= r["o3d_t"] and r[f"{m}_r"] <= r["o3d_r"]:
                c = f"**{c}**"
            cells.append(c)
        out.append(f"| {r['log']} | {r['scored']} ({r['flagged']}; {r['flagged_nocov']}) | " + " | ".join(cells) + " |")
    note = f"(variant {variant}; bold: translation and rotation RMSE both <= open3d point-to-plane's)"
    return "\n".join(out) + "\n\n" + note


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
        print(f"{rows[-1]['log']}: done", file=sys.stderr)
    if args.json:
        print(json.dumps({"variant": args.variant, "rows": rows}))
    else:
        print(fmt(rows, args.variant))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
