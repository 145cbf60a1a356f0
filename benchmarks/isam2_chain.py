"""GTSAM alone: what one ``ISAM2.update`` costs on a plain Pose2 chain as the chain grows -- the
floor under graphnav's runtime exponent (issue #24).

Each update adds one pose, its odometry factor and, every ``--fix-every`` poses, a position prior
(a GNSS fix); nothing of graphnav runs. Prints the GTSAM version and the median wall ms of an update
over each fifth of the chain (one process, nothing else timed); ``--json`` one object.

    python benchmarks/isam2_chain.py --poses 20000            # the installed GTSAM
    python benchmarks/isam2_chain.py --poses 20000 --no-relinearize

GTSAM 4.3.0 walks the whole Bayes tree after every update to count its non-zeros
(``ISAM2Result::treeNnz``, computed unconditionally), so an update's cost grows with the number of
cliques; borglab/gtsam pull request #2800 (merged 2026-09-12) makes that count opt-in. docs/performance.md,
"Session 8: where the runtime exponent comes from".
"""

from __future__ import annotations

import argparse
import json
import time

import gtsam
import numpy as np


def chain(poses: int, *, fix_every: int = 10, relinearize: bool = True) -> np.ndarray:
    """Wall ms of each ``ISAM2.update`` of a Pose2 chain of ``poses`` poses (the first update excluded)."""
    params = gtsam.ISAM2Params()
    if not relinearize:
        params.relinearizeSkip = 2**30
    isam = gtsam.ISAM2(params)
    odo = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.1, 0.1, 0.01]))
    fix = gtsam.noiseModel.Diagonal.Sigmas(np.array([3.0, 3.0, 0.5]))
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), odo))
    v.insert(0, gtsam.Pose2())
    isam.update(g, v)
    ms = np.empty(poses - 1)
    for k in range(1, poses):
        g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
        g.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(1.0, 0.0, 0.01), odo))
        if k % fix_every == 0:
            g.add(gtsam.PriorFactorPose2(k, gtsam.Pose2(float(k), 0.0, 0.0), fix))
        v.insert(k, gtsam.Pose2(float(k), 0.0, 0.0))
        c = time.perf_counter()
        isam.update(g, v)
        ms[k - 1] = (time.perf_counter() - c) * 1e3
    return ms


def fifths(ms: np.ndarray) -> list[float]:
    """The median of each fifth of ``ms``."""
    return [float(np.median(part)) for part in np.array_split(ms, 5)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, default=20000)
    ap.add_argument("--fix-every", type=int, default=10)
    ap.add_argument("--no-relinearize", action="store_true")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.poses < 10 or args.fix_every < 1:
        ap.error("--poses must be >= 10 and --fix-every >= 1")
    med = fifths(chain(args.poses, fix_every=args.fix_every, relinearize=not args.no_relinearize))
    out = {"gtsam": getattr(gtsam, "__version__", None) or _version(), "poses": args.poses,
           "relinearize": not args.no_relinearize, "update_ms_median_by_fifth": med,
           "growth": med[-1] / med[0] if med[0] > 0 else None}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"GTSAM {out['gtsam']}, {args.poses} poses: ISAM2.update median ms by fifth "
              + " ".join(f"{m:.3f}" for m in med) + f"  (last / first {out['growth']:.1f}x)")
    return 0


def _version() -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gtsam")
    except PackageNotFoundError:
        return None


if __name__ == "__main__":
    raise SystemExit(main())
