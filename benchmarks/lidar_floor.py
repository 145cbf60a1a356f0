"""What the LiDAR could give the graph at best: isam2 with its scan factors replaced by the truth.

    python benchmarks/lidar_floor.py LOG [--drop odometry,beacon] [--sigma 0.001] [--json]

Three runs on a log with truth (each the graph's own keyframes, gates and factors; only the scan
matcher's answer is replaced, where it gave one):
* ``real``: the weighted ICP as it is;
* ``honest``: the truth's relative pose plus a draw from the match's own covariance (what a matcher
  exactly as good as it says would give: the information the matches state);
* ``perfect``: the truth's relative pose, every pair (failed ones too), with ``--sigma`` [m] (and a
  tenth of it in rad): a rigid chain; what is left is the other sensors' floor (GNSS averaging).
Prints ATE (smoothed, online), the rigid-aligned ATE and the heading error per run: one table, or
one JSON object with ``--json``. docs/smoother.md ("A slow IMU, and the LiDAR's floor").
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import gtsam
import numpy as np

from graphnav import estimators
from graphnav.evaluation.metrics import ate, heading_error
from graphnav.graph import scan_factors as SF
from graphnav.io import drop as D
from graphnav.io.dispatch import load_log


def _truth_pose(tt: np.ndarray, poses: np.ndarray, t: float) -> gtsam.Pose2:
    """The truth at ``t`` (linear interpolation, yaw unwrapped)."""
    yaw = np.unwrap(poses[:, 2])
    return gtsam.Pose2(float(np.interp(t, tt, poses[:, 0])), float(np.interp(t, tt, poses[:, 1])),
                       float(np.interp(t, tt, yaw)))


def run(log: Any, mode: str, sigma: float, seed: int = 1, **options: Any) -> dict[str, float]:
    truth = log.truth()
    tt, P = np.asarray(truth.t), np.asarray(truth.poses)
    rng = np.random.default_rng(seed)
    orig = SF.default_matcher

    def patched(options: dict[str, Any], sweep_s: float = 0.0):
        m = orig(options, sweep_s)

        def match(cur, prev, init, init_cov=None, in_graph=""):
            ok, p, c = m(cur, prev, init, init_cov, in_graph)
            if mode == "real" or (mode == "honest" and not ok):
                return ok, p, c
            rel = _truth_pose(tt, P, float(prev.t)).between(_truth_pose(tt, P, float(cur.t)))
            if mode == "perfect":
                c = np.diag([sigma**2, sigma**2, (sigma / 10) ** 2])
            z = rel.compose(gtsam.Pose2.Expmap(rng.multivariate_normal(np.zeros(3), c)))
            return True, np.array([z.x(), z.y(), z.theta()]), c

        return match

    SF.default_matcher = patched
    try:
        res = estimators.run("isam2", log, **options)
    finally:
        SF.default_matcher = orig
    out: dict[str, float] = {k: res.info.get(k, 0) for k in ("icp_pairs", "icp_failed", "icp_gated")}
    for name, tj in (("ate_rmse_m", res.trajectory), ("online_ate_rmse_m", res.online)):
        out[name] = float(ate(tj, truth)["rmse"])
    out["ate_aligned_rmse_m"] = float(ate(res.trajectory, truth, align=True)["rmse"])
    out["heading_rmse_deg"] = float(heading_error(res.trajectory, truth)["rmse"])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--drop", default="", help="record kinds left out (as graphnav run --drop)")
    ap.add_argument("--sigma", type=float, default=0.001, help="perfect: the factors' 1-sigma [m]")
    ap.add_argument("-O", dest="options", action="append", default=[], metavar="KEY=VALUE",
                    help="an isam2 option (VALUE as JSON when it parses), repeatable")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    log = load_log(a.log)
    if a.drop:
        log = D.drop_kinds(log, [k for k in a.drop.split(",") if k])
    if log.truth() is None:
        print("the log has no truth", file=sys.stderr)
        return 2
    options: dict[str, Any] = {}
    for kv in a.options:
        k, _, v = kv.partition("=")
        try:
            options[k] = json.loads(v)
        except ValueError:
            options[k] = v
    rows = {mode: run(log, mode, a.sigma, **options) for mode in ("real", "honest", "perfect")}
    if a.json:
        print(json.dumps({"log": a.log, "drop": a.drop, "sigma_m": a.sigma, "runs": rows}))
        return 0
    print(f"| scan factors | ATE | online | aligned | heading [deg] | pairs / failed / gated |   ({a.log}, "
          f"--drop {a.drop or '-'} {' '.join(a.options)})")
    print("|---|---|---|---|---|---|")
    for mode, r in rows.items():
        print(f"| {mode} | {r['ate_rmse_m']:.3f} | {r['online_ate_rmse_m']:.3f} | {r['ate_aligned_rmse_m']:.3f} "
              f"| {r['heading_rmse_deg']:.3f} | {r['icp_pairs']} / {r['icp_failed']} / {r['icp_gated']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
