"""``graphnav info LOG``: what a log holds."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ..io import load_log
from ..log import NavLog
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
    human = "\n".join(
        [f"{args.log}: {len(log)} records, t = {log.t0} .. {log.t1} s, truth: {log.has_truth}"]
        + [f"  {k:14s} {v}" + (f"  (by source: {out['sources'][k]})" if k in out.get("sources", {}) else "")
           for k, v in out["records"].items()]
        + ([f"  date: {log.meta['date'].get('note') or log.meta['date']}"] if "date" in log.meta else [])
        + [f"  gaps ({k}): {g['count']} longer than {g['threshold_s']:.3g} s, {g['total_s']:.1f} s in all"
           for k, g in out["gaps"].items() if g["count"]]
    )
    emit(args, out, human)
    return 0


#: A gap is a step between consecutive records longer than this many times the median step (and
#: than GAP_MIN_S): a GNSS outage, a logger pause, a lost stretch of file.
GAP_FACTOR = 5.0
GAP_MIN_S = 1.0
GAPS_LISTED = 10


def time_gaps(t: np.ndarray) -> dict[str, Any]:
    """The gaps of a sorted time series: steps longer than ``max(GAP_MIN_S, GAP_FACTOR x median
    step)``; their count, total length [s] and the longest :data:`GAPS_LISTED` as ``[t0, t1]``."""
    dt = np.diff(t)
    pos = dt[dt > 0]
    threshold = max(GAP_MIN_S, GAP_FACTOR * float(np.median(pos))) if pos.size else GAP_MIN_S
    idx = np.flatnonzero(dt > threshold)
    longest = idx[np.argsort(-dt[idx], kind="stable")][:GAPS_LISTED]
    return {"threshold_s": threshold, "count": int(idx.size), "total_s": float(dt[idx].sum()),
            "longest": [[float(t[i]), float(t[i + 1])] for i in sorted(longest)]}


def gaps(log: NavLog) -> dict[str, dict[str, Any]]:
    """:func:`time_gaps` of all records together (``"all"``) and of each timed record kind with at
    least 3 records."""
    t_all = np.array([r.t for r in log.records], dtype=float)
    out = {"all": time_gaps(t_all)} if t_all.size >= 3 else {}
    kinds = np.array([r.kind for r in log.records])
    for k in log.counts():
        sel = kinds == k
        if int(sel.sum()) >= 3:
            out[k] = time_gaps(t_all[sel])
    return out
