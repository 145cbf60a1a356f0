"""``graphnav run LOG --estimator NAME --out DIR``: one estimator on one log, scored against truth (or,
``--holdout-gnss EVERY,LENGTH``, against GNSS fixes withheld from it); ``--out`` also gets the report
and map that ``graphnav compare`` writes, for this one estimator.

``graphnav run LOG [LOG ...] -e NAME --out DIR [--scheduler ADDR]``: a fleet of logs, in parallel on a
Dask LocalCluster (loopback) or an existing scheduler (:mod:`graphnav.evaluation.sweep`), each log's
outputs in ``DIR/<log name>/``, resumable (``DIR/fleet.jsonl``); one ``{"runs": [...]}`` object.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

from .. import estimators
from ..estimators.options import check as check_options
from ..evaluation.evaluate import summarize
from ..evaluation.holdout import HoldoutSpec, withhold
from ..io import load_log
from ..io.drop import drop_kinds
from ..io.geo_out import record_origin, write_wgs84
from ..io.outputs import OutDir
from ..io.trajectory_csv import write_trajectory_csv
from ..io.tum import TrajectoryWriter, write_truth, write_tum
from ._common import (
    add_drop_flag,
    add_holdout_flag,
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
#: ``run --out`` writes compare's report, figures and map for its one estimator unless ``--no-report``
#: (tests/conftest.py turns this default off for the suite: ~3 s of figures per run; report tests ask)
REPORT_DEFAULT = True


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run one estimator on a log", description=__doc__)
    add_log_args(p)
    log_arg = next(a for a in p._actions if a.dest == "log")
    log_arg.nargs = "*"  # (none with --list-options; several: a fleet, run in parallel)
    log_arg.metavar = "LOG"
    log_arg.help += "; several logs run in parallel on Dask (--out DIR needed: DIR/<log name>/ each)"
    p.add_argument("--estimator", "-e", help="one of: " + ", ".join(estimators.names()) + " (required)")
    p.add_argument("--list-options", metavar="ESTIMATOR",
                   help="print ESTIMATOR's -O options (default and meaning; one JSON object with --json) and exit")
    p.add_argument("--out", type=Path,
                   help="output directory (trajectory.tum, trajectory.csv, summary.json, truth.tum, report.md, "
                        "report.html, map.html, figures; trajectory.geojson/.gpx/.kml in WGS84 when the log has a "
                        "geodetic origin)")
    add_overwrite_flag(p)
    add_drop_flag(p)
    add_holdout_flag(p)
    p.add_argument("--report", action=argparse.BooleanOptionalAction, default=REPORT_DEFAULT,
                   help="with --out: also write compare's report (report.md, report.html), figures and map.html "
                        "for this estimator (default on; --no-report: only the trajectories, truth.tum, WGS84 "
                        "tracks and summary.json; a fleet of logs writes no report)")
    p.add_argument("--option", "-O", action="append", metavar="[ESTIMATOR.]KEY=VALUE",
                   help="estimator option (VALUE parsed as JSON when it can be), e.g. -O lag=10; repeatable; "
                        "--list-options ESTIMATOR lists them")
    p.add_argument("--scheduler", metavar="ADDR",
                   help="several logs: an existing Dask scheduler (tcp://host:8786), or 'serial' "
                        "(default: a LocalCluster on 127.0.0.1 for the run)")
    p.add_argument("--workers", type=int, default=2, help="several logs: LocalCluster worker processes (default 2)")
    add_json_flag(p)
    p.set_defaults(func=run)


def list_options(args: argparse.Namespace) -> int:
    from ..estimators.options import describe

    opts = describe(args.list_options)
    obj = {"estimator": args.list_options, "options": opts}
    lines = [f"-O options of {args.list_options} (graphnav run LOG -e {args.list_options} -O KEY=VALUE):"]
    if any("path" in o for o in opts):
        lines.append("  in sections: -O SECTION.KEY=VALUE, TOML [options.SECTION] KEY = VALUE; or by the flat "
                     "name, -O FLAT=VALUE (in parentheses where it is not KEY)")
    group = None
    for o in opts:
        if o["group"] != group:
            group = o["group"]
            lines.append(f"  [{group}]" + (f" {o['group_help']}" if o.get("group_help") else ""))
        name = o.get("path", o["name"]).rpartition(".")[2]
        flat = f"  ({o['name']})" if name != o["name"] else ""
        lines.append(f"  {name:32s} {json.dumps(jsonable(o['default'])):14s} {o['type']}{flat}")
        if o["meaning"]:
            lines.append(f"      {o['meaning']}")
    if not opts:
        lines.append("  (none)")
    emit(args, obj, "\n".join(lines))
    return 0


def run(args: argparse.Namespace) -> int:
    if args.list_options:
        return list_options(args)
    logs = list(args.log) if isinstance(args.log, list) else [args.log] if args.log else []
    missing = [n for n, v in (("LOG", logs), ("--estimator", args.estimator)) if not v]
    if missing:
        raise ValueError(f"graphnav run: the following arguments are required: {', '.join(missing)}")
    estimators.get(args.estimator)  # (an unknown name, option or kind fails before --out is touched)
    options = options_for(args, args.estimator)
    check_options(args.estimator, options)
    dropped = dropped_kinds(args)
    spec = HoldoutSpec.parse(args.holdout_gnss) if getattr(args, "holdout_gnss", None) else None
    if len(logs) > 1:
        return _fleet(args, logs, options, dropped)
    args.log = logs[0]
    if not args.out:
        return _run(args, options, dropped, None, spec=spec)
    out = OutDir(args.out, command="run", overwrite=args.overwrite)
    online: list[TrajectoryWriter] = []  # (set once the run writes its online track)

    def keep() -> list[str]:  # a run that dies after estimating keeps its online track (flushed as it came)
        return ["online.tum", "online.cov"] if online and online[0].count else []

    with out.discarded_on_error(keep):  # a failed run leaves nothing else in --out
        return _run(args, options, dropped, out, online, spec=spec)


def _run(args: argparse.Namespace, options: dict, dropped: list[str], out: OutDir | None,
         online: list[TrajectoryWriter] | None = None, spec: HoldoutSpec | None = None) -> int:
    summary = _single(args, options, dropped, out, online, spec)
    human = "\n".join(f"{k:22s} {v}" for k, v in jsonable(summary).items())
    emit(args, summary, human)
    return 0


def _single(args: argparse.Namespace, options: dict, dropped: list[str], out: OutDir | None,
            online: list[TrajectoryWriter] | None = None, spec: HoldoutSpec | None = None) -> dict:
    """One estimator on ``args.log`` (GNSS withheld as ``spec`` says): the summary (the single run's JSON
    fields); files into ``out``."""
    whole = drop_kinds(load_log(args.log, lenient=args.lenient, **log_options(args)), dropped)
    plan = withhold(whole, spec) if spec is not None else None
    log = plan.log if plan is not None else whole
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
    if plan is not None:
        smoothed = estimators.get(args.estimator).kind == "smoother"  # read across a hole (Holdout.score)
        summary["holdout"] = {**plan.describe(), **plan.score(result.trajectory, smoothed=smoothed)}
        summary["holdout_rmse_m"] = summary["holdout"]["rmse_m"]
        if result.online is not None and result.online is not result.trajectory:
            summary["holdout"].update(plan.score_online(result.online))
    if out is not None:  # each file atomically (temporary file + rename)
        write_tum(result.trajectory, out.file("trajectory.tum"))
        write_trajectory_csv(result.trajectory, out.file("trajectory.csv"))
        if result.online is not None and result.online is not result.trajectory:
            write_tum(result.online, out.file("online_final.tum"))
            if "coasted" in (result.online.meta or {}):  # the online track with its coasted flag (and covariance)
                write_trajectory_csv(result.online, out.file("online_final.csv"))
        if getattr(args, "report", False):
            summary.update(_report(args, whole, log, plan, result, summary, runtime, out))
        else:
            write_truth(log, out)  # truth.tum beside the estimate: evo_ape tum truth.tum trajectory.tum
            tracks = {args.estimator: result.trajectory, **({"truth": log.truth()} if log.has_truth else {})}
            summary.update(write_wgs84(out, tracks, log.meta))  # WGS84 tracks, or "wgs84": None and why
        out.write_text("summary.json", json.dumps(jsonable({**summary, "info": result.info}), indent=2))
        summary["out"] = str(args.out)
    return summary


def _report(args: argparse.Namespace, whole, log, plan, result, summary: dict, runtime: float,  # noqa: ANN001
            out: OutDir) -> dict:
    """The report, figures, map, truth.tum and WGS84 tracks of ``graphnav compare`` for this one estimator
    (truth.tum beside the estimate: ``evo_ape tum truth.tum trajectory.tum``); returns the summary's
    ``wgs84`` entry (the tracks in WGS84, or ``"wgs84": None`` and why)."""
    import shlex

    from ..evaluation.comparison import Comparison, Entry
    from ..evaluation.datacheck import data_checks
    from ..evaluation.report import render
    from ..evaluation.report.writer import write

    spec = estimators.get(args.estimator)
    entry = Entry(args.estimator, spec.kind, spec.description, summary.get("options") or {}, result, summary,
                  runtime_s=runtime)
    comp = Comparison([entry], log, log_name=str(args.log), whole_log=whole, holdout=plan,
                      dropped=list(summary.get("dropped") or []), checks=data_checks(whole))
    command = shlex.join(["graphnav", *args.argv]) if hasattr(args, "argv") else None
    rep = render(comp, command=command, workers=1)
    write(rep, out)
    return rep.wgs84 or {}


# -- a fleet of logs ---------------------------------------------------------------------------------
FLEET_RESULTS = "fleet.jsonl"  # DIR/fleet.jsonl: one finished log per line (the sweep's results file)


def log_names(logs: list[str]) -> list[str]:
    """``DIR/<name>/`` of each log: its file name without the log suffixes, made unique (``-2``, ...)."""
    names: list[str] = []
    for lg in logs:
        name = Path(lg).name
        for suffix in (".gz", ".bz2", ".jsonl", ".json", ".npz", ".nmea", ".log", ".txt", ".bag", ".csv"):
            name = name.removesuffix(suffix)
        name = name or "log"
        base, i = name, 1
        while name in names:
            i += 1
            name = f"{base}-{i}"
        names.append(name)
    return names


def _fleet(args: argparse.Namespace, logs: list[str], options: dict, dropped: list[str]) -> int:
    """Every log of ``logs`` through the estimator on Dask (:func:`graphnav.evaluation.sweep.run_sweep`;
    a log already in ``DIR/fleet.jsonl`` with the same parameters is not run again); a failed log is
    a run with an ``error``, the others go on. Exit 0 when every log ran, else 2."""
    from ..config import Range, number
    from ..evaluation.sweep import run_sweep
    from ._common import progress_enabled

    number("--workers", args.workers, Range(lo=1, hi=256, integer=True))
    if not args.out:
        raise ValueError("graphnav run: several logs need --out DIR (each log's outputs go to DIR/<log name>/)")
    root = Path(args.out)
    results = root / FLEET_RESULTS
    if root.exists() and not root.is_dir():
        raise ValueError(f"--out {root}: not a directory")
    if root.exists() and any(root.iterdir()) and not results.exists() and not args.overwrite:
        raise ValueError(f"--out {root} is not empty and holds no {FLEET_RESULTS} to resume "
                         "(--overwrite replaces graphnav's outputs there)")
    root.mkdir(parents=True, exist_ok=True)
    reader = {"lenient": bool(args.lenient), "max_speed": args.max_speed,
              "date": args.date.isoformat() if getattr(args, "date", None) else None}
    tasks = [{"key": name, "log": str(lg), "stamp": _stamp(lg), "estimator": args.estimator, "options": options,
              "dropped": dropped, "reader": reader, "out": str(root / name)}
             for lg, name in zip(logs, log_names(logs), strict=True)]
    report: dict = {}
    t0 = time.perf_counter()
    runs = run_sweep(fleet_task, tasks, out=results, scheduler=args.scheduler, workers=args.workers,
                     progress=progress_enabled(args), desc=f"{args.estimator} on {len(tasks)} logs", report=report,
                     overwrite=bool(args.overwrite))
    wall = time.perf_counter() - t0
    failed = sum(1 for r in runs if r.get("error"))
    obj = {"runs": runs, "logs": len(runs), "failed": failed, "scheduler": report.get("scheduler"),
           "reused": len(runs) - report.get("pending", len(runs)), "wall_s": wall,
           "runtime_s_sum": sum(float(r.get("runtime_s") or 0.0) for r in runs), "out": str(root)}
    rows = [f"{'log':24s} {'ATE RMSE [m]':>12s} {'runtime [s]':>11s}  error"]
    for r in runs:
        ate, rt = r.get("ate_rmse_m"), r.get("runtime_s")
        ate_s = "-" if ate is None else f"{ate:.3f}"
        rt_s = "-" if rt is None else f"{rt:.1f}"
        rows.append(f"{r['log'][-24:]:24s} {ate_s:>12s} {rt_s:>11s}  {r.get('error') or ''}")
    rows.append(f"{len(runs)} logs ({failed} failed) in {wall:.1f} s wall on {obj['scheduler']}; outputs in {root}/")
    emit(args, obj, "\n".join(rows))
    return 2 if failed else 0


def _stamp(path: str) -> list[int] | None:
    """Size and modification time of a log (a directory: of its newest entry): a changed log is run again."""
    try:
        p = Path(path)
        st = [p.stat(), *(c.stat() for c in p.iterdir())] if p.is_dir() else [p.stat()]
    except OSError:
        return None
    return [sum(s.st_size for s in st), max(s.st_mtime_ns for s in st)]


def fleet_task(task: dict) -> dict:
    """One log of a fleet (runs in a Dask worker): the single run's summary, its files in
    ``task["out"]``; any failure is the run's ``error`` (one line), never an exception."""
    import datetime as dt
    from dataclasses import replace

    from ..errors import GraphnavError
    from ..log import default_limits, set_default_limits

    rd = task["reader"]
    if rd.get("max_speed") is not None:
        set_default_limits(replace(default_limits(), max_speed=float(rd["max_speed"])))
    args = argparse.Namespace(log=task["log"], estimator=task["estimator"], lenient=rd["lenient"], json=True,
                              quiet=True, date=dt.date.fromisoformat(rd["date"]) if rd.get("date") else None,
                              out=Path(task["out"]))
    head = {"log": task["log"], "estimator": task["estimator"]}
    try:
        out = OutDir(args.out, command="run", overwrite=True)  # the fleet's own sub-directory
        online: list[TrajectoryWriter] = []
        with out.discarded_on_error(lambda: []):
            summary = _single(args, dict(task["options"]), list(task["dropped"]), out, online)
        return jsonable({**head, **summary})
    except (GraphnavError, OSError, ValueError, KeyError) as err:
        return {**head, "error": " ".join(str(err).split())[:500]}
    except Exception as err:  # noqa: BLE001 - a bug in one log's run must not stop the fleet
        return {**head, "error": f"internal error: {type(err).__name__}: {' '.join(str(err).split())[:400]}"}
