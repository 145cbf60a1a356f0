"""The JSON Lines navigation-log format (spec: docs/log-format.md), optionally gzipped."""

from __future__ import annotations

import gzip
import io
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..errors import LogError
from ..geodesy import LocalFrame
from ..log import (
    MAX_CLOUD_POINTS,
    MAX_RING,
    RECORD_TYPES,
    SOURCE_FIELD,
    SOURCED_KINDS,
    BeaconObs,
    Cloud,
    Gnss,
    KnownBeacon,
    Limits,
    NavLog,
    Record,
    Scan,
    check_record,
    make_cloud,
)
from .textlines import Lines, note_truncation

REQUIRED: dict[str, tuple[str, ...]] = {
    "scan": ("t",),
    "gnss": ("t", "sigma"),
    "heading": ("t", "yaw", "sigma"),
    "odometry": ("t", "v", "w"),
    "imu": ("t", "ax", "ay", "wz"),
    "beacon": ("t", "id", "range", "bearing"),
    "truth": ("t", "x", "y", "yaw"),
    "pose_prior": ("t", "x", "y", "yaw", "sigma_xy", "sigma_yaw"),
    "beacon_known": ("id", "x", "y", "sigma"),
    "cloud": ("t", "points"),
    "gnss_velocity": ("t", "vx", "vy"),
    "water_speed": ("t", "v"),
    "attitude": ("t", "roll", "pitch"),
}
OPTIONAL: dict[str, tuple[str, ...]] = {
    "scan": ("range_max",),
    "cloud": ("intensity", "ring", "roll", "pitch"),
    "odometry": ("sigma_v", "sigma_w"),
    "beacon": ("sigma_range", "sigma_bearing"),
    "imu": ("az", "wx", "wy"),
    "gnss_velocity": ("sigma",),
    "water_speed": ("sigma_v",),
    "attitude": ("sigma",),
}


MAX_LINE_BYTES = 32 << 20
"""The longest line read (32 MiB): a cloud of about 500 000 points at 4 decimals with intensity and ring
(~55 bytes a point); larger clouds go in the ``.npz`` form. Reading a line takes a few times its size."""


class _OwnedGzip(gzip.GzipFile):
    """A GzipFile that closes the file object it was given (no name or time in the header)."""

    def close(self) -> None:
        fo = self.fileobj
        super().close()
        if fo is not None:
            fo.close()


def _open_text(path: Path, mode: str) -> TextIO:
    if path.suffix == ".gz":  # mtime=0: the same log gives the same bytes
        if mode == "w":
            raw = _OwnedGzip(filename="", mode="wb", fileobj=open(path, "wb"), mtime=0)
        else:
            raw = gzip.open(path, "rb")
        return io.TextIOWrapper(raw, encoding="utf-8")
    return open(path, mode, encoding="utf-8")


def _num(obj: dict, name: str) -> float:
    if name not in obj:
        raise LogError(f"missing in a '{obj.get('type', '?')}' record", field=name)
    v = obj[name]
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise LogError(f"expected a number, got {json.dumps(v)[:40]}", field=name)
    try:
        return float(v)
    except OverflowError:  # an integer beyond float range (e.g. 400 digits)
        raise LogError(f"integer with {len(str(abs(v)))} digits is out of range", field=name) from None


def _array(obj: dict, name: str) -> np.ndarray:
    v = obj.get(name)
    if not isinstance(v, list):
        raise LogError("expected a list of numbers", field=name)
    out = np.empty(len(v))
    for i, x in enumerate(v):
        if x is None:
            out[i] = math.nan
        elif isinstance(x, bool) or not isinstance(x, int | float):
            raise LogError(f"element {i} is not a number", field=name)
        else:
            try:
                out[i] = float(x)
            except OverflowError:
                raise LogError(f"element {i} is out of range", field=name) from None
    return out


