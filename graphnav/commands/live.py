"""``graphnav live --nmea udp://127.0.0.1:10110 --publish udp://127.0.0.1:10111 --out DIR``: online
navigation from NMEA 0183 streams (and NMEA 2000 gateways, ``--n2k``; Signal K servers, ``--signalk
ws://HOST:PORT``), the solution published as NMEA (GGA, HDT, VTG, ROT) and as Signal K deltas
(``--publish-signalk``). Listen on
loopback unless the sender is another machine (then bind that interface's address)."""

from __future__ import annotations

import argparse
import json
import logging

from ..errors import GraphnavError
from ..estimators import online_names
from ..io import load_log
from ..io.outputs import ensure_dir, write_text_atomic
from ..log import ODOMETRY_FROM_ROT
from ..online.live_runner import LiveRunner
from ..online.warmup import MAX_WARMUP_S, live_estimator
from ._common import add_drop_flag, add_json_flag, dropped_kinds, emit, jsonable, options_for
from .replay import parse_origin

log_ = logging.getLogger("graphnav.live")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("live", help="online estimation from NMEA streams", description=__doc__)
    p.add_argument("--nmea", action="append", metavar="udp://HOST:PORT|tcp://HOST:PORT",
                   help="NMEA 0183 source (UDP: bind; TCP: connect); repeatable")
    p.add_argument("--n2k", action="append", metavar="udp://HOST:PORT|tcp://HOST:PORT",
                   help="NMEA 2000 gateway text (canboat, Yacht Devices RAW, Actisense N2K ASCII; docs/log-format.md); "
                        "repeatable")
    p.add_argument("--signalk", action="append", metavar="ws://HOST:PORT[/PATH]",
                   help="a Signal K server's websocket delta stream (path default /signalk/v1/stream?subscribe=self); "
                        "repeatable")
    p.add_argument("--scans", action="append", metavar="udp://HOST:PORT",
                   help="LiDAR scans, one JSON scan record per datagram (docs/live.md); repeatable")
    p.add_argument("--scans-from", metavar="LOG", help="replay this log's scans on the NMEA stream's clock; "
                   "the run ends with the last scan")
    p.add_argument("--estimator", "-e", default="fixed-lag",
                   help=f"online estimator: {', '.join(online_names())} (default fixed-lag)")
    p.add_argument("--option", "-O", action="append", metavar="[ESTIMATOR.]KEY=VALUE",
                   help="estimator option (VALUE parsed as JSON when it can be); repeatable")
    p.add_argument("--publish", metavar="udp://HOST:PORT", help="send the solution as NMEA here")
    p.add_argument("--publish-signalk", metavar="udp://HOST:PORT",
                   help="send the solution as Signal K deltas here (one datagram per estimate; "
                        "uncertainties under meta)")
    p.add_argument("--out", metavar="DIR", help="write every estimate to a new DIR/live-YYYYmmddTHHMMSSZ.tum "
                   "(UTC start; flushed line by line), the summary beside it (.summary.json)")
    p.add_argument("--origin", metavar="LAT,LON", help="local frame origin (default: the first fix)")
    p.add_argument("--no-checksum-required", action="store_true",
                   help="accept sentences without a checksum (a wrong checksum is always rejected)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--idle-exit", type=float, metavar="S", help="stop when no input came for S seconds")
    p.add_argument("--warmup", type=float, metavar="S",
                   help="fixed-lag/isam2 with motion auto: hold the first records until S seconds (stream time) after "
                        "the first fix, then choose the motion model from them as an offline run would (default: "
                        "every kind seen twice and two of the slowest kind's intervals after the first fix; "
                        "docs/live.md); -O motion=... skips the warm-up")
    add_drop_flag(p)
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..config import Range, number

    for flag, value in (("--duration", args.duration), ("--idle-exit", args.idle_exit)):
        number(flag, value, Range(lo=0.0, hi=1e9, lo_open=True, optional=True))
    number("--warmup", args.warmup, Range(lo=0.0, hi=MAX_WARMUP_S, optional=True))
    if not (args.nmea or args.n2k or args.signalk):
        raise GraphnavError("give at least one source: --nmea, --n2k or --signalk", where="--nmea")
    drop = dropped_kinds(args)
    if args.out:
        ensure_dir(args.out)
    options = options_for(args, args.estimator)
    if args.estimator == "ekf":  # a marine stream's odometry is a rate of turn with the SOG (io.nmea_motion, n2k)
        options.setdefault("meta", {"odometry": ODOMETRY_FROM_ROT})
    make = live_estimator(args.estimator, options, args.warmup)
    estimator = make()
    if args.warmup is not None and not hasattr(estimator, "rule"):
        log_.warning("--warmup is ignored: the warm-up chooses the motion of fixed-lag/isam2 with motion auto")
    scans = load_log(args.scans_from) if args.scans_from else None
    runner = LiveRunner(args.nmea or [], estimator, n2k_sources=args.n2k, signalk_sources=args.signalk,
                        publish_signalk=args.publish_signalk, drop=drop, publish=args.publish, out_dir=args.out,
                        scans_from=scans,
                        origin=parse_origin(args.origin), require_checksum=not args.no_checksum_required,
                        duration=args.duration, idle_exit=args.idle_exit, scan_sources=args.scans,
                        restart=make)
    summary = runner.run()
    if args.out and runner.sink.writer is not None:  # beside this run's own TUM file, written atomically
        write_text_atomic(runner.sink.writer.path.with_suffix(".summary.json"), json.dumps(jsonable(summary), indent=2))
    emit(args, summary)
    return 0
