"""graphnav export LOG|RUN_DIR --to nmea|geojson|gpx|kml --out FILE: a track in WGS84 for chart
plotters and GIS.

A RUN_DIR (the --out of graphnav run: summary.json + trajectory.tum or .csv) exports the
estimator's trajectory, placed with the geodetic origin run recorded in summary.json. A LOG is not run:
its truth is exported (--source truth, the default when it has one) or its GNSS fixes (--source
gnss: positions only, no heading), placed with the log's own origin (meta["origin"]). Without a
geodetic origin nothing is written: a clear error (an origin is never invented).

--to nmea writes, per pose, GGA (position), RMC (position, SOG, COG, date), HDT (heading) and VTG
(COG, SOG) built by pynmea2, with SOG/COG from the step to the next pose; --to geojson|gpx|kml as
graphnav run --out writes them (graphnav.io.geo_out).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GraphnavError
from ._common import add_date_flag, log_options

FORMATS = ("nmea", "geojson", "gpx", "kml")
NMEA_SENTENCES = ("GGA", "RMC", "HDT", "VTG")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a run's trajectory or a log's truth/GNSS as NMEA, GeoJSON, GPX or KML",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", metavar="LOG|RUN_DIR", help="a log, or the --out directory of graphnav run")
    p.add_argument("--to", choices=FORMATS, default=None,
                   help="output format (default: from the --out file's suffix: .nmea, .geojson, .gpx, .kml)")
    p.add_argument("--out", type=Path, required=True, metavar="FILE", help="the file to write (atomically)")
    p.add_argument("--source", choices=("truth", "gnss"), default=None,
                   help="for a LOG: export its truth or its GNSS fixes (default: the truth when it has one)")
    p.add_argument("--overwrite", action="store_true", help="replace FILE when it exists")
    p.add_argument("--lenient", action="store_true", help="for a LOG: skip malformed records (and count them)")
    add_date_flag(p)
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(func=run)


def _format(args: argparse.Namespace) -> str:
    if args.to is not None:
        return args.to
    suffix = args.out.suffix.lower().lstrip(".")
    fmt = {"json": "geojson", "txt": "nmea", "log": "nmea"}.get(suffix, suffix)
    if fmt not in FORMATS:
        raise GraphnavError(f"--to not given and the --out suffix {args.out.suffix!r} names no format: "
                            "give --to nmea|geojson|gpx|kml", where=str(args.out))
    return fmt


def is_run_dir(path: Path) -> bool:
    return path.is_dir() and (path / "summary.json").is_file() and any(
        (path / n).is_file() for n in ("trajectory.tum", "trajectory.csv"))


def _from_run_dir(path: Path) -> tuple[Any, Any, dict[str, Any]]:
    from ..geodesy import origin_frame
    from ..io.trajectory_csv import read_trajectory_csv
    from ..io.tum import read_tum

    try:
        summary = json.loads((path / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        raise GraphnavError(f"summary.json is not readable JSON ({type(exc).__name__}: {str(exc)[:80]})",
                            where=str(path / "summary.json")) from None
    name = str(summary.get("estimator", "trajectory")) if isinstance(summary, dict) else "trajectory"
    tum, csv = path / "trajectory.tum", path / "trajectory.csv"
    try:
        traj = read_tum(tum, name) if tum.is_file() else read_trajectory_csv(csv, name)
    except (OSError, ValueError, IndexError) as exc:
        raise GraphnavError(f"cannot read the trajectory ({exc})", where=str(tum if tum.is_file() else csv)) from None
    frame, reason = origin_frame({"origin": summary.get("origin")} if isinstance(summary, dict) else {})
    if frame is None:
        why = "records no geodetic origin (the log had none, or the run predates origins in summary.json)" \
            if not isinstance(summary, dict) or summary.get("origin") is None else f"has a bad origin: {reason}"
        raise GraphnavError(f"summary.json {why}: no WGS84 position can be given", where=str(path / "summary.json"))
    return traj, frame, {"kind": "run", "source": "trajectory", "track": name}


def _from_log(args: argparse.Namespace) -> tuple[Any, Any, dict[str, Any]]:
    from ..geodesy import origin_frame
    from ..io import load_log
    from ..trajectory import Trajectory

    log = load_log(args.input, lenient=args.lenient, **log_options(args))
    source = args.source or ("truth" if log.has_truth else "gnss")
    if source == "truth":
        if not log.has_truth:
            raise GraphnavError("the log has no truth records (try --source gnss)", where=str(args.input))
        traj = log.truth()
    else:
        g = log.columns("gnss")
        if not len(g["t"]):
            raise GraphnavError("the log has no GNSS fixes" + (" (try --source truth)" if log.has_truth else ""),
                                where=str(args.input))
        traj = Trajectory(g["t"], np.column_stack([g["x"], g["y"], np.full(len(g["t"]), np.nan)]), name="gnss")
    frame, reason = origin_frame(log.meta)
    if frame is None:
        raise GraphnavError(f"{reason}: no WGS84 position can be given", where=str(args.input))
    info = {"kind": "log", "source": source, "track": traj.name or source}
    if source == "gnss":
        info["heading"] = "none (GNSS fixes carry no heading: no HDT, no heading property)"
    return traj, frame, info


def run(args: argparse.Namespace) -> int:
    from ..io.geo_out import GeoTrack, check_track, origin_dict, render
    from ..io.nmea_out import trajectory_to_nmea
    from ..io.outputs import check_replaceable, write_text_atomic
    from ._common import emit

    fmt = _format(args)
    check_replaceable(args.out, overwrite=args.overwrite)
    src = Path(args.input)
    if is_run_dir(src):
        if args.source is not None:
            raise GraphnavError("--source applies to a LOG, not to a run directory", where=str(src))
        traj, frame, info = _from_run_dir(src)
    else:
        traj, frame, info = _from_log(args)
    if not len(traj):
        raise GraphnavError("nothing to export: the track is empty", where=str(src))
    check_track(traj, str(src))
    obj: dict[str, Any] = {"input": str(src), **info, "to": fmt, "out": str(args.out), "poses": len(traj),
                           "origin": origin_dict(frame)}
    if fmt == "nmea":
        lines = [s for _, s in trajectory_to_nmea(traj.t, traj.poses, frame, kinds=NMEA_SENTENCES)]
        text = "".join(s + "\r\n" for s in lines)
        obj["sentences"] = len(lines)
        obj["sentence_types"] = list(NMEA_SENTENCES)
    else:
        text = render([GeoTrack.from_trajectory(traj, frame, info["track"])], fmt)
    write_text_atomic(args.out, text)
    emit(args, obj, f"wrote {len(traj)} poses of {info['source']} ({info['track']}) as {fmt} to {args.out}")
    return 0