def _points(obj: dict) -> np.ndarray:
    """A cloud's ``points``: a list of ``[x, y, z]`` number triples (count bounded before converting)."""
    v = obj.get("points")
    if not isinstance(v, list):
        raise LogError("expected a list of [x, y, z] triples", field="points")
    if len(v) > MAX_CLOUD_POINTS:
        raise LogError(f"{len(v)} points, more than {MAX_CLOUD_POINTS}", field="points")
    for i, p in enumerate(v):
        if not (isinstance(p, list) and len(p) == 3
                and all(isinstance(x, int | float) and not isinstance(x, bool) for x in p)):
            raise LogError(f"point {i} is not an [x, y, z] triple of numbers", field="points")
    try:
        return np.array(v, dtype=np.float64).reshape(-1, 3)
    except OverflowError:
        raise LogError("a coordinate is out of range", field="points") from None


def _cloud(obj: dict) -> Cloud:
    pts = _points(obj)
    n = pts.shape[0]
    inten = ring = None
    if obj.get("intensity") is not None:
        inten = _array(obj, "intensity")
        if inten.size != n:
            raise LogError(f"{inten.size} values for {n} points", field="intensity")
    if obj.get("ring") is not None:
        rv = obj["ring"]
        if not isinstance(rv, list) or len(rv) != n or not all(
                isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= MAX_RING for x in rv):
            raise LogError(f"expected {n} integers in [0, {MAX_RING}]", field="ring")
        ring = np.array(rv, dtype=np.int64) if rv else np.zeros(0, dtype=np.int64)
    att = [_num(obj, k) if obj.get(k) is not None else math.nan for k in ("roll", "pitch")]
    return make_cloud(_num(obj, "t"), pts, inten, ring, *att)


def parse_record(obj: Any, frame: LocalFrame | None = None, limits: Limits | None = None
                 ) -> Record | KnownBeacon | dict:
    """Turn one decoded JSON object into a record (a ``meta`` object is returned as a dict).

    Raises :class:`LogError` naming the field on any problem, physical validity included
    (:func:`graphnav.log.check_record` with ``limits``).
    """
    if not isinstance(obj, dict):
        raise LogError("each line must be a JSON object")
    kind = obj.get("type")
    if kind == "meta":
        return {k: v for k, v in obj.items() if k != "type"}
    if kind not in REQUIRED:
        raise LogError(f"unknown record type {json.dumps(kind)[:40]}", field="type")
    for name in REQUIRED[kind]:
        if name not in obj:
            raise LogError(f"missing in a '{kind}' record", field=name)
    if kind == "scan":
        ranges = _array(obj, "ranges")
        if "angles" in obj:
            angles = _array(obj, "angles")
        elif "angle_min" in obj and "angle_increment" in obj:
            angles = _num(obj, "angle_min") + _num(obj, "angle_increment") * np.arange(ranges.size)
        else:
            raise LogError("a scan needs 'angles' (or 'angle_min' and 'angle_increment')", field="angles")
        rmax = _num(obj, "range_max") if obj.get("range_max") is not None else math.nan
        rec: Record | KnownBeacon = Scan(_num(obj, "t"), ranges, angles, rmax)
    elif kind == "cloud":
        rec = _cloud(obj)
    elif kind == "gnss":
        if "x" in obj and "y" in obj:
            x, y = _num(obj, "x"), _num(obj, "y")
        elif "lat" in obj and "lon" in obj:
            if frame is None:
                raise LogError("lat/lon fix but no local frame", field="lat")
            lat, lon = _num(obj, "lat"), _num(obj, "lon")
            if not (-90.0 <= lat <= 90.0):
                raise LogError("latitude out of [-90, 90]", field="lat")
            if not (-180.0 <= lon <= 180.0):
                raise LogError("longitude out of [-180, 180]", field="lon")
            x, y = frame.to_local(lat, lon)
        else:
            raise LogError("a gnss record needs 'x' and 'y' or 'lat' and 'lon'", field="x")
        rec = Gnss(_num(obj, "t"), float(x), float(y), _num(obj, "sigma"))
    elif kind in ("beacon", "beacon_known"):
        bid = obj["id"]
        if isinstance(bid, bool) or not isinstance(bid, str | int) or bid == "":
            raise LogError("beacon id must be a non-empty string or an integer", field="id")
        nums = {n: _num(obj, n) for n in REQUIRED[kind] + OPTIONAL.get(kind, ()) if n != "id" and n in obj}
        cls = BeaconObs if kind == "beacon" else KnownBeacon
        rec = cls(id=str(bid), **nums)
    else:
        names = REQUIRED[kind] + OPTIONAL.get(kind, ())
        rec = RECORD_TYPES[kind](**{n: _num(obj, n) for n in names if n in obj})
    if kind in SOURCED_KINDS and SOURCE_FIELD in obj:
        src = obj[SOURCE_FIELD]
        if isinstance(src, bool) or not isinstance(src, str | int):
            raise LogError("source must be a string or an integer", field=SOURCE_FIELD)
        rec = replace(rec, source=str(src))
    check_record(rec, limits)
    return rec


