"""``graphnav live --nmea udp://0.0.0.0:10110 --publish udp://HOST:PORT --out DIR``: online
navigation from NMEA streams, the solution published as NMEA (GGA, HDT, VTG, ROT)."""

from __future__ import annotations

import argparse
import json
import logging

from ..io import load_log
from ..online.live import LiveRunner
from ..online.runner import ONLINE_ESTIMATORS, make_online
from ._common import add_json_flag, emit, jsonable, parse_options
from .replay import parse_origin

log_ = logging.getLogger("graphnav.live")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("live", help="online estimation from NMEA streams", description=__doc__)
    p.add_argument("--nmea", action="append", required=True, metavar="udp://HOST:PORT|tcp://HOST:PORT",
                   help="NMEA 0183 source (UDP: bind; TCP: connect); repeatable")
    p.add_argument("--scans", action="append", metavar="udp://HOST:PORT",
                   help="LiDAR scans, one JSON scan record per datagram (docs/live.md); repeatable")
    p.add_argument("--scans-from", metavar="LOG", help="replay this log's scans on the NMEA stream's clock; "
                   "the run ends with the last scan")
    p.add_argument("--estimator", "-e", default="fixed-lag",
                   help=f"online estimator: {', '.join(sorted(ONLINE_ESTIMATORS))} (default fixed-lag)")
    p.add_argument("--option", "-O", action="append", metavar="KEY=VALUE", help="estimator option")
    p.add_argument("--publish", metavar="udp://HOST:PORT", help="send the solution as NMEA here")
    p.add_argument("--out", metavar="DIR", help="write every estimate to DIR/live.tum (flushed)")
    p.add_argument("--origin", metavar="LAT,LON", help="local frame origin (default: the first fix)")
    p.add_argument("--no-checksum-required", action="store_true",
                   help="accept sentences without a checksum (a wrong checksum is always rejected)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--idle-exit", type=float, metavar="S", help="stop when no input came for S seconds")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    estimator = make_online(args.estimator, **parse_options(args.option))
    scans = load_log(args.scans_from) if args.scans_from else None
    runner = LiveRunner(args.nmea, estimator, publish=args.publish, out_dir=args.out, scans_from=scans,
                        origin=parse_origin(args.origin), require_checksum=not args.no_checksum_required,
                        duration=args.duration, idle_exit=args.idle_exit, scan_sources=args.scans)
    log_.info("listening on %s; publishing to %s", ", ".join(args.nmea), args.publish or "-")
    summary = runner.run()
    if args.out:
        from pathlib import Path

        (Path(args.out) / "summary.json").write_text(json.dumps(jsonable(summary), indent=2))
    emit(args, summary)
    return 0
