"""``graphnav info LOG``: what a log holds."""

from __future__ import annotations

import argparse

from ..io import load_log
from ._common import add_json_flag, add_log_args, emit


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="count the records of a log", description=__doc__)
    add_log_args(p)
    p.add_argument("--topic", action="append", metavar="KIND=TOPIC",
                   help="ROS bags: read KIND (scan, gnss, imu, heading, odometry, nmea) from TOPIC")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    options = {}
    if getattr(args, "topic", None):
        from ..io.rosbag import parse_topic_args

        options["topics"] = parse_topic_args(args.topic)
    log = load_log(args.log, lenient=args.lenient, **options)
    out = {"records": log.counts(), "t0": log.t0, "t1": log.t1, "has_truth": log.has_truth}
    for key in ("name", "origin", "skipped", "skipped_errors", "truncated", "dropped_fields", "frame", "reference",
                "topics", "time", "messages", "ignored", "unused", "missing_returns", "dead_beams", "dropped"):
        if key in log.meta:
            out[key] = log.meta[key]
    human = "\n".join(
        [f"{args.log}: {len(log)} records, t = {log.t0} .. {log.t1} s, truth: {log.has_truth}"]
        + [f"  {k:12s} {v}" for k, v in out["records"].items()]
    )
    emit(args, out, human)
    return 0
