"""``graphnav convert FORMAT INPUT --out LOG``: a dataset in its own format -> a graphnav log.

* ``carmen FILE.log[.gz]``: a CARMEN log's laser scans (FLASER, ROBOTLASER1 or RAWLASER1) and,
  from a corrected log, the laser poses as ``truth`` (docs/datasets.md, graphnav/io/carmen.py).
* ``mrclam DIR --robot N``: one robot of a UTIAS MRCLAM dataset: odometry, landmark sightings as
  beacon observations, Vicon truth and a pose prior at the first truth pose (graphnav/io/mrclam.py).

The output is JSON Lines (``.jsonl[.gz]``) or ``.npz``. ``--json`` prints one object: the
records written per type and what was dropped or skipped.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ._common import add_json_flag, emit


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("convert", help="convert a CARMEN log or an MRCLAM dataset into a graphnav log",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    fmt = p.add_subparsers(dest="format", metavar="FORMAT", required=True)
    c = fmt.add_parser("carmen", help="a CARMEN text log (.log, .clf, optionally .gz)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("input", type=Path, help="the CARMEN log")
    c.add_argument("--time", choices=("auto", "log", "index"), default="auto",
                   help="auto (default): the messages' timestamps when they increase strictly, else scan "
                        "index x --scan-dt; log: the timestamps (backwards = error); index: always the index")
    c.add_argument("--scan-dt", type=float, default=1.0, metavar="S",
                   help="seconds between scans when the time is the scan index (default 1)")
    c.add_argument("--max-range", type=float, default=None, metavar="M",
                   help="returns >= M are missing (default: the message's max_range; FLASER: the "
                        "detected saturation value)")
    c.add_argument("--no-truth", action="store_true",
                   help="do not write the laser poses as truth (for raw, uncorrected logs)")
    _common(c)
    c.set_defaults(func=run_carmen)
    m = fmt.add_parser("mrclam", help="one robot of a UTIAS MRCLAM dataset directory", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    m.add_argument("input", type=Path, help="the dataset directory (Barcodes.dat, RobotN_*.dat[.gz], ...)")
    m.add_argument("--robot", type=int, required=True, metavar="N", help="robot number (1-5)")
    m.add_argument("--charted", action="store_true",
                   help="also write the landmark ground truth as charted beacons (beacon_known, sigma = the "
                        "larger std-dev); by default the landmarks are left for the estimator to map")
    _common(m)
    m.set_defaults(func=run_mrclam)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace --out when it is an existing regular file (it is replaced atomically)")
    p.add_argument("--lenient", action="store_true", help="skip malformed lines (and count them)")
    add_json_flag(p)


def _write(args: argparse.Namespace, log, extra: dict[str, Any]) -> int:
    from ..io import save_log

    save_log(log, args.out, overwrite=args.overwrite)
    out: dict[str, Any] = {"format": args.format, "input": str(args.input), "out": str(args.out),
                           "records": log.counts(), "t0": log.t0, "t1": log.t1, **extra}
    for key in ("skipped", "skipped_errors"):
        if key in log.meta:
            out[key] = log.meta[key]
    human = "\n".join([f"{args.input} -> {args.out}: {len(log)} records, t = {log.t0} .. {log.t1} s"]
                      + [f"  {k:12s} {v}" for k, v in out["records"].items()]
                      + [f"  {k}: {v}" for k, v in extra.items()])
    emit(args, out, human)
    return 0


def _prepare_out(args: argparse.Namespace) -> None:
    """``--out`` refused before any reading when it exists without ``--overwrite`` or is no regular file."""
    from ..io.outputs import check_replaceable, ensure_dir

    ensure_dir(args.out.parent, "--out (its directory)")
    check_replaceable(args.out, overwrite=args.overwrite)


def run_carmen(args: argparse.Namespace) -> int:
    from ..config import Range, number
    from ..io.carmen import read_carmen

    number("--scan-dt", args.scan_dt, Range(lo=0.0, hi=3600.0, lo_open=True))
    if args.max_range is not None:
        number("--max-range", args.max_range, Range(lo=0.0, hi=1e4, lo_open=True))
    _prepare_out(args)

    log = read_carmen(args.input, lenient=args.lenient, truth=not args.no_truth, time=args.time,
                      scan_dt=args.scan_dt, max_range=args.max_range)
    extra = {k: log.meta[k] for k in ("messages", "ignored", "unused", "time", "max_range", "missing_returns",
                                      "dead_beams") if k in log.meta}
    return _write(args, log, extra)


def run_mrclam(args: argparse.Namespace) -> int:
    from ..io.mrclam import read_mrclam

    _prepare_out(args)

    log = read_mrclam(args.input, args.robot, lenient=args.lenient, charted=args.charted)
    dropped = log.meta["dropped"]
    extra = {"robot": args.robot, "sightings_kept": log.meta["sightings_kept"],
             "dropped_robot": sum(dropped["robot"].values()),
             "dropped_unknown_barcode": sum(dropped["unknown_barcode"].values()), "dropped": dropped,
             "charted": args.charted}
    return _write(args, log, extra)
