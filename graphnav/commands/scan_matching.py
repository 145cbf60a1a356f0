"""``graphnav scan-matching LOG --frames N``: the scan-matching paper's comparison on a log's 3D clouds:
per method the single-frame registration error and time and the continuous-frame (chained) ATE and
time against the log's reference, on the same levelled, filtered frames (docs/scan-matching-3d.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import add_json_flag, emit, plain_options


def register(sub: argparse._SubParsersAction) -> None:
    from ..evaluation.scan_matching3d import METHODS

    p = sub.add_parser("scan-matching", help="compare 3D scan-matching methods on a log's clouds (the paper's table)",
                       description=__doc__)
    p.add_argument("log", type=Path, help="a log with cloud and truth records (.npz, .jsonl[.gz], a ROS bag, ...)")
    p.add_argument("--frames", type=int, default=100, help="the first N clouds with a reference pose (default 100)")
    p.add_argument("--methods", default=",".join(METHODS),
                   help=f"comma-separated subset of {','.join(METHODS)} (default: all)")
    p.add_argument("--option", "-O", action="append", metavar="KEY=VALUE",
                   help="CloudMatchConfig field (the filter and GICP settings), e.g. -O voxel=0.4; repeatable")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..evaluation.scan_matching3d import compare
    from ..io import load_log

    if not 2 <= args.frames <= 1_000_000:
        raise ValueError(f"--frames must be in [2, 1000000], got {args.frames}")
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    log = load_log(args.log)
    res = compare(log, args.frames, methods, plain_options(args))
    out = {"log": str(args.log), **res}
    lines = [f"{res['frames']} frames ({res['points_per_frame']:.0f} points each after the filter)",
             f"{'method':<10} {'1-frame m':>10} {'deg':>8} {'ms':>8} | {'ATE m':>8} {'ms/frame':>9} {'CPU ms':>7}"]
    for name, m in res["methods"].items():
        if "skipped" in m:
            lines.append(f"{name:<10} skipped: {m['skipped']}")
            continue
        lines.append(f"{name:<10} {m['single_trans_rmse_m']:10.4f} {m['single_rot_rmse_deg']:8.4f} "
                     f"{m['single_ms_median']:8.1f} | {m['continuous_ate_m']:8.4f} {m['continuous_ms_per_frame']:9.1f} "
                     f"{m['continuous_cpu_ms_per_frame']:7.1f}")
    for name in ("s2m", "s2m-gicp"):
        if f"{name}_vs_kiss" in res:
            r = res[f"{name}_vs_kiss"]
            lines.append(f"{name} / kiss-icp: CPU time x{r['cpu_ratio']:.2f} (wall x{r['time_ratio']:.2f}), "
                         f"ATE x{r['ate_ratio']:.2f}")
    emit(args, out, "\n".join(lines))
    return 0
