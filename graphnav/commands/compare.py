"""``graphnav compare LOG --out DIR [--estimators a,b,...]``: every estimator the log can feed, side
by side — DIR/report.md, DIR/report.html (self-contained), PNG figures, DIR/<estimator>.tum and
DIR/truth.tum, DIR/map.html (the tracks, self-contained), and when the log has a geodetic origin every
track in WGS84: DIR/trajectory.geojson, .gpx, .kml."""

from __future__ import annotations

import argparse
import logging
import os
import shlex
import time
from pathlib import Path

from .. import estimators
from ..errors import GraphnavError
from ..estimators.options import check as check_options
from ..evaluation.comparison import compare, ranked
from ..evaluation.report import to_json, write_report
from ..evaluation.trackmap import write_track_map
from ..io import load_log
from ..io.drop import drop_kinds
from ..io.geo_out import write_wgs84
from ..io.outputs import OutDir
from ..scan.icp_cache import MatchCache
from ._common import (
    add_drop_flag,
    add_json_flag,
    add_log_args,
    add_overwrite_flag,
    dropped_kinds,
    emit,
    log_options,
    options_by_estimator,
    progress_bar,
)

log_ = logging.getLogger("graphnav.compare")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="run several estimators on one log and write a report",
                       description=__doc__)
    add_log_args(p)
    p.add_argument("--out", type=Path, required=True, help="output directory (report.md, *.png, *.tum)")
    add_overwrite_flag(p)
    add_drop_flag(p)
    p.add_argument("--estimators", "-e", default=None,
                   help="comma-separated names, LABEL=NAME to run one estimator twice under another "
                        "label (default: every estimator the log can feed); known: "
                        + ", ".join(estimators.names()))
    p.add_argument("--option", "-O", action="append", metavar="ESTIMATOR.KEY=VALUE",
                   help="option for one estimator (or label), e.g. -O scan-to-map.backend=gicp; repeatable")
    p.add_argument("--workers", "-j", type=int, default=0,
                   help="processes for the estimators and the figures (the smoothers share one, with their "
                        "weighted-ICP matches; runtimes then include contention); default 0: one per core, "
                        "1: everything in this process")
    p.add_argument("--no-icp-cache", dest="icp_cache", action="store_false",
                   help="every estimator computes its own weighted-ICP matches (default: a match shared by "
                        "several estimators is computed once; their runtimes then exclude it)")
    p.add_argument("--tiles", metavar="URL", default=None,
                   help="map.html draws map tiles from this {z}/{x}/{y} URL template under the tracks (loaded "
                        "over the network when the page is opened; default: none, the page is self-contained)")
    add_json_flag(p)
    p.set_defaults(func=run)


def _runnable(log, names: list[str] | None) -> int:  # noqa: ANN001
    """How many of ``names`` (``LABEL=NAME`` allowed) the log can feed: the progress bar's total."""
    n = 0
    for name in names if names is not None else estimators.names():
        try:
            n += estimators.get(name.partition("=")[2] or name).unmet(log) is None
        except KeyError:
            pass
    return n


def _check_names(names: list[str] | None) -> None:
    """Every estimator ``-e`` names (``LABEL=NAME``: its NAME) is one graphnav knows: an unknown one is
    a ``KeyError`` with the closest names (difflib), before anything runs or is written."""
    for name in names or []:
        est = (name.partition("=")[2] if "=" in name else name).strip()
        if est not in estimators.registry():
            raise KeyError(f"-e {name}: " + estimators.unknown_name(est))


def _check_scopes(options: dict[str, dict], names: list[str] | None) -> None:
    """Every ``-O ESTIMATOR.KEY`` names an estimator (or label) this comparison runs, and a key it knows."""
    labels = {}
    for name in names if names is not None else estimators.names():
        label, _, est = name.partition("=") if "=" in name else (name, "", name)
        labels[label.strip()] = est.strip()
    for scope, given in options.items():
        if scope not in labels:
            if scope not in estimators.registry():
                raise KeyError(f"-O {scope}.KEY=VALUE: " + estimators.unknown_name(scope, {*estimators.names(),
                                                                                         *labels}))
            raise ValueError(f"-O {scope}.KEY=VALUE: {scope!r} is not one of the estimators compared "
                             f"({', '.join(labels)})")
        if labels[scope] in estimators.registry():
            check_options(labels[scope], given)