def read_jsonl(path: str | Path, *, lenient: bool = False, limits: Limits | None = None) -> NavLog:
    """Read a ``.jsonl`` / ``.jsonl.gz`` log.

    Strict by default: the first bad line raises :class:`LogError` with file, line and field.
    With ``lenient`` bad lines (physically invalid ones too, :class:`graphnav.log.Limits`) are
    skipped and counted in ``log.meta["skipped"]`` (their first messages in
    ``log.meta["skipped_errors"]``). Blank lines and lines starting with ``#`` are
    comments.
    """
    path = Path(path)
    records: list[Record] = []
    known: list[KnownBeacon] = []
    meta: dict[str, Any] = {"source": str(path)}
    frame: LocalFrame | None = None
    skipped: list[str] = []
    last_t = -math.inf
    lines = Lines(path, lenient=lenient, max_line=MAX_LINE_BYTES)  # read and decompressed line by line
    for lineno, raw in lines:
        try:
            try:
                s = raw.decode("utf-8").strip()
            except UnicodeDecodeError as exc:
                raise LogError(f"not UTF-8 (byte {exc.start})") from None
            if not s or s.startswith("#"):
                continue
            try:
                obj = json.loads(s)
            except (ValueError, RecursionError) as exc:  # JSONDecodeError, or an integer of > 4300 digits
                raise LogError(f"not valid JSON ({exc.__class__.__name__}: {str(exc)[:60]})") from None
            if isinstance(obj, dict) and obj.get("type") == "gnss" and "lat" in obj and frame is None:
                frame = _frame_from(meta, obj)
            rec = parse_record(obj, frame, limits)
            if isinstance(rec, dict):
                meta.update(rec)
                if "origin" in rec:
                    frame = _frame_from(meta, None)
                    meta["origin"] = {"lat": frame.lat0, "lon": frame.lon0, "h": frame.h0}
                continue
            if isinstance(rec, KnownBeacon):
                known.append(rec)
                continue
            if rec.t < last_t:
                raise LogError(f"time goes backwards ({rec.t!r} after {last_t!r})", field="t")
            last_t = rec.t
            records.append(rec)
        except LogError as err:
            err = err.located(file=str(path), line=lineno)
            if not lenient:
                raise err from None
            skipped.append(str(err))
    if frame is not None:
        meta["origin"] = {"lat": frame.lat0, "lon": frame.lon0, "h": frame.h0}
    if lenient:
        note_truncation(meta, lines, skipped)
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    return NavLog(records, known, meta).mark_checked(limits)


