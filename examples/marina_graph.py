"""Build a factor graph from the logged marina dataset by hand, optimise it, read the covariance.

The weighted-ICP paper's marina data (177 real 2D LiDAR scans, GNSS-RTK reference) has no GNSS
or compass of its own, so this script simulates them from the reference (``--gnss-sigma``,
``--compass-sigma-deg``; ``--no-gnss`` for pure scan-matching odometry anchored on the first
reference pose). The graph uses the ``factors`` package (native GTSAM factors only):

* one weighted-ICP ``BetweenFactorPose2`` per consecutive scan pair (:func:`graphnav.scan.weighted_icp.match_scans`,
  HDL variant, its full 3x3 covariance scaled as the smoother does, docs/smoother.md);
* a robust ``PoseTranslationPrior2D`` per GNSS fix, a ``PoseRotationPrior2D`` per compass reading;

then batch Levenberg-Marquardt, the ATE against the reference and the marginal covariance of the
last pose. (``graphnav run LOG --estimator batch`` does all of this, and more, for any log.)

Usage: ``python examples/marina_graph.py [MARINA_DIR] [--scans N] [--no-gnss] [--seed S] [--json]``
(default directory ``../shared/data/icp_data_marina``; exit code 2 when it is absent).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import gtsam
import numpy as np

import factors as F
from graphnav.evaluation.metrics import ate
from graphnav.geometry import cov_to_world
from graphnav.io.marina import is_marina_dir, read_marina
from graphnav.scan.weighted_icp import IcpConfig, match_scans
from graphnav.trajectory import Trajectory


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("marina", nargs="?", type=Path, default=Path("../shared/data/icp_data_marina"))
    ap.add_argument("--scans", type=int, default=None, help="use only the first N scans (quick runs)")
    ap.add_argument("--no-gnss", action="store_true", help="scan matching only (no GNSS, no compass)")
    ap.add_argument("--gnss-sigma", type=float, default=3.0, help="simulated GNSS 1-sigma per axis [m]")
    ap.add_argument("--compass-sigma-deg", type=float, default=2.0, help="simulated compass 1-sigma [deg]")
    ap.add_argument("--seed", type=int, default=1, help="noise of the simulated GNSS/compass")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = ap.parse_args(argv)
    if not is_marina_dir(args.marina):
        print(f"marina dataset not found at {args.marina} (expected ranges.mat, angles.mat, gps.mat); "
              "pass its directory as the first argument", file=sys.stderr)
        return 2

    # 1. The log: scans stamped k * 1 s; reference ("truth") poses for scans 1..176 (scan 0 has none).
    log = read_marina(args.marina)
    ref = log.truth()
    scans = [s for s in log.of("scan") if s.t >= ref.t[0] - 1e-9]  # start at the first referenced scan
    if args.scans:
        scans = scans[: args.scans]
    truth = {float(t): p for t, p in zip(ref.t, ref.poses, strict=True)}
    X = F.X  # pose keys x0, x1, ...

    graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
    rng = np.random.default_rng(args.seed)

    # 2. Anchor: with GNSS a loose prior (the fixes place the track); without, the reference start.
    x0 = truth[scans[0].t]
    sig0 = [10.0, 10.0, math.radians(30.0)] if not args.no_gnss else [1e-3, 1e-3, 1e-4]
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*x0), gtsam.noiseModel.Diagonal.Sigmas(np.array(sig0))))
    initial.insert(X(0), gtsam.Pose2(*x0))

    # 3. Weighted-ICP between factors; the initial guess is the last increment (constant velocity).
    cfg = IcpConfig(variant="HDL")
    pose, last, failed = gtsam.Pose2(*x0), np.zeros(3), 0
    for k in range(1, len(scans)):
        m = match_scans(scans[k], scans[k - 1], cfg, init=last)  # pose of scan k in scan k-1's frame
        if m.ok:
            last = m.pose
            graph.add(F.icp_between(X(k - 1), X(k), m.pose, m.cov))  # the match's own covariance, unscaled
        else:  # no usable match: a weak constant-velocity factor keeps the chain connected
            failed += 1
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([2.0, 2.0, math.radians(20.0)]))
            graph.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), gtsam.Pose2(*last), noise))
        pose = pose.compose(gtsam.Pose2(*last))
        initial.insert(X(k), pose)  # dead-reckoned initial values

    # 4. Simulated GNSS (Huber-robust) and compass from the reference, one of each per scan.
    if not args.no_gnss:
        sc = math.radians(args.compass_sigma_deg)
        for k, s in enumerate(scans):
            x, y, yaw = truth[s.t]
            gx, gy = np.array([x, y]) + rng.normal(0.0, args.gnss_sigma, 2)
            graph.add(F.gnss_factor(X(k), gx, gy, args.gnss_sigma))
            graph.add(F.compass_factor(X(k), yaw + rng.normal(0.0, sc), sc))

    # 5. Batch Levenberg-Marquardt, then the marginal covariance of the last pose.
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    n = len(scans)
    est = Trajectory([s.t for s in scans],
                     [[result.atPose2(X(k)).x(), result.atPose2(X(k)).y(), result.atPose2(X(k)).theta()]
                      for k in range(n)], name="marina-graph")
    dr = Trajectory([s.t for s in scans], [[initial.atPose2(X(k)).x(), initial.atPose2(X(k)).y(),
                                            initial.atPose2(X(k)).theta()] for k in range(n)])
    cov_body = gtsam.Marginals(graph, result).marginalCovariance(X(n - 1))  # GTSAM: body-frame tangent
    cov = cov_to_world(result.atPose2(X(n - 1)).theta(), cov_body)  # (x, y, yaw) in the world frame
    a, a_dr = ate(est, ref), ate(dr, ref)

    out = {"scans": n, "factors": graph.size(), "icp_failed": failed, "gnss": not args.no_gnss,
           "ate_rmse_m": a["rmse"], "ate_max_m": a["max"], "dead_reckoning_ate_rmse_m": a_dr["rmse"],
           "last_pose": [est.poses[-1, 0], est.poses[-1, 1], math.degrees(est.poses[-1, 2])],
           "last_pose_sigma": [math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1]), math.degrees(math.sqrt(cov[2, 2]))],
           "last_pose_cov": cov.tolist(), "final_error": graph.error(result)}
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"graph: {n} poses, {graph.size()} factors ({n - 1} ICP, {failed} of them constant-velocity "
          f"fallbacks{'' if args.no_gnss else f', {n} GNSS, {n} compass'})")
    print(f"ATE RMSE vs the reference: {a['rmse']:.3f} m (max {a['max']:.3f} m); "
          f"chained ICP alone: {a_dr['rmse']:.3f} m")
    x, y, yaw = out["last_pose"]
    sx, sy, syaw = out["last_pose_sigma"]
    print(f"last pose (t = {scans[-1].t:.0f} s): x = {x:.2f} ± {sx:.2f} m, y = {y:.2f} ± {sy:.2f} m, "
          f"yaw = {yaw:.2f} ± {syaw:.2f} deg (1 sigma)")
    print("its marginal covariance (x [m], y [m], yaw [rad]; world frame):")
    print(np.array2string(cov, precision=5, suppress_small=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
