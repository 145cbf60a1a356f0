"""A compact binary log form: one ``.npz`` of column arrays, written with ``allow_pickle=False``.

Layout: ``<kind>/<field>`` arrays per record type (scan beams concatenated, with
``scan/offsets``; cloud points concatenated as one flat float32 ``cloud/xyz`` split by
``cloud/offsets`` (in points), ``cloud/intensity`` float32 and ``cloud/ring`` uint16 over the same
points, ``cloud/flags`` per cloud: bit 0 intensity given, bit 1 ring given),
``<kind>/source`` (strings, only when a record of that kind states its source), ``order`` (kind code
of every record, in log order) so that ties in time
round-trip exactly, ``beacon_known/<field>``, and ``meta`` (a JSON string).
"""

from __future__ import annotations

import dataclasses
import json
import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib import format as npformat

from ..errors import LogError
from ..log import (
    OPTIONAL_SCALARS,
    RECORD_TYPES,
    SCALAR_FIELDS,
    SOURCED_KINDS,
    Cloud,
    KnownBeacon,
    Limits,
    NavLog,
    Record,
    Scan,
    check_record,
    suspect_rows,
)

KINDS = list(RECORD_TYPES)
FORMAT_VERSION = 1
# added after version 1 files were written: NaN when absent
OPTIONAL_COLUMNS = ("range_max", "roll", "pitch", "az", "wx", "wy")
KNOWN_MEMBERS = frozenset(
    ["version", "order", "meta", "scan/offsets", "scan/ranges", "scan/angles"]
    + ["cloud/offsets", "cloud/xyz", "cloud/intensity", "cloud/ring", "cloud/flags"]
    + [f"{k}/{f}" for k in KINDS for f in SCALAR_FIELDS[k]]
    + [f"{k}/source" for k in SOURCED_KINDS]
    + [f"beacon_known/{f}" for f in ("id", "x", "y", "sigma")])
#: Default bound on the decoded size of the arrays a log declares [bytes]: 4 GiB, a day of 10 Hz
#: 360-beam scans (float32 ranges + angles, ~2.5 GB) with room to spare. ``read_npz(max_bytes=)``.
MAX_DECODED_BYTES = 4 << 30


def write_npz(log: NavLog, path: str | Path) -> None:
    """Write the log to ``path`` (compressed npz)."""
    arrays: dict[str, np.ndarray] = {"version": np.array(FORMAT_VERSION)}
    code = {k: i for i, k in enumerate(KINDS)}
    arrays["order"] = np.array([code[r.kind] for r in log.records], dtype=np.int8)
    for kind in KINDS:
        recs = log.of(kind)
        if not recs:
            continue
        for name in SCALAR_FIELDS[kind]:
            vals = [getattr(r, name) for r in recs]
            arrays[f"{kind}/{name}"] = np.array(vals, dtype=str if name == "id" else float)
        if kind in SOURCED_KINDS and any(r.source for r in recs):
            arrays[f"{kind}/source"] = np.array([r.source for r in recs], dtype=str)
        if kind == "scan":
            lens = np.array([r.ranges.size for r in recs])
            arrays["scan/offsets"] = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
            arrays["scan/ranges"] = np.concatenate([r.ranges for r in recs]).astype(np.float32)
            arrays["scan/angles"] = np.concatenate([r.angles for r in recs]).astype(np.float32)
        if kind == "cloud":
            _write_clouds(recs, arrays)
    if log.beacons_known:
        for name in ("id", "x", "y", "sigma"):
            vals = [getattr(b, name) for b in log.beacons_known]
            arrays[f"beacon_known/{name}"] = np.array(vals, dtype=str if name == "id" else float)
    meta = {k: v for k, v in log.meta.items() if k not in ("source",)}
    arrays["meta"] = np.array(json.dumps(meta))
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def _write_clouds(recs: list[Cloud], arrays: dict[str, np.ndarray]) -> None:
    lens = np.array([len(r) for r in recs], dtype=np.int64)
    arrays["cloud/offsets"] = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
    arrays["cloud/xyz"] = np.concatenate([r.points.ravel() for r in recs]).astype(np.float32)
    flags = np.array([(r.intensity is not None) | ((r.ring is not None) << 1) for r in recs], dtype=np.int8)
    arrays["cloud/flags"] = flags
    if np.any(flags & 1):
        arrays["cloud/intensity"] = np.concatenate(
            [r.intensity if r.intensity is not None else np.zeros(len(r), np.float32) for r in recs])
    if np.any(flags & 2):
        arrays["cloud/ring"] = np.concatenate(
            [r.ring if r.ring is not None else np.zeros(len(r), np.uint16) for r in recs]).astype(np.uint16)


