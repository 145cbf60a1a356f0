"""A compact binary log form: one ``.npz`` of column arrays, written with ``allow_pickle=False``.

Layout: ``<kind>/<field>`` arrays per record type (scan beams concatenated, with
``scan/offsets``), ``order`` (kind code of every record, in log order) so that ties in time
round-trip exactly, ``beacon_known/<field>``, and ``meta`` (a JSON string).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..errors import LogError
from ..log import RECORD_TYPES, SCALAR_FIELDS, KnownBeacon, NavLog, Record, Scan, check_record

KINDS = list(RECORD_TYPES)
FORMAT_VERSION = 1


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


def read_npz(path: str | Path) -> NavLog:
    """Read a log written by :func:`write_npz`. Errors name the file and the array."""
    path = Path(path)
    try:
        z = np.load(path, allow_pickle=False)
        data = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise LogError(f"not a graphnav npz log: {exc}", file=str(path)) from None
    if "order" not in data:
        raise LogError("missing array", file=str(path), field="order")
    try:
        meta = json.loads(str(data.get("meta", "{}")))
    except json.JSONDecodeError:
        raise LogError("meta is not JSON", file=str(path), field="meta") from None
    meta["source"] = str(path)
    per_kind: dict[str, list[Record]] = {}
    for kind in KINDS:
        key_t = f"{kind}/t"
        if key_t not in data:
            continue
        n = data[key_t].shape[0]
        cols = {}
        for name in SCALAR_FIELDS[kind]:
            arr = data.get(f"{kind}/{name}")
            if arr is None or arr.shape != (n,):
                raise LogError(f"missing or of the wrong length (expected {n})", file=str(path),
                               field=f"{kind}/{name}")
            cols[name] = arr.tolist()
        recs: list[Record] = []
        if kind == "scan":
            off = data.get("scan/offsets")
            rng, ang = data.get("scan/ranges"), data.get("scan/angles")
            if off is None or rng is None or ang is None or off.shape != (n + 1,) or rng.shape != ang.shape \
                    or off[-1] != rng.shape[0]:
                raise LogError("scan arrays inconsistent", file=str(path), field="scan/offsets")
            rng, ang = rng.astype(float), ang.astype(float)
            for i in range(n):
                recs.append(Scan(float(cols["t"][i]), rng[off[i]:off[i + 1]], ang[off[i]:off[i + 1]]))
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
    order = data["order"]
    cursor = dict.fromkeys(per_kind, 0)
    records: list[Record] = []
    for c in order.tolist():
        if not 0 <= c < len(KINDS) or KINDS[c] not in per_kind or cursor[KINDS[c]] >= len(per_kind[KINDS[c]]):
            raise LogError("record order does not match the record arrays", file=str(path), field="order")
        k = KINDS[c]
        records.append(per_kind[k][cursor[k]])
        cursor[k] += 1
    if any(cursor[k] != len(v) for k, v in per_kind.items()):
        raise LogError("record order does not match the record arrays", file=str(path), field="order")
    known = []
    if "beacon_known/id" in data:
        ids = data["beacon_known/id"].tolist()
        known = [KnownBeacon(str(ids[i]), float(data["beacon_known/x"][i]), float(data["beacon_known/y"][i]),
                             float(data["beacon_known/sigma"][i])) for i in range(len(ids))]
    try:
        return NavLog(records, known, meta)
    except LogError as err:
        raise err.located(file=str(path)) from None
