"""Pick a reader or writer from a path: directory (marina, ROS 2 bag), .jsonl[.gz], .npz, ROS bags,
CARMEN logs (.clf[.gz]; .log[.gz] and .txt[.gz] when their first lines are CARMEN messages), NMEA 2000
text (.n2k, .raw, .data, .can [.gz]; .log/.txt whose first lines are N2K), Signal K deltas (.sk[.gz],
and .json/.jsonl/.log/.txt whose first line is a delta) and NMEA 0183 (.nmea[.gz]; other .log/.txt files)."""

from __future__ import annotations

import stat
from pathlib import Path

from ..errors import LogError
from ..log import Limits, NavLog

NMEA_SUFFIXES = (".nmea", ".nmea.gz", ".txt", ".log")
JSONL_SUFFIXES = (".jsonl", ".jsonl.gz", ".ndjson")
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
CARMEN_SUFFIXES = (".clf", ".clf.gz")
SNIFF_SUFFIXES = (".log", ".log.gz", ".txt", ".txt.gz")  # CARMEN, N2K, Signal K or NMEA, told apart by content
N2K_SUFFIXES = (".n2k", ".n2k.gz", ".raw", ".raw.gz", ".data", ".data.gz", ".can", ".can.gz")
SIGNALK_SUFFIXES = (".sk", ".sk.gz", ".signalk", ".signalk.gz")
SIGNALK_SNIFF = (".json", ".json.gz", *JSONL_SUFFIXES, ".jsonl.gz", *SNIFF_SUFFIXES)


def _head(p: Path, n: int = 8) -> list[str]:
    """The first ``n`` lines of a (gzipped) text file, "" where unreadable (the readers say why)."""
    from .textlines import Lines

    out: list[str] = []
    try:
        for _, raw in Lines(p, lenient=True, quiet=True, max_line=65536):
            out.append(raw.decode("utf-8", "replace"))
            if len(out) >= n:
                break
    except Exception:  # noqa: BLE001 - a probe only: the chosen reader reports the problem
        return out
    return out


