"""A compact binary log form: one ``.npz`` of column arrays, written with ``allow_pickle=False``.

Layout: ``<kind>/<field>`` arrays per record type (scan beams concatenated, with
``scan/offsets``), ``order`` (kind code of every record, in log order) so that ties in time
round-trip exactly, ``beacon_known/<field>``, and ``meta`` (a JSON string).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..errors import LogError
from ..log import RECORD_TYPES, SCALAR_FIELDS, KnownBeacon, NavLog, Record, Scan, check_record

KINDS = list(RECORD_TYPES)
FORMAT_VERSION = 1
OPTIONAL_COLUMNS = ("range_max",)  # added after version 1 files were written: NaN when absent


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
        if kind == "scan":
            lens = np.array([r.ranges.size for r in recs])
            arrays["scan/offsets"] = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
            arrays["scan/ranges"] = np.concatenate([r.ranges for r in recs]).astype(np.float32)
            arrays["scan/angles"] = np.concatenate([r.angles for r in recs]).astype(np.float32)
    if log.beacons_known:
        for name in ("id", "x", "y", "sigma"):
            vals = [getattr(b, name) for b in log.beacons_known]
            arrays[f"beacon_known/{name}"] = np.array(vals, dtype=str if name == "id" else float)
    meta = {k: v for k, v in log.meta.items() if k not in ("source",)}
    arrays["meta"] = np.array(json.dumps(meta))
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def _get(data: dict, key: str, path: Path, *, numeric: bool = True, integer: bool = False,
         length: int | None = None) -> np.ndarray:
    """A 1-D array from the archive, checked for kind and length; LogError naming it otherwise."""
    arr = data.get(key)
    if arr is None:
        raise LogError("missing array", file=str(path), field=key)
    ok_kind = (np.issubdtype(arr.dtype, np.integer) if integer else
               np.issubdtype(arr.dtype, np.number) and not np.issubdtype(arr.dtype, np.complexfloating)
               if numeric else arr.dtype.kind == "U")
    if arr.ndim != 1 or not ok_kind:
        raise LogError(f"expected a 1-D {'integer' if integer else 'numeric' if numeric else 'string'} array, "
                       f"got {arr.dtype} with shape {arr.shape}", file=str(path), field=key)
    if length is not None and arr.shape[0] != length:
        raise LogError(f"expected {length} values, got {arr.shape[0]}", file=str(path), field=key)
    return arr


def read_npz(path: str | Path) -> NavLog:
    """Read a log written by :func:`write_npz`. Errors name the file and the array."""
    path = Path(path)
    try:
        z = np.load(path, allow_pickle=False)
        data = {k: z[k] for k in z.files}
    except Exception as exc:  # numpy/zipfile raise many types for a corrupt archive
        raise LogError(f"not a graphnav npz log: {exc.__class__.__name__}: {exc}", file=str(path)) from None
    order = _get(data, "order", path, integer=True)
    meta_arr = data.get("meta", np.array("{}"))
    try:
        meta = json.loads(str(meta_arr.item())) if meta_arr.dtype.kind == "U" and meta_arr.ndim == 0 else None
    except json.JSONDecodeError:
        meta = None
    if not isinstance(meta, dict):
        raise LogError("meta must be a JSON object string", file=str(path), field="meta")
    meta["source"] = str(path)
    per_kind: dict[str, list[Record]] = {}
    for kind in KINDS:
        if f"{kind}/t" not in data:
            continue
        n = _get(data, f"{kind}/t", path).shape[0]
        cols = {name: _get(data, f"{kind}/{name}", path, numeric=name != "id", length=n).tolist()
                if f"{kind}/{name}" in data or name not in OPTIONAL_COLUMNS else [math.nan] * n
                for name in SCALAR_FIELDS[kind]}
        recs: list[Record] = []
        if kind == "scan":
            off = _get(data, "scan/offsets", path, integer=True, length=n + 1)
            rng = _get(data, "scan/ranges", path).astype(float)
            ang = _get(data, "scan/angles", path, length=rng.shape[0]).astype(float)
            if off[0] != 0 or np.any(np.diff(off) < 0) or off[-1] != rng.shape[0]:
                raise LogError("offsets must rise from 0 to the number of beams", file=str(path), field="scan/offsets")
            for i in range(n):
                recs.append(Scan(float(cols["t"][i]), rng[off[i]:off[i + 1]], ang[off[i]:off[i + 1]],
                                 float(cols["range_max"][i])))
        else:
            cls = RECORD_TYPES[kind]
            for i in range(n):
                recs.append(cls(**{k: (str(v[i]) if k == "id" else float(v[i])) for k, v in cols.items()}))
        for i, r in enumerate(recs):
            try:
                check_record(r)
            except LogError as err:
                raise LogError(f"record {i}: {err.message}", file=str(path), field=f"{kind}/{err.field}") from None
        per_kind[kind] = recs
    cursor = dict.fromkeys(per_kind, 0)
    records: list[Record] = []
    for c in order.tolist():
        k = KINDS[c] if 0 <= c < len(KINDS) else None
        if k is None or k not in per_kind or cursor[k] >= len(per_kind[k]):
            raise LogError("record order does not match the record arrays", file=str(path), field="order")
        records.append(per_kind[k][cursor[k]])
        cursor[k] += 1
    if any(cursor[k] != len(v) for k, v in per_kind.items()):
        raise LogError("record order does not match the record arrays", file=str(path), field="order")
    known = []
    if "beacon_known/id" in data:
        ids = _get(data, "beacon_known/id", path, numeric=False).tolist()
        xs, ys, sg = (_get(data, f"beacon_known/{f}", path, length=len(ids)) for f in ("x", "y", "sigma"))
        known = [KnownBeacon(str(ids[i]), float(xs[i]), float(ys[i]), float(sg[i])) for i in range(len(ids))]
        for b in known:
            try:
                check_record(b)
            except LogError as err:
                raise LogError(err.message, file=str(path), field=f"beacon_known/{err.field}") from None
    try:
        return NavLog(records, known, meta)
    except LogError as err:
        raise err.located(file=str(path)) from None