def _frame_from(meta: dict, first_fix: dict | None) -> LocalFrame:
    """The local frame: the meta line's ``origin`` when given, else the first lat/lon fix."""
    if "origin" in meta:
        o = meta["origin"]
        if not isinstance(o, dict):
            raise LogError("meta origin must be an object {lat, lon, h}", field="origin")
        try:
            lat, lon, h = _num(o, "lat"), _num(o, "lon"), _num(o, "h") if "h" in o else 0.0
        except (LogError, KeyError):
            raise LogError("meta origin must hold numbers lat, lon (and h)", field="origin") from None
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and math.isfinite(h)):
            raise LogError("meta origin out of range", field="origin")
        return LocalFrame(lat, lon, h)
    if first_fix is None:
        raise LogError("no origin for lat/lon fixes", field="origin")
    lat, lon = _num(first_fix, "lat"), _num(first_fix, "lon")
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise LogError("first fix out of range", field="lat")
    return LocalFrame(lat, lon, 0.0)


def _clean(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def record_to_obj(rec: Record | KnownBeacon) -> dict[str, Any]:
    """The JSON object of one record (missing scan returns become ``null``)."""
    obj: dict[str, Any] = {}
    if not isinstance(rec, KnownBeacon):
        obj["t"] = rec.t
    obj["type"] = rec.kind
    if isinstance(rec, Scan):
        obj["ranges"] = [_clean(r) for r in rec.ranges.tolist()]
        obj["angles"] = [_clean(a) for a in rec.angles.tolist()]
        if math.isfinite(rec.range_max):
            obj["range_max"] = rec.range_max
        return obj
    if isinstance(rec, Cloud):
        obj["points"] = rec.points.astype(float).tolist()
        if rec.intensity is not None:
            obj["intensity"] = rec.intensity.astype(float).tolist()
        if rec.ring is not None:
            obj["ring"] = rec.ring.tolist()
        for k in ("roll", "pitch"):
            if math.isfinite(getattr(rec, k)):
                obj[k] = getattr(rec, k)
        return obj
    for name in REQUIRED[rec.kind] + OPTIONAL.get(rec.kind, ()):
        if name == "t":
            continue
        v = getattr(rec, name)
        if isinstance(v, float) and math.isnan(v) and name in OPTIONAL.get(rec.kind, ()):
            continue
        obj[name] = v
    if isinstance(rec, Gnss):
        obj["x"], obj["y"] = rec.x, rec.y
    if getattr(rec, SOURCE_FIELD, ""):
        obj[SOURCE_FIELD] = rec.source
    return obj


def write_jsonl(log: NavLog, path: str | Path, *, scan_decimals: int = 4) -> None:
    """Write a log as JSON Lines (gzipped when the name ends in ``.gz``).

    A ``meta`` line comes first, then charted beacons, then the records in time order.
    Scan ranges/angles and cloud points/intensities are rounded to ``scan_decimals`` (0.1 mm /
    0.1 mrad by default).
    """
    path = Path(path)
    with _open_text(path, "w") as fh:
        _write(log, fh, scan_decimals)


def _write(log: NavLog, fh: TextIO, scan_decimals: int) -> None:
    meta = {k: v for k, v in log.meta.items() if k not in ("source", "skipped", "skipped_errors")}
    if meta:
        fh.write(json.dumps({"type": "meta", **meta}, allow_nan=False) + "\n")
    for b in log.beacons_known:
        fh.write(json.dumps(record_to_obj(b), allow_nan=False) + "\n")
    for rec in log.records:
        obj = record_to_obj(rec)
        if isinstance(rec, Scan):
            obj["ranges"] = [None if r is None else round(r, scan_decimals) for r in obj["ranges"]]
            obj["angles"] = [None if a is None else round(a, scan_decimals) for a in obj["angles"]]
        elif isinstance(rec, Cloud):  # float32 values: 4 decimals (0.1 mm) say all they hold at < 100 m
            obj["points"] = np.round(rec.points.astype(float), scan_decimals).tolist()
            if rec.intensity is not None:
                obj["intensity"] = np.round(rec.intensity.astype(float), scan_decimals).tolist()
        fh.write(json.dumps(obj, allow_nan=False, separators=(",", ":")) + "\n")