def _read_clouds(data: _Archive, path: Path, ts: list[float], roll: list[float], pitch: list[float]
                 ) -> list[Record | None]:
    """The clouds: offsets checked (rising from 0) and every array's length checked against them from
    its header before its data is read."""
    n = len(ts)
    off = _get(data, "cloud/offsets", path, integer=True, length=n + 1)
    if (off[0] != 0 or np.any(np.diff(off) < 0)):
        raise LogError("offsets must rise from 0 to the number of points", file=str(path), field="cloud/offsets")
    m = int(off[-1])
    xyz = _get(data, "cloud/xyz", path, length=3 * m).astype(np.float32, copy=False).reshape(-1, 3)
    flags = _get(data, "cloud/flags", path, integer=True, length=n)
    inten = _get(data, "cloud/intensity", path, length=m).astype(np.float32, copy=False) if np.any(flags & 1) else None
    ring = _get(data, "cloud/ring", path, integer=True, length=m) if np.any(flags & 2) else None
    if ring is not None and (ring.dtype != np.uint16):
        raise LogError(f"expected uint16, got {ring.dtype}", file=str(path), field="cloud/ring")
    out: list[Record | None] = []
    for i in range(n):
        a, b = int(off[i]), int(off[i + 1])
        out.append(Cloud(float(ts[i]), xyz[a:b], inten[a:b] if inten is not None and flags[i] & 1 else None,
                         ring[a:b] if ring is not None and flags[i] & 2 else None, float(roll[i]), float(pitch[i])))
    return out


