"""``graphnav compare LOG --out DIR [--estimators a,b,...]``: every estimator the log can feed, side
by side — DIR/report.md, DIR/report.html (self-contained), PNG figures, DIR/<estimator>.tum and
DIR/truth.tum, DIR/map.html (the tracks, self-contained), and when the log has a geodetic origin every
track in WGS84: DIR/trajectory.geojson, .gpx, .kml. ``--holdout-gnss EVERY,LENGTH`` scores a log
without truth against GNSS fixes withheld from every estimator."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from .. import estimators
from ..evaluation.holdout import HoldoutSpec
from ..evaluation.pipeline import CompareOptions, run_compare
from ..io.outputs import OutDir
from . import _common as c


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="run several estimators on one log and write a report", description=__doc__)
    c.add_log_args(p)
    p.add_argument("--out", type=Path, required=True, help="output directory (report.md, *.png, *.tum)")
    c.add_overwrite_flag(p)
    c.add_drop_flag(p)
    p.add_argument("--estimators", "-e", default=None,
                   help="comma-separated names, LABEL=NAME to run one estimator twice under another label "
                        "(default: every estimator the log can feed); known: " + ", ".join(estimators.names()))
    p.add_argument("--option", "-O", action="append", metavar="ESTIMATOR.KEY=VALUE",
                   help="option for one estimator (or label), e.g. -O scan-to-map.backend=gicp; repeatable")
    c.add_compare_flags(p)
    c.add_json_flag(p)
    p.set_defaults(func=run)


def options(args: argparse.Namespace) -> CompareOptions:
    """The command line as one typed options object (a bad -O, name, kind or hold-out fails here)."""
    names = [n.strip() for n in args.estimators.split(",") if n.strip()] if args.estimators else None
    return CompareOptions(
        log=str(args.log), out=args.out, estimators=names, options=c.options_by_estimator(args),
        dropped=c.dropped_kinds(args), workers=args.workers, icp_cache=args.icp_cache, tiles=args.tiles,
        holdout=HoldoutSpec.parse(args.holdout_gnss) if args.holdout_gnss else None, lenient=args.lenient,
        read=c.log_options(args), command=shlex.join(["graphnav", *args.argv]) if hasattr(args, "argv") else None)


def run(args: argparse.Namespace) -> int:
    opts = options(args)
    opts.check()  # (before --out is touched)
    out = OutDir(args.out, command="compare", overwrite=args.overwrite)
    with out.discarded_on_error(), c.progress_callback(args, "compare") as progress:  # a failure leaves nothing
        outcome = run_compare(opts, out, progress)
    c.emit(args, outcome.json, outcome.text)
    return 0
