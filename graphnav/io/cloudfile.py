"""One point cloud from one file: PLY and PCD through open3d, KITTI Velodyne ``.bin`` (float32 x, y, z,
intensity). Returns (N, 3) float64 points; non-finite points are dropped.

open3d reads leniently (a truncated binary PLY comes back full length with a warning on stdout; a
PLY without y/z properties reads as zeros), so the header is checked here first (x, y, z present;
the declared count at most :data:`MAX_POINTS` and backed by the file's bytes or rows) and the count
open3d returns is checked against it: a bad file is a :class:`~graphnav.errors.LogError` naming
the file, never a silent or partial read, nor an allocation the file's size does not back.
open3d's own messages are silenced (they go to stdout, which the CLI's ``--json`` contract keeps
for the one JSON object).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import LogError, require

FORMATS = (".ply", ".pcd", ".bin")
_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
_MAX_HEADER = 1 << 16
MAX_POINTS = 50_000_000  # a declared count beyond this is refused before anything is allocated


def read_cloud(path: str | os.PathLike) -> NDArray[np.float64]:
    """(N, 3) points of a ``.ply``, ``.pcd`` or KITTI ``.bin`` file (see the module doc)."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in FORMATS:
        raise LogError(f"unknown point-cloud format {path.suffix!r} (known: {', '.join(FORMATS)})", file=str(path))
    size = path.stat().st_size  # FileNotFoundError for a missing file: the CLI names it
    if ext == ".bin":
        if size == 0 or size % 16:
            raise LogError(f"not a KITTI Velodyne scan: {size} bytes is not a positive multiple of 16 "
                           "(float32 x, y, z, intensity)", file=str(path))
        pts = np.fromfile(path, dtype="<f4").reshape(-1, 4)[:, :3].astype(float)
    else:
        declared = _ply_count(path, size) if ext == ".ply" else _pcd_count(path, size)
        pts = _open3d_read(path)
        if len(pts) != declared:
            raise LogError(f"header declares {declared} points, {len(pts)} could be read", file=str(path))
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        raise LogError("no finite points", file=str(path))
    return pts


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
