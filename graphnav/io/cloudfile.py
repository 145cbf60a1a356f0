"""One point cloud from one file: PLY through open3d, PCD through pypcd4 (the ``[pcd]`` extra), KITTI
Velodyne ``.bin`` (float32 x, y, z, intensity). Returns (N, 3) float64 points; non-finite points are
dropped. :func:`read_cloud_record` also returns the intensity (and ``ring`` of a PCD that has one) as a
:class:`~graphnav.log.Cloud`; :func:`read_cloud_dir` reads a folder of them (KITTI ``velodyne/``) as a
log, one cloud per file.

open3d reads leniently (a truncated binary PLY comes back full length with a warning on stdout; a
PLY without y/z properties reads as zeros), so the header is checked here first (x, y, z present;
the declared count at most :data:`MAX_POINTS` and backed by the file's bytes or rows) and the count
open3d returns is checked against it: a bad file is a :class:`~graphnav.errors.LogError` naming
the file, never a silent or partial read, nor an allocation the file's size does not back.
open3d's own messages are silenced (they go to stdout, which the CLI's ``--json`` contract keeps
for the one JSON object).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import LogError, require
from ..log import Cloud, Limits, NavLog, check_record, make_cloud

FORMATS = (".ply", ".pcd", ".bin")
_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
_MAX_HEADER = 1 << 16
MAX_CLOUD_BYTES = 256 << 20
"""The memory budget of one cloud: the (N, 3) float64 points it is read into (registration then takes
a few times this); a file that declares more is refused before anything is allocated."""
MAX_POINTS = MAX_CLOUD_BYTES // 24  # ~11.2 M points


def read_cloud(path: str | os.PathLike) -> NDArray[np.float64]:
    """(N, 3) points of a ``.ply``, ``.pcd`` or KITTI ``.bin`` file (see the module doc)."""
    return _read(Path(path))[0]


def read_cloud_record(path: str | os.PathLike, t: float = 0.0) -> Cloud:
    """One file as a :class:`~graphnav.log.Cloud` at time ``t`` (intensity from a KITTI ``.bin`` or a
    PCD ``intensity`` field, ``ring`` from a PCD ``ring`` field; PLY: points only)."""
    pts, inten, ring = _read(Path(path))
    return make_cloud(t, pts, inten, ring)


def _read(path: Path) -> tuple[NDArray[np.float64], NDArray | None, NDArray | None]:
    ext = path.suffix.lower()
    if ext not in FORMATS:
        raise LogError(f"unknown point-cloud format {path.suffix!r} (known: {', '.join(FORMATS)})", file=str(path))
    size = path.stat().st_size  # FileNotFoundError for a missing file: the CLI names it
    if ext == ".bin":
        if size == 0 or size % 16:
            raise LogError(f"not a KITTI Velodyne scan: {size} bytes is not a positive multiple of 16 "
                           "(float32 x, y, z, intensity)", file=str(path))
        if size // 16 > MAX_POINTS:
            raise LogError(f"{size // 16} points, more than {MAX_POINTS} (the {MAX_CLOUD_BYTES >> 20} MiB budget "
                           "of a cloud)", file=str(path))
        raw = np.fromfile(path, dtype="<f4").reshape(-1, 4)
        pts, inten, ring = raw[:, :3].astype(float), raw[:, 3], None
    elif ext == ".ply":
        declared = _ply_count(path, size)
        pts, inten, ring = _open3d_read(path), None, None
        if len(pts) != declared:
            raise LogError(f"header declares {declared} points, {len(pts)} could be read", file=str(path))
    else:
        declared = _pcd_count(path, size)
        pts, inten, ring = _pcd_read(path)
        if len(pts) != declared:
            raise LogError(f"header declares {declared} points, {len(pts)} could be read", file=str(path))
    keep = np.all(np.isfinite(pts), axis=1)
    if inten is not None:
        inten = inten[keep]
        if not np.all(np.isfinite(inten)):
            inten = None  # an intensity the file does not give for every point is not kept
    if len(pts) == 0 or not keep.any():
        raise LogError("no finite points", file=str(path))
    return pts[keep], inten, None if ring is None else ring[keep]


def _pcd_read(path: Path) -> tuple[NDArray[np.float64], NDArray | None, NDArray | None]:
    """x, y, z (and intensity, ring when present) of a PCD through pypcd4 (the header already checked)."""
    PointCloud = require("pypcd4", "reading PCD point-cloud files").PointCloud
    try:
        pc = PointCloud.from_path(path)
        pts = pc.numpy(("x", "y", "z")).astype(float)
        inten = pc.numpy(("intensity",))[:, 0].astype(np.float32) if "intensity" in pc.fields else None
        ring = pc.numpy(("ring",))[:, 0] if "ring" in pc.fields else None
    except Exception as exc:  # noqa: BLE001 - pypcd4 raises many types for a damaged file
        raise LogError(f"cannot read PCD: {exc.__class__.__name__}: {str(exc)[:160]}", file=str(path)) from None
    if ring is not None:
        if not np.all(np.isfinite(ring)) or np.any(ring < 0) or np.any(ring != np.round(ring)):
            raise LogError("ring field is not non-negative integers", file=str(path))
        ring = ring.astype(np.int64)
    return pts.reshape(-1, 3), inten, ring


def read_cloud_dir(path: str | os.PathLike, *, hz: float = 10.0, limits: Limits | None = None,
                   max_files: int = 1_000_000) -> NavLog:
    """A folder of clouds as a log (a KITTI odometry sequence: ``velodyne/*.bin`` and ``times.txt``):
    one ``cloud`` record per ``.bin``/``.pcd``/``.ply`` file in name order. Times come from a
    ``times.txt`` (one number per line, one line per file) in the folder or its parent when there is
    one, else ``i / hz`` (``meta["times"]`` says which)."""
    path = Path(path)
    d = path / "velodyne" if (path / "velodyne").is_dir() else path
    files = sorted(f for f in d.iterdir() if f.suffix.lower() in FORMATS and f.is_file())
    if not files:
        raise LogError("no .bin, .pcd or .ply point-cloud files", file=str(d))
    if len(files) > max_files:
        raise LogError(f"{len(files)} files, more than {max_files}", file=str(d))
    tfile = next((p for p in (d / "times.txt", d.parent / "times.txt", path / "times.txt") if p.is_file()), None)
    if tfile is not None:
        times = []
        for i, line in enumerate(tfile.read_text(encoding="utf-8").splitlines()[: len(files) + 1], start=1):
            if not line.strip():
                continue
            try:
                v = float(line.split()[0])
            except ValueError:
                raise LogError(f"not a number: {line[:40]!r}", file=str(tfile), line=i, field="t") from None
            if not math.isfinite(v):
                raise LogError("time must be finite", file=str(tfile), line=i, field="t")
            times.append(v)
        if len(times) < len(files):
            raise LogError(f"{len(times)} times for {len(files)} cloud files", file=str(tfile))
        source = str(tfile)
    else:
        times = [i / hz for i in range(len(files))]
        source = f"{hz:g} Hz (no times.txt)"
    recs = []
    for f, t in zip(files, times, strict=False):
        c = read_cloud_record(f, t)
        try:
            check_record(c, limits)
        except LogError as err:
            raise err.located(file=str(f)) from None
        recs.append(c)
    try:
        return NavLog(recs, [], {"source": str(path), "format": "cloud folder", "times": source,
                                 "frame": "sensor frame (docs/conventions.md)"})
    except LogError as err:
        raise err.located(file=str(tfile or d)) from None


def is_cloud_dir(path: Path) -> bool:
    """A folder (or its ``velodyne/`` subfolder) holding point-cloud files."""
    d = path / "velodyne" if (path / "velodyne").is_dir() else path
    return d.is_dir() and any(f.suffix.lower() in FORMATS for f in d.iterdir())


def _open3d_read(path: Path) -> NDArray[np.float64]:
    o3d = require("open3d", f"reading {path.suffix or 'this'} point-cloud files")
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        pc = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
    return np.asarray(pc.points, dtype=float).reshape(-1, 3)


def _header_lines(path: Path, last: str) -> tuple[list[str], int]:
    """ASCII header lines up to and including the one starting with ``last``; and its byte length."""
    with open(path, "rb") as fh:
        head = fh.read(_MAX_HEADER)
    lines: list[str] = []
    pos = 0
    while pos < len(head):
        end = head.find(b"\n", pos)
        if end < 0:
            break
        try:
            line = head[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise LogError(f"header line {len(lines) + 1} is not ASCII", file=str(path)) from None
        lines.append(line)
        pos = end + 1
        if line.split(" ")[0] == last:
            return lines, pos
    raise LogError(f"no '{last}' line in the first {_MAX_HEADER} bytes: not a valid header", file=str(path))


def _count_rows(path: Path, offset: int) -> int:
    """Lines after ``offset`` (a last line without its newline counts), read in 1 MB chunks."""
    rows, last = 0, b"\n"
    with open(path, "rb") as fh:
        fh.seek(offset)
        while chunk := fh.read(1 << 20):
            rows += chunk.count(b"\n")
            last = chunk[-1:]
    return rows + (last != b"\n")


def _ply_count(path: Path, size: int) -> int:
    """Vertex count of a PLY header, after checking it has x, y, z and, when binary, that the file
    is long enough for the elements up to the vertices."""
    lines, hlen = _header_lines(path, "end_header")
    if not lines or lines[0] != "ply":
        raise LogError("not a PLY file (first line is not 'ply')", file=str(path))
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for k, line in enumerate(lines[1:], start=2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info", "end_header"):
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3 and tok[2].isdigit():
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property" and elements and len(tok) >= 3:
            elements[-1][2].append(("list", tok[-1]) if tok[1] == "list" else (tok[1], tok[2]))
        else:
            raise LogError(f"header line {k} not understood: {line!r}", file=str(path))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise LogError(f"unknown PLY format {fmt!r}", file=str(path))
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise LogError("no 'vertex' element", file=str(path))
    vi = names.index("vertex")
    props = [p[1] for p in elements[vi][2]]
    missing = [c for c in "xyz" if c not in props]
    if missing:
        raise LogError(f"vertex element has no {', '.join(missing)} property", file=str(path))
    if elements[vi][1] > MAX_POINTS:
        raise LogError(f"the header declares {elements[vi][1]} vertices, more than {MAX_POINTS}", file=str(path))
    if fmt == "ascii":  # one line per element row
        need = sum(count for _, count, _ in elements[: vi + 1])
        rows = _count_rows(path, hlen)
        if rows < need:
            raise LogError(f"truncated: the header declares {elements[vi][1]} vertices ({need} rows), the file "
                           f"has {rows}", file=str(path))
    else:
        need = hlen
        for _, count, plist in elements[: vi + 1]:
            if any(t not in _PLY_SIZES for t, _ in plist):
                return elements[vi][1]  # list or unknown property before the vertices: size not fixed
            need += count * sum(_PLY_SIZES[t] for t, _ in plist)
        if size < need:
            raise LogError(f"truncated: the header declares {elements[vi][1]} vertices ({need} bytes with "
                           f"the header), the file has {size}", file=str(path))
    return elements[vi][1]


def _pcd_count(path: Path, size: int) -> int:
    """Point count of a PCD header, after checking it has x, y, z and, when binary, the length."""
    lines, hlen = _header_lines(path, "DATA")
    fields: dict[str, list[str]] = {}
    for line in lines:
        tok = line.split()
        if tok and not tok[0].startswith("#"):
            fields[tok[0].upper()] = tok[1:]
    names = fields.get("FIELDS", [])
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise LogError(f"FIELDS has no {', '.join(missing)}", file=str(path))
    try:
        n = int(fields["POINTS"][0]) if "POINTS" in fields else int(fields["WIDTH"][0]) * int(fields["HEIGHT"][0])
    except (KeyError, IndexError, ValueError):
        raise LogError("no valid POINTS (or WIDTH and HEIGHT) line", file=str(path)) from None
    if not 0 <= n <= MAX_POINTS:
        raise LogError(f"the header declares {n} points, not in [0, {MAX_POINTS}]", file=str(path))
    data = (fields.get("DATA") or [""])[0].lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise LogError(f"unknown PCD DATA {data!r}", file=str(path))
    if data == "ascii":
        rows = _count_rows(path, hlen)
        if rows < n:
            raise LogError(f"truncated: the header declares {n} points, the file has {rows} rows", file=str(path))
        return n
    try:
        sizes = [int(s) for s in fields["SIZE"]]
        counts = [int(c) for c in fields.get("COUNT", ["1"] * len(sizes))]
    except (KeyError, ValueError):
        raise LogError("no valid SIZE/COUNT lines", file=str(path)) from None
    row = sum(s * c for s, c in zip(sizes, counts, strict=False))
    if data == "binary":
        need = hlen + n * row
        if size < need:
            raise LogError(f"truncated: the header declares {n} points ({need} bytes with the header), the file "
                           f"has {size}", file=str(path))
    else:  # binary_compressed: uint32 compressed and uncompressed sizes, then the LZF block
        with open(path, "rb") as fh:
            fh.seek(hlen)
            head = fh.read(8)
        if len(head) < 8:
            raise LogError("truncated: no compressed-block sizes after the header", file=str(path))
        packed, unpacked = np.frombuffer(head, "<u4").tolist()
        if hlen + 8 + packed > size or unpacked != n * row:
            raise LogError(f"compressed block of {packed} bytes ({unpacked} unpacked) does not fit the file "
                           f"({size} bytes) or {n} points of {row} bytes", file=str(path))
    return n


def read_transform(path: str | os.PathLike) -> NDArray[np.float64]:
    """A 4x4 rigid transform from a text file of 16 numbers (or 12: the top 3x4 rows, KITTI style)."""
    path = Path(path)
    try:
        vals = np.array(path.read_text(encoding="utf-8").split(), dtype=float)
    except ValueError as err:
        raise LogError(f"not a transform: {err}", file=str(path)) from None
    except UnicodeDecodeError:
        raise LogError("not a text file", file=str(path)) from None
    if vals.size not in (12, 16):
        raise LogError(f"a transform needs 12 or 16 numbers, found {vals.size}", file=str(path))
    T = np.eye(4)
    T[: vals.size // 4] = vals.reshape(-1, 4)
    R = T[:3, :3]
    if not np.all(np.isfinite(T)) or np.abs(R.T @ R - np.eye(3)).max() > 1e-3 or np.linalg.det(R) <= 0:
        raise LogError("the rotation block is not a rotation (R'R != I or det <= 0)", file=str(path))
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise LogError("the last row is not 0 0 0 1", file=str(path))
    return T
