"""``graphnav simulate SCENARIO ... --out LOG``: write a simulated log.

The scenarios are the simulators of :mod:`graphnav.sim` (numeric cores: a seed in, a
:class:`~graphnav.log.NavLog` out); their command-line glue (arguments, writing, the JSON summary)
is here.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io import save_log
from ..sim import fairway, harbour, marina_degraded, solent
from ._common import emit


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a scenario into a log", description=__doc__)
    scen = p.add_subparsers(dest="scenario", metavar="SCENARIO", required=True)
    for add in (_register_fairway, _register_harbour, _register_marina_degraded, _register_solent):
        add(scen)


def _register_fairway(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fairway", help="the beacon paper's fairway passage: odometry + beacon range/bearing",
                       description=fairway.__doc__)
    p.add_argument("--beacons", required=True, help='beacon positions "x1,y1;x2,y2;..." [m]')
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="output log (.jsonl, .jsonl.gz or .npz)")
    p.set_defaults(func=_fairway)


def _fairway(args: argparse.Namespace) -> int:
    log = fairway.simulate_fairway(fairway.parse_beacons(args.beacons), args.seed)
    save_log(log, args.out)
    return 0


def _register_harbour(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "harbour",
        help="a vessel crossing a small harbour: LiDAR, GNSS, compass, odometry, beacons",
        description=harbour.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=None,
                   help="length of the run [s] (shorter: truncated; longer: the route repeats)")
    p.add_argument("--laps", type=int, default=None, help="times round the route (default 1, or what --duration needs)")
    p.add_argument("--fix-hz", type=float, default=1.0, help="GNSS and compass rate [Hz] (default 1)")
    p.add_argument("--lidar-hz", type=float, default=5.0, help="LiDAR scan rate [Hz] (default 5; 0: no scans)")
    p.add_argument("--t0", type=float, default=0.0, help="time of the first record [s] (e.g. a POSIX time)")
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(func=_harbour)


def _harbour(args: argparse.Namespace) -> int:
    cfg = harbour.HarbourConfig(fix_hz=args.fix_hz, lidar_hz=args.lidar_hz, t0=args.t0)
    log = harbour.simulate_harbour(args.seed, cfg, duration=args.duration, laps=args.laps)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_log(log, args.out)
    emit(
        args,
        {
            "scenario": "harbour",
            "seed": args.seed,
            "out": str(args.out),
            "records": log.counts(),
            "t0": log.t0,
            "t1": log.t1,
        },
    )
    return 0


def _register_marina_degraded(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "marina-degraded",
        help="real marina scans + simulated GNSS (outage, jump) and biased compass",
        description=marina_degraded.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--marina", type=Path, required=True, help="the icp_data_marina directory")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--jump-m", type=float, default=20.0, help="GNSS jump size [m] (0: none, same noise)")
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(func=_marina_degraded)


def _marina_degraded(args: argparse.Namespace) -> int:
    log = marina_degraded.simulate_marina_degraded(args.marina, args.seed, jump_m=args.jump_m)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_log(log, args.out)
    emit(
        args,
        {
            "scenario": "marina-degraded",
            "seed": args.seed,
            "out": str(args.out),
            "records": log.counts(),
            "events": log.meta["events"],
        },
    )
    return 0


def _register_solent(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("solent", help="the fuzzy-adaptive-UKF paper's Solent waypoint mission (3 scenarios)",
                       description=solent.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", type=int, choices=(1, 2, 3), default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--current-speed", type=float, default=solent.SolentConfig.current_speed)
    p.add_argument("--calib-residual", type=float, default=solent.SolentConfig.calib_residual,
                   help="residual IMU bias after calibration, fraction of Table 3's bias (default 0.1)")
    p.add_argument("--no-calibration", action="store_true", help="leave Table 3's IMU biases in the log")
    p.add_argument("--out", type=Path, required=True, help="log file (.jsonl, .jsonl.gz or .npz)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(func=_solent)


def _solent(args: argparse.Namespace) -> int:
    cfg = solent.SolentConfig(scenario=args.scenario, seed=args.seed, current_speed=args.current_speed,
                              calib_residual=args.calib_residual, calibrate=not args.no_calibration)
    log = solent.simulate_solent(cfg)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_log(log, args.out)
    summary = {"out": str(args.out), "scenario": cfg.scenario, "seed": cfg.seed, "records": log.counts(),
               "duration_s": log.t1 - log.t0, "waypoints_reached": log.meta["waypoints_reached"]}
    emit(args, summary)
    return 0