def run(args: argparse.Namespace) -> int:
    options = options_by_estimator(args)  # (a bad -O, name or kind fails before --out is touched)
    names = [n.strip() for n in args.estimators.split(",") if n.strip()] if args.estimators else None
    _check_names(names)
    _check_scopes(options, names)
    dropped = dropped_kinds(args)
    out = getattr(args, "out_dir", None)  # (demo prepares its own)
    if out is not None:
        return _compare(args, options, names, dropped, out)
    out = OutDir(args.out, command="compare", overwrite=getattr(args, "overwrite", False))
    with out.discarded_on_error():  # a failed compare leaves nothing in --out
        return _compare(args, options, names, dropped, out)


def _compare(args: argparse.Namespace, options: dict[str, dict], names: list[str] | None, dropped: list[str],
             out: OutDir) -> int:
    log = drop_kinds(load_log(args.log, lenient=args.lenient, **log_options(args)), dropped)
    t0 = time.perf_counter()
    if not 0 <= args.workers <= 256:
        raise ValueError(f"--workers must be in [0, 256] (0: one per CPU), got {args.workers}")
    workers = args.workers if args.workers > 0 else (os.cpu_count() or 1)
    cache = MatchCache() if getattr(args, "icp_cache", True) else None  # (demo builds its own Namespace)
    bar = progress_bar(args, total=_runnable(log, names), desc="compare", unit="estimator")
    started = []

    def progress(name: str) -> None:  # called as each estimator starts
        if started:
            bar.update(1)
        started.append(name)
        bar.set_postfix_str(name)
        if bar.disable:
            log_.info("running %s on %s", name, args.log)

    try:
        entries = compare(log, names, options=options, progress=progress, workers=workers, cache=cache)
        if started:
            bar.update(1)
    finally:
        bar.close()
    if not any(e.ok for e in entries):
        why = "; ".join(f"{e.name}: " + (f"failed: {e.error}" if e.error is not None else f"not run: {e.skipped}")
                        for e in entries)
        after = f" (after --drop {','.join(dropped)})" if dropped else ""
        raise GraphnavError(f"no estimator ran on this log{after}: {why or 'none given'}", where=str(args.log))
    command = shlex.join(["graphnav", *args.argv]) if hasattr(args, "argv") else None
    files = write_report(entries, log, out, log_name=str(args.log), command=command, workers=workers)
    tracks = {**({"truth": log.truth()} if log.has_truth else {}),
              **{e.name: e.result.trajectory for e in entries if e.ok and e.result is not None}}
    geo = write_wgs84(out, tracks, log.meta)  # WGS84 tracks, or "wgs84": None and why
    files.update({n: out.path / n for n in (geo["wgs84"] or {}).get("files", [])})
    files["map.html"] = write_track_map(out.file("map.html"), tracks, log.meta, title=f"Tracks: {args.log}",
                                        tiles=getattr(args, "tiles", None))
    total = time.perf_counter() - t0
    for e in entries:
        if e.error is not None:
            log_.warning("%s failed: %s", e.name, e.error)
        elif e.skipped is not None:
            log_.info("%s not run: %s", e.name, e.skipped)
    hits = sum((e.summary or {}).get("icp_cache_hits", 0) for e in entries) if cache is not None else None
    obj = to_json(entries, str(args.log), out=str(args.out), total_runtime_s=total, workers=workers,
                  icp_cache_hits=hits, map="map.html", dropped=dropped, **geo)
    lines = [f"{'estimator':16s} {'ATE RMSE [m]':>12s} {'RPE [m]':>9s} {'runtime [s]':>11s}  note"]
    for e in ranked(entries):
        s = e.summary or {}
        a, r, t = (f"{s[k]:.3f}" if isinstance(s.get(k), float) else "–"
                   for k in ("ate_rmse_m", "rpe_rmse_m", "runtime_s"))
        note = "" if e.ok else f"failed: {e.error}" if e.error is not None else f"not run: {e.skipped}"
        lines.append(f"{e.name:16s} {a:>12s} {r:>9s} {t:>11s}  " + note)
    cached = f"; {hits} weighted-ICP matches shared between estimators" if hits else ""
    lines.append(f"wrote {len(files)} files to {args.out} (report.md) in {total:.1f} s{cached}")
    emit(args, obj, "\n".join(lines))
    return 0
