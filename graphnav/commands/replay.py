"""``graphnav replay LOG --nmea-out udp://127.0.0.1:PORT --speed 10``: a log as NMEA traffic."""

from __future__ import annotations

import argparse
import signal
import threading

from ..io import load_log
from ..online.nmea_replay import replay
from ._common import add_json_flag, add_log_args, emit, log_options, seed_arg


def parse_origin(text: str | None) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--origin {text!r}: expected LAT,LON in degrees") from None
    return lat, lon


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="send a log as NMEA 0183 over UDP", description=__doc__)
    add_log_args(p)
    p.add_argument("--nmea-out", required=True, metavar="udp://HOST:PORT", help="where to send the sentences")
    p.add_argument("--scans-out", metavar="udp://HOST:PORT",
                   help="also send the log's scans, one JSON scan record per datagram (see docs/live.md)")
    p.add_argument("--speed", type=float, default=1.0, help="x real time (0: as fast as possible)")
    p.add_argument("--origin", metavar="LAT,LON", help="geodetic origin of the log's local frame "
                   "(default: the log's meta origin, else 43.5,16.4)")
    p.add_argument("--corrupt", type=float, default=0.0, metavar="FRACTION",
                   help="damage this fraction of sentences (checksum/robustness tests)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of --corrupt's damage (default 0)")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..config import Range, number

    number("--speed", args.speed, Range(lo=0.0, hi=1e6))
    number("--corrupt", args.corrupt, Range(lo=0.0, hi=1.0))
    log = load_log(args.log, lenient=args.lenient, **log_options(args))
    stop = threading.Event()
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        out = replay(log, args.nmea_out, speed=args.speed, origin=parse_origin(args.origin),
                     corrupt=args.corrupt, seed=args.seed, stop=stop, scans_target=args.scans_out)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    human = f"sent {out['sentences_sent']} sentences to {out['target']} in {out['wall_s']:.1f} s"
    emit(args, out, human)
    return 0