class _Archive:
    """The members of a graphnav ``.npz`` that the reader uses, read one at a time on demand.

    Members with other names are never decompressed. The declared (zip header) sizes of the known
    members must add up to at most ``max_bytes``, and each member's array header must fit in its
    declared size, before any array data is read; every read array is exactly the size its header
    states (numpy preallocates it and streams the member into it)."""

    def __init__(self, path: Path, max_bytes: int) -> None:
        self.path = path
        try:
            self.zf = zipfile.ZipFile(path)
            infos = {i.filename: i for i in self.zf.infolist()}
        except Exception as exc:  # zipfile raises many types for a damaged archive
            raise LogError(f"not a graphnav npz log: {exc.__class__.__name__}: {str(exc)[:200]}",
                           file=str(path)) from None
        self.info = {k: infos[k + ".npy"] for k in KNOWN_MEMBERS if k + ".npy" in infos}
        declared = sum(i.file_size for i in self.info.values())
        if declared > max_bytes:
            raise LogError(f"its arrays declare {declared / 2**20:.0f} MiB decoded, more than the "
                           f"{max_bytes / 2**20:.0f} MiB allowed (max_bytes)", file=str(path))

    def close(self) -> None:
        self.zf.close()

    def __contains__(self, key: str) -> bool:
        return key in self.info

    def header(self, key: str) -> tuple[tuple[int, ...], np.dtype]:
        """Shape and dtype from the member's ``.npy`` header (no array data read)."""
        zi = self.info[key]
        try:
            with self.zf.open(zi) as fp:
                version = npformat.read_magic(fp)
                if version == (1, 0):
                    shape, _, dtype = npformat.read_array_header_1_0(fp)
                else:
                    shape, _, dtype = npformat.read_array_header_2_0(fp)
        except Exception as exc:  # noqa: BLE001 - a damaged member: many exception types
            raise LogError(f"bad array header: {exc.__class__.__name__}: {str(exc)[:120]}", file=str(self.path),
                           field=key) from None
        if dtype.hasobject or math.prod(shape) * dtype.itemsize > zi.file_size:
            raise LogError(f"array header ({dtype}, shape {shape}) does not fit the member's "
                           f"{zi.file_size} bytes", file=str(self.path), field=key)
        return shape, dtype

    def read(self, key: str) -> np.ndarray:
        self.header(key)
        try:
            with self.zf.open(self.info[key]) as fp:
                return npformat.read_array(fp, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - CRC error, truncated member, ...
            raise LogError(f"cannot read array: {exc.__class__.__name__}: {str(exc)[:120]}",
                           file=str(self.path), field=key) from None


def _get(data: _Archive, key: str, path: Path, *, numeric: bool = True, integer: bool = False,
         length: int | None = None) -> np.ndarray:
    """A 1-D array from the archive, checked for kind and length (from its header, before its data
    is read); LogError naming it otherwise."""
    if key not in data:
        raise LogError("missing array", file=str(path), field=key)
    shape, dtype = data.header(key)
    ok_kind = (np.issubdtype(dtype, np.integer) if integer else
               np.issubdtype(dtype, np.number) and not np.issubdtype(dtype, np.complexfloating)
               if numeric else dtype.kind == "U")
    if len(shape) != 1 or not ok_kind:
        raise LogError(f"expected a 1-D {'integer' if integer else 'numeric' if numeric else 'string'} array, "
                       f"got {dtype} with shape {shape}", file=str(path), field=key)
    if length is not None and shape[0] != length:
        raise LogError(f"expected {length} values, got {shape[0]}", file=str(path), field=key)
    return data.read(key)


def read_npz(path: str | Path, *, max_bytes: int = MAX_DECODED_BYTES, lenient: bool = False,
             limits: Limits | None = None) -> NavLog:
    """Read a log written by :func:`write_npz`. Errors name the file and the array.

    Only the members the format defines are read (one at a time, each checked against its header
    first); ``max_bytes`` bounds their total declared decoded size (:class:`_Archive`). Records
    are checked by :func:`graphnav.log.check_record` (``limits``); with ``lenient`` an invalid
    record is skipped and counted (``meta["skipped"]``, ``meta["skipped_errors"]``) instead."""
    path = Path(path)
    data = _Archive(path, max_bytes)
    try:
        return _read(data, path, lenient, limits)
    finally:
        data.close()


def _init_fields(cls: type) -> list[str]:
    """The names of a record type's ``__init__`` parameters, in order."""
    return [f.name for f in dataclasses.fields(cls) if f.init]


def _in_order(order: np.ndarray, per_kind: dict[str, list[Record | None]], path: Path, skipped: bool) -> list[Record]:
    """The records of ``per_kind`` interleaved as ``order`` (kind indices) says, those skipped (``None``) left
    out; a LogError unless ``order`` takes each kind's records exactly."""
    bad = LogError("record order does not match the record arrays", file=str(path), field="order")
    if order.size and (order.min() < 0 or order.max() >= len(KINDS)):
        raise bad
    counts = np.bincount(order.astype(np.int64), minlength=len(KINDS))
    if any(int(counts[i]) != len(per_kind.get(k, ())) for i, k in enumerate(KINDS)):
        raise bad
    nexts = [iter(per_kind.get(k, ())).__next__ for k in KINDS]
    records = [nexts[c]() for c in order.tolist()]
    return [r for r in records if r is not None] if skipped else records


def _read(data: _Archive, path: Path, lenient: bool, limits: Limits | None) -> NavLog:
    order = _get(data, "order", path, integer=True)
    meta_arr = data.read("meta") if "meta" in data else np.array("{}")
    try:
        meta = json.loads(str(meta_arr.item())) if meta_arr.dtype.kind == "U" and meta_arr.ndim == 0 else None
    except (ValueError, RecursionError):  # JSONDecodeError, or a > 4300-digit integer
        meta = None
    if not isinstance(meta, dict):
        raise LogError("meta must be a JSON object string", file=str(path), field="meta")
    meta["source"] = str(path)
    per_kind: dict[str, list[Record | None]] = {}
    skipped: list[str] = []
    for kind in KINDS:
        if f"{kind}/t" not in data:
            continue
        n = _get(data, f"{kind}/t", path, length=int(np.count_nonzero(order == KINDS.index(kind)))).shape[0]
        optional = OPTIONAL_COLUMNS + OPTIONAL_SCALARS[kind]
        cols: dict[str, Any] = {
            name: _get(data, f"{kind}/{name}", path, numeric=name != "id", length=n)
            if f"{kind}/{name}" in data or name not in optional else np.full(n, math.nan)
            for name in SCALAR_FIELDS[kind]}
        cols = {k: [str(x) for x in v.tolist()] if k == "id" else v.astype(float) for k, v in cols.items()}
        suspects: np.ndarray | None = None  # rows check_record could reject (None: check every row)
        recs: list[Record | None] = []
        if kind == "scan":
            off = _get(data, "scan/offsets", path, integer=True, length=n + 1)
            if off[0] != 0 or np.any(np.diff(off) < 0):
                raise LogError("offsets must rise from 0 to the number of beams", file=str(path), field="scan/offsets")
            rng = _get(data, "scan/ranges", path, length=int(off[-1])).astype(float)
            ang = _get(data, "scan/angles", path, length=rng.shape[0]).astype(float)
            for i in range(n):
                recs.append(Scan(float(cols["t"][i]), rng[off[i]:off[i + 1]], ang[off[i]:off[i + 1]],
                                 float(cols["range_max"][i])))
            # the scans check_record could reject: a scalar field, or a beam without a finite angle (1-D
            # ranges and angles of one length by construction)
            suspects = suspect_rows(Scan, {"t": cols["t"], "range_max": cols["range_max"]}, limits)
            no_angle = np.flatnonzero(~np.isfinite(ang))
            suspects[np.searchsorted(off, no_angle, side="right") - 1] = True
        elif kind == "cloud":
            recs = _read_clouds(data, path, cols["t"], cols["roll"], cols["pitch"])
        else:
            cls = RECORD_TYPES[kind]
            if f"{kind}/source" in data and kind in SOURCED_KINDS:
                cols["source"] = [str(x) for x in _get(data, f"{kind}/source", path, numeric=False, length=n).tolist()]
            suspects = suspect_rows(cls, cols, limits)
            names = list(cols)
            rows = zip(*(c if isinstance(c, list) else c.tolist() for c in cols.values()), strict=True)
            if names == _init_fields(cls)[:len(names)]:  # the columns in the record's field order: positional
                recs = [cls(*row) for row in rows]  # (no keyword dict per record: 80 000 records of a log)
            else:
                recs = [cls(**dict(zip(names, row, strict=True))) for row in rows]
        for i in range(len(recs)) if suspects is None else np.flatnonzero(suspects).tolist():
            r = recs[i]
            try:
                check_record(r, limits)
            except LogError as err:
                err = LogError(f"record {i}: {err.message}", file=str(path), field=f"{kind}/{err.field}")
                if not lenient:
                    raise err from None
                skipped.append(str(err))
                recs[i] = None
        per_kind[kind] = recs
    records = _in_order(order, per_kind, path, bool(skipped))
    known = []
    if "beacon_known/id" in data:
        ids = _get(data, "beacon_known/id", path, numeric=False).tolist()
        xs, ys, sg = (_get(data, f"beacon_known/{f}", path, length=len(ids)) for f in ("x", "y", "sigma"))
        known = [KnownBeacon(str(ids[i]), float(xs[i]), float(ys[i]), float(sg[i])) for i in range(len(ids))]
        for b in known:
            try:
                check_record(b, limits)
            except LogError as err:
                raise LogError(err.message, file=str(path), field=f"beacon_known/{err.field}") from None
    if lenient:
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    try:
        return NavLog(records, known, meta).mark_checked(limits)
    except LogError as err:
        raise err.located(file=str(path)) from None
