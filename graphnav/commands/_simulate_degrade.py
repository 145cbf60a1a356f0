"""``graphnav simulate degrade LOG --odometry-noise V,W,W0DEG --seed S --out OUT``: simulated sensors
from a log's truth, added to the log (the model: :mod:`graphnav.sim.degrade`, docs/datasets.md).

Wheel odometry: the unicycle arc between consecutive truth poses, then per sample (white noise)
v x (1 + N(0, V)) and w x (1 + N(0, W)) + N(0, W0DEG deg/s), plus an optional constant yaw-rate
bias (--yaw-rate-bias). The records carry the sigmas the simulator used (V|v|, sqrt((W w)^2 + W0^2)).
GNSS and compass come from the truth poses with the given sigmas; outages and jumps are windows
whose start is seconds after the first truth pose, or 'A%..B%' (centred at a time drawn in that
part of the run). --preset marina-degraded reproduces 'graphnav simulate marina-degraded' draw for
draw (GNSS 3 m, a 40 s outage in 15%..45%, a 20 m 10 s jump in 60%..85%, compass 2 deg + 3 deg bias).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

from ._common import add_json_flag, emit


def _floats(text: str, opt: str, n_min: int, n_max: int) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"{opt} {text!r}: expected {n_min}-{n_max} comma-separated numbers") from None
    if not n_min <= len(vals) <= n_max or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{opt} {text!r}: expected {n_min}-{n_max} comma-separated finite numbers")
    return vals


def parse_start(text: str, opt: str) -> float | tuple[float, float]:
    """``"120"`` -> 120.0 s; ``"15%..45%"`` -> (0.15, 0.45)."""
    if "%" in text:
        a, sep, b = text.partition("..")
        try:
            lo, hi = float(a.strip().rstrip("%")) / 100, float(b.strip().rstrip("%")) / 100
        except ValueError:
            raise ValueError(f"{opt}: start {text!r} is not SECONDS or A%..B%") from None
        if not sep or not 0.0 <= lo <= hi <= 1.0:
            raise ValueError(f"{opt}: start {text!r} is not A%..B% with 0 <= A <= B <= 100")
        return lo, hi
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{opt}: start {text!r} is not SECONDS or A%..B%") from None


def parse_window(text: str, opt: str, *, jump: bool):
    from ..sim.degrade import Window

    parts = text.split(",")
    if len(parts) != (3 if jump else 2):
        raise ValueError(f"{opt} {text!r}: expected START,DURATION" + (",METRES" if jump else ""))
    rest = _floats(",".join(parts[1:]), opt, len(parts) - 1, len(parts) - 1)
    if rest[0] <= 0:
        raise ValueError(f"{opt} {text!r}: the duration must be > 0")
    return Window(parse_start(parts[0], opt), rest[0], rest[1] if jump else 0.0)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("degrade", help="add simulated odometry, GNSS and compass (from the log's truth) to a log",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", help="input log with truth (any format graphnav reads: .jsonl[.gz], a CARMEN log, ...)")
    p.add_argument("--preset", choices=("marina-degraded",), help="start from a preset (options below override it)")
    p.add_argument("--odometry-noise", metavar="V,W,W0DEG",
                   help="wheel odometry with per-sample noise: relative 1-sigma V on v, W on w, plus an additive "
                        "1-sigma W0DEG deg/s on w (e.g. 0.05,0.05,0.5)")
    p.add_argument("--yaw-rate-bias", type=float, default=0.0, metavar="DEG_S",
                   help="a constant yaw-rate bias added to the odometry w (deg/s; default 0; not in the sigmas)")
    p.add_argument("--gnss", metavar="SIGMA[,HZ]", help="GNSS fixes, SIGMA m per axis, at most HZ (default: every "
                                                         "truth time)")
    p.add_argument("--compass", metavar="SIGMA_DEG[,BIAS_DEG[,HZ]]", help="compass with a constant bias")
    p.add_argument("--gnss-outage", action="append", metavar="START,DURATION",
                   help="no GNSS for DURATION s from START (s after the first truth, or A%%..B%%); repeatable")
    p.add_argument("--gnss-jump", action="append", metavar="START,DURATION,METRES",
                   help="GNSS off by METRES (direction from the seed) for DURATION s from START; repeatable")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--lenient", action="store_true", help="skip malformed input records (and count them)")
    add_json_flag(p)
    p.set_defaults(func=run)


def config_from_args(args: argparse.Namespace):
    """The :class:`graphnav.sim.degrade.DegradeConfig` the options describe."""
    from ..sim.degrade import PRESETS, DegradeConfig, OdometryNoise

    cfg = PRESETS[args.preset] if args.preset else DegradeConfig()
    if args.odometry_noise:
        v, w, w0 = _floats(args.odometry_noise, "--odometry-noise", 3, 3)
        if min(v, w, w0) < 0:
            raise ValueError("--odometry-noise: the sigmas must be >= 0")
        cfg = replace(cfg, odometry=OdometryNoise(v, w, math.radians(w0), math.radians(args.yaw_rate_bias)))
    elif args.yaw_rate_bias:
        raise ValueError("--yaw-rate-bias needs --odometry-noise")
    if args.gnss:
        g = _floats(args.gnss, "--gnss", 1, 2)
        cfg = replace(cfg, gnss_sigma=g[0], gnss_hz=g[1] if len(g) > 1 else None)
    if args.compass:
        c = _floats(args.compass, "--compass", 1, 3)
        cfg = replace(cfg, compass_sigma=math.radians(c[0]), compass_bias=math.radians(c[1]) if len(c) > 1 else 0.0,
                      compass_hz=c[2] if len(c) > 2 else None)
    if args.gnss_outage:
        cfg = replace(cfg, outages=tuple(parse_window(w, "--gnss-outage", jump=False) for w in args.gnss_outage))
    if args.gnss_jump:
        cfg = replace(cfg, jumps=tuple(parse_window(w, "--gnss-jump", jump=True) for w in args.gnss_jump))
    if (cfg.outages or cfg.jumps) and cfg.gnss_sigma is None:
        raise ValueError("--gnss-outage / --gnss-jump need --gnss")
    if cfg.odometry is None and cfg.gnss_sigma is None and cfg.compass_sigma is None:
        raise ValueError("nothing to simulate: give --odometry-noise, --gnss, --compass or --preset")
    return cfg


def run(args: argparse.Namespace) -> int:
    from ..io import load_log, save_log
    from ..sim.degrade import degrade

    cfg = config_from_args(args)
    base = load_log(args.log, lenient=args.lenient)
    log = degrade(base, cfg, args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_log(log, args.out)
    out = {"scenario": "degrade", "input": str(args.log), "seed": args.seed, "out": str(args.out),
           "records": log.counts(), "t0": log.t0, "t1": log.t1, "simulated": log.meta["simulated"],
           "events": log.meta["events"]}
    for key in ("odometry_arc_residual_m", "odometry_skipped_steps", "replaced", "skipped"):
        if key in log.meta:
            out[key] = log.meta[key]
    emit(args, out)
    return 0