def load_log(path: str | Path, *, lenient: bool = False, limits: Limits | None = None, **options) -> NavLog:
    """Read any supported log. ``lenient`` skips (and counts) malformed or physically invalid
    records (``limits``, :class:`graphnav.log.Limits`; default :func:`graphnav.log.default_limits`)
    where the format has records to skip; ``date`` (``"YYYY-MM-DD"``) is the day of an NMEA log
    without a date of its own (ignored for other formats, whose times are complete); other
    ``options`` go to the chosen reader."""
    p = Path(path)
    name = p.name.lower()
    if not p.exists():
        raise LogError("no such file or directory", file=str(p))
    if not (p.is_dir() or p.is_file() or stat.S_ISFIFO(p.stat().st_mode)):
        raise LogError("not a regular file, directory or pipe (a device or socket has no end)", file=str(p))
    day = options.pop("date", None)  # the day of a dateless NMEA 0183 / time-of-day NMEA 2000 log
    columns = options.pop("columns", None)  # a CSV's column mapping (the only reader that takes one)
    if name.endswith((".csv", ".csv.gz", ".tsv", ".tsv.gz")):
        from .csv_table import read_csv_log

        return read_csv_log(p, columns=columns, lenient=lenient, limits=limits)
    if columns is not None:
        raise LogError("--columns maps the columns of a CSV log (.csv, .tsv); this is not one", file=str(p),
                       field="--columns")
    if day is not None and not (name.endswith(NMEA_SUFFIXES) or name.endswith(SNIFF_SUFFIXES)
                                or name.endswith(N2K_SUFFIXES)):
        day = None
    if p.is_dir():
        from .marina import is_marina_dir, read_marina

        if is_marina_dir(p):
            return read_marina(p, limits=limits, **options)
        from .mrclam import is_mrclam_dir, read_mrclam

        if is_mrclam_dir(p):
            if "robot" not in options:
                raise LogError("an MRCLAM dataset directory: say which robot (load_log(dir, robot=N), or "
                               "graphnav convert mrclam DIR --robot N --out LOG)", file=str(p))
            return read_mrclam(p, lenient=lenient, limits=limits, **options)
        if (p / "metadata.yaml").exists():
            from .rosbag import read_bag

            return read_bag(p, lenient=lenient, limits=limits, **options)
        from .cloudfile import is_cloud_dir, read_cloud_dir

        if is_cloud_dir(p):
            return read_cloud_dir(p, limits=limits, **options)
        raise LogError("directory is neither a marina dataset (ranges.mat, angles.mat, gps.mat), an MRCLAM "
                       "dataset (Barcodes.dat, Landmark_Groundtruth.dat), a ROS 2 bag (metadata.yaml) nor a "
                       "folder of point clouds (.bin, .pcd, .ply; KITTI velodyne/)", file=str(p))
    if name.endswith(SIGNALK_SUFFIXES) or (name.endswith(SIGNALK_SNIFF) and p.is_file()):
        from .signalk import is_signalk_text, read_signalk

        if name.endswith(SIGNALK_SUFFIXES) or is_signalk_text(_head(p)):
            return read_signalk(p, lenient=lenient, limits=limits, **options)
    if name.endswith(N2K_SUFFIXES) or (name.endswith(SNIFF_SUFFIXES) and p.is_file()):
        from .n2k import is_n2k_text, read_n2k

        if name.endswith(N2K_SUFFIXES) or is_n2k_text(_head(p)):
            return read_n2k(p, lenient=lenient, limits=limits, date=day, **options)
    if name.endswith(JSONL_SUFFIXES):
        from .jsonl import read_jsonl

        return read_jsonl(p, lenient=lenient, limits=limits)
    if name.endswith(".npz"):
        from .npz import read_npz

        return read_npz(p, lenient=lenient, limits=limits, **{k: v for k, v in options.items() if k == "max_bytes"})
    if name.endswith(CARMEN_SUFFIXES) or name.endswith(SNIFF_SUFFIXES):
        from .carmen import is_carmen, read_carmen

        if name.endswith(CARMEN_SUFFIXES) or is_carmen(p):
            return read_carmen(p, lenient=lenient, limits=limits, **options)
    if name.endswith(NMEA_SUFFIXES) or name.endswith(SNIFF_SUFFIXES):
        from .nmea import read_nmea

        return read_nmea(p, lenient=lenient, limits=limits, date=day, **options)
    if name.endswith(BAG_SUFFIXES):
        from .rosbag import read_bag

        return read_bag(p, lenient=lenient, limits=limits, **options)
    raise LogError("unknown log type (expected a marina directory, .jsonl[.gz], .npz, .nmea, a CARMEN .log/.clf, "
                   "NMEA 2000 text (.n2k, .raw, .data), Signal K deltas (.sk), .csv/.tsv (with --columns) or a ROS "
                   "bag)",
                   file=str(p))


def save_log(log: NavLog, path: str | Path, *, overwrite: bool = True, flag: str = "--out") -> None:
    """Write a log as JSON Lines (``.jsonl``/``.jsonl.gz``) or binary (``.npz``), atomically (a
    temporary file renamed onto ``path``: a crash leaves the earlier file, never half of one). Only a
    regular file is replaced, and only with ``overwrite`` (a :class:`GraphnavError` naming ``flag``)."""
    from .outputs import atomic_path, check_replaceable

    p = Path(path)
    name = p.name.lower()
    if not name.endswith((".npz", *JSONL_SUFFIXES)):
        raise LogError("can write .jsonl, .jsonl.gz or .npz", file=str(p))
    check_replaceable(p, overwrite=overwrite, flag=flag)
    with atomic_path(p) as tmp:
        if name.endswith(".npz"):
            from .npz import write_npz

            write_npz(log, tmp)
        else:
            from .jsonl import write_jsonl

            write_jsonl(log, tmp)
