"""``graphnav beacons search --beacons {1,2,4}``: the exhaustive beacon-layout search of the beacon
paper (sections 6-7), scored by the EKF-SLAM covariance (eq. 28) or the factor graph's marginals."""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..beacons.layout import (
    Choices,
    Fairway,
    chunk_tasks,
    grid,
    layout_cost_s,
    resolve_backend,
    score_chunk,
    summarize_search,
)
from ..evaluation.sweep import run_sweep
from ._common import add_dashboard_flag, add_json_flag, emit, progress_enabled, seed_arg

log = logging.getLogger("graphnav.beacons")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("beacons", help="beacon-layout studies", description=__doc__)
    bsub = p.add_subparsers(dest="beacons_cmd", metavar="CMD", required=True)
    s = bsub.add_parser("search", help="exhaustive layout search (paper's Table 1)")
    s.add_argument("--beacons", type=int, choices=(1, 2, 4), required=True, help="number of beacons")
    s.add_argument("--criterion", choices=("ekf", "smoother"), default="ekf",
                   help="ekf: EKF-SLAM covariance (eq. 28); smoother: GTSAM marginals (slower)")
    s.add_argument("--marginals", choices=("online", "smoothed"), default="online",
                   help="smoother criterion: iSAM2 online marginals or the smoothed ones")
    s.add_argument("--scheduler", default="auto",
                   help="auto (default): in-process when an embedded Dask LocalCluster would cost more to start "
                        "than it saves, else the LocalCluster; 'local': always the LocalCluster; "
                        "'tcp://host:8786': an existing cluster; 'serial': in-process")
    s.add_argument("--backend", choices=("auto", "numba", "numpy"), default="auto",
                   help="EKF criterion: compiled kernel (numba, optional dependency) or numpy; auto: numba "
                        "when importable and --linearize truth")
    s.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default 2)")
    add_dashboard_flag(s)
    s.add_argument("--chunk", type=int, default=None, help="configurations per sweep task")
    s.add_argument("--results", type=Path, default=None,
                   help="JSON-lines file of finished chunks: an interrupted search resumes from it (a chunk "
                        "is reused only if every parameter of it is the same; a file written by other "
                        "code is refused)")
    s.add_argument("--overwrite", action="store_true",
                   help="discard what --results holds and start it afresh")
    s.add_argument("--limit", type=int, default=None, help="score only every k-th layout (quick looks)")
    s.add_argument("--linearize", choices=("truth", "estimate"), default="truth",
                   help="truth (default): G, W, H on the true track and beacons (no noise draw); estimate: run "
                        "the filter on simulated noisy data and linearise at its estimate")
    s.add_argument("--beacon-init", choices=("first-sighting", "zero", "truth"), default="first-sighting",
                   help="a beacon's mean before its first update (matters with --linearize estimate): inverse "
                        "observation (default), eq. 15 literally (0, 0), or the truth")
    s.add_argument("--p0-cross", choices=("zero", "paper"), default="zero",
                   help="initial cross covariances: zero (default, a valid P0) or paper (eq. 14 as printed, "
                        "indefinite)")
    s.add_argument("--p0-beacon", type=float, default=1e6, help="beacon prior variance [m^2] (eq. 14)")
    s.add_argument("--w-second", choices=("rot", "theta"), default="rot",
                   help="second column of W (eq. 22): rot = dg/dROT (default) or theta = dg/dtheta as printed")
    s.add_argument("--seed", type=seed_arg, default=0, help="noise seed for --linearize estimate (default 0)")
    s.add_argument("--no-progress", action="store_true", help="no progress bar (as --quiet)")
    add_json_flag(s)
    s.set_defaults(func=search)


def search(args: argparse.Namespace) -> int:
    from ..config import Range, number

    number("--workers", args.workers, Range(lo=1, hi=256, integer=True))
    number("--chunk", args.chunk, Range(lo=1, hi=10_000_000, integer=True, optional=True))
    number("--limit", args.limit, Range(lo=1, hi=10_000_000, integer=True, optional=True))
    number("--p0-beacon", args.p0_beacon, Range(lo=0.0, hi=1e12, lo_open=True))
    layouts = grid(args.beacons)
    if args.limit:
        layouts = layouts[:: args.limit]
    fw = Fairway()
    ch = Choices(linearize=args.linearize, beacon_init=args.beacon_init, p0_beacon=args.p0_beacon,
                 p0_cross=args.p0_cross, w_second=args.w_second, seed=args.seed)
    t0 = time.perf_counter()
    if args.criterion == "ekf":
        chunk = args.chunk or 512
        backend = resolve_backend(args.backend, ch)
        tasks = chunk_tasks(layouts, chunk, fw, ch, extra={"backend": backend})
        fn = score_chunk
        cost = len(layouts) * layout_cost_s(args.beacons, backend, fw) / len(tasks)
    else:
        from ..beacons.layout_graph import score_chunk_graph

        chunk = args.chunk or 16
        tasks = chunk_tasks(layouts, chunk, fw, ch)  # scores both online and smoothed marginals
        fn = score_chunk_graph
        cost = len(layouts) * 0.08 * args.beacons / len(tasks)  # iSAM2, both marginals: ~0.08 s per 1-beacon layout
    report: dict[str, Any] = {}
    results = run_sweep(fn, tasks, out=args.results, scheduler=args.scheduler, workers=args.workers,
                        progress=progress_enabled(args), desc=f"{args.beacons}-beacon {args.criterion}",
                        task_cost_s=cost, report=report, dashboard=args.dashboard, overwrite=args.overwrite)
    pick = "scores" if args.criterion == "ekf" else f"scores_{args.marginals}"
    scores = np.concatenate([np.asarray(r[pick], dtype=float).reshape(-1, 3) for r in results])
    wall = time.perf_counter() - t0
    s = summarize_search(layouts, scores)
    criterion = args.criterion if args.criterion == "ekf" else f"smoother-{args.marginals}"
    out: dict[str, Any] = {"beacons": s["beacons"], "configs": s["configs"], "criterion": criterion,
                           "best": s["best"], "worst_mean_mxy": s["worst_mean_mxy"],
                           "mean_over_configs_mxy": s["mean_over_configs_mxy"], "wall_s": wall,
                           "configs_per_s": len(layouts) / wall, "scheduler": report["scheduler"]}
    if args.criterion == "ekf":
        out["backend"] = backend
    log.info("%d configurations in %.2f s (%.0f configs/s; %s)", len(layouts), wall, len(layouts) / wall,
             report["scheduler"])
    b = s["best"]
    human = (f"{s['beacons']} beacon(s), {s['configs']} configurations, criterion {out['criterion']}\n"
             f"best layout {b['layout']}: mean M_xy {b['mean_mxy']:.3f} m (M_x {b['mean_mx']:.3f}, "
             f"M_y {b['mean_my']:.3f})\nworst mean M_xy {s['worst_mean_mxy']:.3f} m, "
             f"mean over configurations {s['mean_over_configs_mxy']:.3f} m\n"
             f"wall {wall:.2f} s ({len(layouts) / wall:.0f} configs/s; scheduler {report['scheduler']})")
    emit(args, out, human)
    return 0
