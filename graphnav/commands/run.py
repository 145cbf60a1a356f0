"""``graphnav run LOG --estimator NAME --out DIR``: one estimator on one log, scored against truth."""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

from .. import estimators
from ..estimators.options import check as check_options
from ..evaluation.evaluate import summarize
from ..io import load_log
from ..io.drop import drop_kinds
from ..io.geo_out import record_origin, write_wgs84
from ..io.outputs import OutDir
from ..io.trajectory_csv import write_trajectory_csv
from ..io.tum import TrajectoryWriter, write_truth, write_tum
from ._common import (
    add_drop_flag,
    add_json_flag,
    add_log_args,
    add_overwrite_flag,
    dropped_kinds,
    emit,
    jsonable,
    log_options,
    options_for,
    progress_bar,
)

log_ = logging.getLogger("graphnav.run")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run one estimator on a log", description=__doc__)
    add_log_args(p)
    next(a for a in p._actions if a.dest == "log").nargs = "?"  # (not needed with --list-options)
    p.add_argument("--estimator", "-e", help="one of: " + ", ".join(estimators.names()) + " (required)")
    p.add_argument("--list-options", metavar="ESTIMATOR",
                   help="print ESTIMATOR's -O options (default and meaning; one JSON object with --json) and exit")
    p.add_argument("--out", type=Path,
                   help="output directory (trajectory.tum, trajectory.csv, summary.json, truth.tum; "
                        "trajectory.geojson/.gpx/.kml in WGS84 when the log has a geodetic origin)")
    add_overwrite_flag(p)
    add_drop_flag(p)
    p.add_argument("--option", "-O", action="append", metavar="[ESTIMATOR.]KEY=VALUE",
                   help="estimator option (VALUE parsed as JSON when it can be), e.g. -O lag=10; repeatable; "
                        "--list-options ESTIMATOR lists them")
    add_json_flag(p)
    p.set_defaults(func=run)


def list_options(args: argparse.Namespace) -> int:
    from ..estimators.options import describe

    opts = describe(args.list_options)
    obj = {"estimator": args.list_options, "options": opts}
    lines = [f"-O options of {args.list_options} (graphnav run LOG -e {args.list_options} -O KEY=VALUE):"]
    group = None
    for o in opts:
        if o["group"] != group:
            group = o["group"]
            lines.append(f"  [{group}]")
        lines.append(f"  {o['name']:32s} {json.dumps(jsonable(o['default'])):14s} {o['type']}")
        if o["meaning"]:
            lines.append(f"      {o['meaning']}")
    if not opts:
        lines.append("  (none)")
    emit(args, obj, "\n".join(lines))
    return 0


def run(args: argparse.Namespace) -> int:
    if args.list_options:
        return list_options(args)
    missing = [n for n, v in (("LOG", args.log), ("--estimator", args.estimator)) if not v]
    if missing:
        raise ValueError(f"graphnav run: the following arguments are required: {', '.join(missing)}")
    estimators.get(args.estimator)  # (an unknown name, option or kind fails before --out is touched)
    options = options_for(args, args.estimator)
    check_options(args.estimator, options)
    dropped = dropped_kinds(args)
    if not args.out:
        return _run(args, options, dropped, None)
    out = OutDir(args.out, command="run", overwrite=args.overwrite)
    online: list[TrajectoryWriter] = []  # (set once the run writes its online track)

    def keep() -> list[str]:  # a run that dies after estimating keeps its online track (flushed as it came)
        return ["online.tum", "online.cov"] if online and online[0].count else []

    with out.discarded_on_error(keep):  # a failed run leaves nothing else in --out
        return _run(args, options, dropped, out, online)


def _run(args: argparse.Namespace, options: dict, dropped: list[str], out: OutDir | None,
         online: list[TrajectoryWriter] | None = None) -> int:
    log = drop_kinds(load_log(args.log, lenient=args.lenient, **log_options(args)), dropped)
    why = estimators.get(args.estimator).unmet(log)
    if why:
        after = f" (after --drop {','.join(dropped)})" if dropped else ""
        raise ValueError(f"estimator {args.estimator!r} cannot run on {args.log}{after}: {why}")
    writer = None
    if out is not None:
        out.file("online.cov")  # the writer's covariance sidecar, when the estimator gives covariances
        writer = TrajectoryWriter(out.file("online.tum"))  # appended and flushed as estimates arrive
        if online is not None:
            online.append(writer)
    log_.info("running %s on %s (%d records)", args.estimator, args.log, len(log))
    span = max(float(log.t1 - log.t0), 0.0) if len(log) else 0.0
    bar = progress_bar(args, total=round(span, 1), unit="s", desc=f"{args.estimator} (log time)",
                       bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s [{elapsed}<{remaining}]")

    def on_estimate(t: float, pose, cov) -> None:  # noqa: ANN001
        if writer is not None:
            writer.write(t, pose, cov)
        done = min(max(float(t - log.t0), 0.0), bar.total or 0.0)
        if done > bar.n:
            bar.update(done - bar.n)

    t0 = time.perf_counter()
    try:
        result = estimators.run(args.estimator, log, on_estimate=on_estimate if writer or not bar.disable else None,
                                **options)
        if not bar.disable and bar.total and bar.n < bar.total:
            bar.update(bar.total - bar.n)  # (the last estimate may precede the log's last record)
    finally:
        bar.close()
        if writer:
            writer.close()
    runtime = time.perf_counter() - t0
    summary = summarize(args.estimator, result, log, runtime_s=runtime)
    summary["options"] = options
    summary["dropped"] = dropped
    summary["inputs"] = estimators.inputs(args.estimator, log, options, result.info)
    summary["origin"] = record_origin(log.meta)  # the log's geodetic origin (None: none), for graphnav export
    if out is not None:  # each file atomically (temporary file + rename)
        write_tum(result.trajectory, out.file("trajectory.tum"))
        write_truth(log, out)  # truth.tum beside the estimate: evo_ape tum truth.tum trajectory.tum
        write_trajectory_csv(result.trajectory, out.file("trajectory.csv"))
        if result.online is not None and result.online is not result.trajectory:
            write_tum(result.online, out.file("online_final.tum"))
        tracks = {args.estimator: result.trajectory, **({"truth": log.truth()} if log.has_truth else {})}
        summary.update(write_wgs84(out, tracks, log.meta))  # WGS84 tracks, or "wgs84": None and why
        out.write_text("summary.json", json.dumps(jsonable({**summary, "info": result.info}), indent=2))
        summary["out"] = str(args.out)
    human = "\n".join(f"{k:22s} {v}" for k, v in jsonable(summary).items())
    emit(args, summary, human)
    return 0
