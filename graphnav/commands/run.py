"""``graphnav run LOG --estimator NAME --out DIR``: one estimator on one log, scored against truth."""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

from .. import estimators
from ..evaluation.evaluate import summarize
from ..io import load_log
from ..io.geo_out import record_origin, write_wgs84
from ..io.outputs import OutDir
from ..io.tum import TrajectoryWriter, write_truth
from ._common import add_json_flag, add_log_args, add_overwrite_flag, emit, jsonable, parse_options

log_ = logging.getLogger("graphnav.run")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run one estimator on a log", description=__doc__)
    add_log_args(p)
    p.add_argument("--estimator", "-e", required=True, help="one of: " + ", ".join(estimators.names()))
    p.add_argument("--out", type=Path,
                   help="output directory (trajectory.tum, trajectory.csv, summary.json, truth.tum; "
                        "trajectory.geojson/.gpx/.kml in WGS84 when the log has a geodetic origin)")
    add_overwrite_flag(p)
    p.add_argument("--option", "-O", action="append", metavar="KEY=VALUE",
                   help="estimator option (value parsed as JSON when it can be); repeatable")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = OutDir(args.out, command="run", overwrite=args.overwrite) if args.out else None
    log = load_log(args.log, lenient=args.lenient)
    options = parse_options(args.option)
    writer = None
    if out is not None:
        out.file("online.cov")  # the writer's covariance sidecar, when the estimator gives covariances
        writer = TrajectoryWriter(out.file("online.tum"))  # appended and flushed as estimates arrive
    log_.info("running %s on %s (%d records)", args.estimator, args.log, len(log))
    t0 = time.perf_counter()
    try:
        result = estimators.run(args.estimator, log, on_estimate=writer.write if writer else None, **options)
    finally:
        if writer:
            writer.close()
    runtime = time.perf_counter() - t0
    summary = summarize(args.estimator, result, log, runtime_s=runtime)
    summary["options"] = options
    summary["origin"] = record_origin(log.meta)  # the log's geodetic origin (None: none), for graphnav export
    if out is not None:  # each file atomically (temporary file + rename)
        result.trajectory.to_tum(out.file("trajectory.tum"))
        write_truth(log, out)  # truth.tum beside the estimate: evo_ape tum truth.tum trajectory.tum
        result.trajectory.to_csv(out.file("trajectory.csv"))
        if result.online is not None and result.online is not result.trajectory:
            result.online.to_tum(out.file("online_final.tum"))
        tracks = {args.estimator: result.trajectory, **({"truth": log.truth()} if log.has_truth else {})}
        summary.update(write_wgs84(out, tracks, log.meta))  # WGS84 tracks, or "wgs84": None and why
        out.write_text("summary.json", json.dumps(jsonable({**summary, "info": result.info}), indent=2))
        summary["out"] = str(args.out)
    human = "\n".join(f"{k:22s} {v}" for k, v in jsonable(summary).items())
    emit(args, summary, human)
    return 0
