"""``graphnav info LOG``: what a log holds."""

from __future__ import annotations

import argparse

from ..evaluation.datacheck import gaps, gnss_jumps, speed_log_scale
from ..io import load_log
from ._common import add_json_flag, add_log_args, emit, log_options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="count the records of a log", description=__doc__)
    add_log_args(p)
    p.add_argument("--topic", action="append", metavar="KIND=TOPIC",
                   help="ROS bags: read KIND (scan, cloud, gnss, gnss_velocity, imu, heading, odometry, nmea) "
                        "from TOPIC")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    options = {}
    if getattr(args, "topic", None):
        from ..io.rosbag import parse_topic_args

        options["topics"] = parse_topic_args(args.topic)
    log = load_log(args.log, lenient=args.lenient, **options, **log_options(args))
    out = {"records": log.counts(), "t0": log.t0, "t1": log.t1, "has_truth": log.has_truth}
    for key in ("name", "origin", "skipped", "skipped_errors", "truncated", "dropped_fields", "frame", "reference",
                "topics", "time", "date", "messages", "ignored", "unused", "missing_returns", "dead_beams", "dropped",
                "sentences", "hdg_without_variation", "format", "pgns", "paths", "columns", "units"):
        if key in log.meta:
            out[key] = log.meta[key]
    from ..io.n2k import record_sources

    if sources := record_sources(log):
        out["sources"] = sources
    out["gaps"] = gaps(log)
    out["gnss_jumps"] = gnss_jumps(log)
    if (sl := speed_log_scale(log)) is not None:
        out["speed_log"] = sl
    human = "\n".join(
        [f"{args.log}: {len(log)} records, t = {log.t0} .. {log.t1} s, truth: {log.has_truth}"]
        + [f"  {k:14s} {v}" + (f"  (by source: {out['sources'][k]})" if k in out.get("sources", {}) else "")
           for k, v in out["records"].items()]
        + ([f"  date: {log.meta['date'].get('note') or log.meta['date']}"] if "date" in log.meta else [])
        + [f"  gaps ({k}): {g['count']} longer than {g['threshold_s']:.3g} s, {g['total_s']:.1f} s in all"
           for k, g in out["gaps"].items() if g["count"]]
        + [f"  GNSS jumps: {j['count']} (faster than {j['speed_bound_mps']:.3g} m/s + 5 sigma)" for j in
           [out["gnss_jumps"]] if j["count"]]
        + [f"    {d['t0']:.1f} -> {d['t1']:.1f} s: {d['distance_m']:.1f} m" for d in out["gnss_jumps"]["largest"]]
        + [speed_log_line(out.get("speed_log"))]
    )
    emit(args, out, human.rstrip("\n"))
    return 0


def speed_log_line(sl: dict | None) -> str:
    """The human line of :func:`~graphnav.evaluation.datacheck.speed_log_scale` ('' without one)."""
    if sl is None:
        return ""
    if sl["scale"] is None:
        return "  speed log: no window with the heading varied enough to tell its scale from a current"
    n = len(sl["windows"])
    spread = f", {sl['scale_spread']:.3f} between windows" if sl["scale_spread"] is not None else ""
    return (f"  speed log: x{sl['scale']:.3f} against the GNSS velocity ({n} window{'s' if n != 1 else ''}{spread}; "
            f"above 1: it under-reads), bow vs track through the water {sl['angle_deg']:+.1f} deg")
