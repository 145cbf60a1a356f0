"""CSV (and TSV) logs with a column mapping: ``--columns t=time,lat=Latitude,lon=Longitude,sigma=2.5``.

Each row of the table gives the records whose fields it holds (docs/csv.md): a GNSS fix (``lat`` +
``lon`` or ``x`` + ``y``, with ``sigma``), a heading (``heading`` or ``yaw``, with ``heading_sigma``),
a velocity over ground (``sog`` + ``cog`` or ``vx`` + ``vy``), a speed through water (``stw``),
odometry (``v`` + ``w``). A mapping's value is a column of the header, or a number (a constant, e.g.
the GNSS sigma a datasheet states), optionally followed by ``:UNIT`` (``sog=SOG:kn``); without a unit
each field takes the one :data:`TARGETS` states (SI, angles as graphnav's or the nautical convention
the name says). An empty cell leaves that row's record out; anything else that is not a number is a
:class:`LogError` naming the file, the line and the column. Without ``--columns`` the header's own
names are the fields (a column named ``lat`` is ``lat``).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..errors import LogError
from ..geodesy import LocalFrame
from ..geometry import heading_deg_to_yaw
from ..log import Gnss, GnssVelocity, Heading, Limits, NavLog, Odometry, Record, WaterSpeed, check_record
from .textlines import Lines

CSV_SUFFIXES = (".csv", ".csv.gz", ".tsv", ".tsv.gz")

_LENGTH = {"m": 1.0, "km": 1000.0, "ft": 0.3048, "nmi": 1852.0}
_SPEED = {"m/s": 1.0, "kn": 1852.0 / 3600.0, "km/h": 1.0 / 3.6}
_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
_RATE = {"rad/s": 1.0, "deg/s": math.pi / 180.0, "deg/min": math.pi / 180.0 / 60.0}
_DEG = {"deg": 1.0}
_TIME = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


@dataclass(frozen=True)
class Target:
    """A field a column can be mapped to: its meaning, default unit and the units it accepts."""

    meaning: str
    unit: str
    units: Mapping[str, float]


TARGETS: dict[str, Target] = {
    "t": Target("time: seconds (any epoch), or an ISO 8601 date-time (UTC unless it says) -> POSIX seconds", "s",
                _TIME),
    "lat": Target("GNSS latitude, WGS84", "deg", _DEG),
    "lon": Target("GNSS longitude, WGS84", "deg", _DEG),
    "x": Target("GNSS position east in the local frame", "m", _LENGTH),
    "y": Target("GNSS position north in the local frame", "m", _LENGTH),
    "sigma": Target("GNSS 1-sigma per horizontal axis", "m", _LENGTH),
    "heading": Target("heading, clockwise from true north (nautical)", "deg", _ANGLE),
    "yaw": Target("yaw, counter-clockwise from east (graphnav's)", "rad", _ANGLE),
    "heading_sigma": Target("heading/yaw 1-sigma", "deg", _ANGLE),
    "sog": Target("speed over ground", "m/s", _SPEED),
    "cog": Target("course over ground, clockwise from true north", "deg", _ANGLE),
    "vx": Target("velocity over ground east", "m/s", _SPEED),
    "vy": Target("velocity over ground north", "m/s", _SPEED),
    "velocity_sigma": Target("velocity over ground 1-sigma per axis", "m/s", _SPEED),
    "stw": Target("speed through water along the bow (speed log)", "m/s", _SPEED),
    "stw_sigma": Target("speed through water 1-sigma", "m/s", _SPEED),
    "v": Target("odometry: speed along the bow", "m/s", _SPEED),
    "w": Target("odometry: yaw rate, counter-clockwise positive", "rad/s", _RATE),
}


@dataclass(frozen=True)
class Source:
    """Where a field's value comes from: a column (its index and name) or a constant; and the factor
    of its unit to SI."""

    column: int | None
    name: str
    constant: float | None
    scale: float
    unit: str = ""  # the unit the values are read in


def parse_columns(spec: str | Mapping[str, str] | None, flag: str = "--columns") -> dict[str, str]:
    """``"t=time,lat=Latitude"`` (or a mapping) -> ``{field: "COLUMN[:UNIT]"}``; an unknown field is a
    :class:`LogError` naming ``flag`` and the known fields."""
    if spec is None:
        return {}
    if isinstance(spec, str):
        out: dict[str, str] = {}
        for item in (s.strip() for s in spec.split(",")):
            if not item:
                continue
            key, eq, value = item.partition("=")
            if not eq or not key.strip() or not value.strip():
                raise LogError(f"{flag}: expected FIELD=COLUMN[:UNIT], got {item[:60]!r}", field=flag)
            out[key.strip()] = value.strip()
        spec = out
    bad = sorted(k for k in spec if k not in TARGETS)
    if bad:
        raise LogError(f"{flag}: unknown field(s) {', '.join(bad)}; known: {', '.join(TARGETS)}", field=flag)
    return {str(k): str(v) for k, v in spec.items()}


def _sources(mapping: dict[str, str], header: list[str], path: Path, flag: str) -> dict[str, Source]:
    index = {h: i for i, h in enumerate(header)}
    out: dict[str, Source] = {}
    for field, value in mapping.items():
        target = TARGETS[field]
        name, unit = value, None
        if value not in index and ":" in value:
            name, _, unit = value.rpartition(":")
        if unit is not None and unit not in target.units:
            raise LogError(f"{flag}: {field}={value}: unknown unit {unit!r} for {field} ({target.meaning}); "
                           f"known: {', '.join(target.units)}", field=flag)
        scale = target.units[unit or target.unit]
        if name in index:
            out[field] = Source(index[name], name, None, scale, unit or target.unit)
            continue
        try:
            const = float(name)
        except ValueError:
            raise LogError(f"{flag}: {field}={value}: no column {name!r} in the header; columns: "
                           f"{', '.join(header)[:400]}", file=str(path), line=1, field=flag) from None
        if not math.isfinite(const) or field == "t":
            raise LogError(f"{flag}: {field}={value}: a constant must be a finite number (and t a column)",
                           field=flag)
        out[field] = Source(None, name, const * scale, scale, unit or target.unit)
    return out


def _time(cell: str, scale: float) -> float:
    """A time cell: a number (times ``scale``: its unit), else an ISO 8601 date-time (UTC unless it says)
    -> POSIX seconds."""
    try:
        return float(cell) * scale
    except ValueError:
        pass
    text = cell.strip().replace("Z", "+00:00")
    d = datetime.fromisoformat(text)
    if d.tzinfo is None:
        d = d.replace(tzinfo=UTC)
    return d.timestamp()


def read_csv_log(path: str | Path, *, columns: str | Mapping[str, str] | None = None, lenient: bool = False,
                 limits: Limits | None = None, flag: str = "--columns") -> NavLog:
    """A CSV/TSV file (``.csv``, ``.tsv``, optionally gzipped) as a :class:`NavLog` (module docstring)."""
    path = Path(path)
    mapping = parse_columns(columns, flag)
    lines = Lines(path, lenient=lenient)
    rows = iter(lines)
    header: list[str] | None = None
    delimiter = "\t" if ".tsv" in path.name.lower() else ","
    src: dict[str, Source] = {}
    records: list[Record] = []
    skipped: list[str] = []
    frame: LocalFrame | None = None
    last_t = -math.inf
    for lineno, raw in rows:
        try:
            text = raw.decode("utf-8-sig" if lineno == 1 else "utf-8").rstrip("\r\n")
        except UnicodeDecodeError:
            err = LogError("not UTF-8 text", file=str(path), line=lineno)
            if header is None or not lenient:
                raise err from None
            skipped.append(str(err))
            continue
        if not text.strip() or text.lstrip().startswith("#"):
            continue
        if header is None:
            if delimiter == "," and text.count(";") > text.count(","):
                delimiter = ";"
            header = [h.strip() for h in _cells(text, delimiter, path, lineno)]
            given = mapping or {h: h for h in header if h in TARGETS}
            src = _sources(given, header, path, flag)
            if "t" not in src:
                raise LogError(f"no time column: map one ({flag} t=COLUMN[:s|ms|us|ns]); columns: "
                               f"{', '.join(header)[:400]}", file=str(path), line=lineno, field=flag)
            continue
        try:
            cells = _cells(text, delimiter, path, lineno)
            vals = _row(cells, src, path, lineno)
            if vals["t"] < last_t:
                raise LogError(f"time {vals['t']:.9g} before the previous row's {last_t:.9g} (rows must be in "
                               "time order)", file=str(path), line=lineno, field=f"column '{src['t'].name}' (t)")
            recs, frame = _records(vals, frame, src, path, lineno)
            for r in recs:
                try:
                    check_record(r, limits)
                except LogError as exc:
                    raise exc.located(file=str(path), line=lineno) from None
            last_t = vals["t"]
            records.extend(recs)
        except LogError as exc:
            if not lenient:
                raise
            skipped.append(str(exc))
    if header is None:
        raise LogError("no header line (the first line names the columns)", file=str(path), line=1)
    meta: dict[str, Any] = {"name": path.name.split(".")[0], "format": "csv",
                            "columns": {f: (s.name if s.column is not None else f"constant {s.name}")
                                        for f, s in src.items()},
                            "units": {f: s.unit for f, s in src.items()}}
    if frame is not None:
        meta["origin"] = {"lat": frame.lat0, "lon": frame.lon0, "h": frame.h0}
    if skipped or lines.truncated:
        meta["skipped"] = len(skipped) + bool(lines.truncated)
        meta["skipped_errors"] = (skipped + ([str(lines.truncated)] if lines.truncated else []))[:20]
    return NavLog(records, [], meta)


def _cells(text: str, delimiter: str, path: Path, lineno: int) -> list[str]:
    """One line's cells; a line the csv module cannot split (a lone carriage return inside a field)
    is a :class:`LogError` naming it."""
    try:
        return next(csv.reader([text], delimiter=delimiter), [])
    except csv.Error as exc:
        raise LogError(f"not a CSV line: {exc}", file=str(path), line=lineno) from None


def _row(cells: list[str], src: dict[str, Source], path: Path, lineno: int) -> dict[str, float]:
    """The row's mapped values in SI (empty cells absent)."""
    vals: dict[str, float] = {}
    for field, s in src.items():
        if s.column is None:
            vals[field] = float(s.constant)  # type: ignore[arg-type]
            continue
        where = f"column '{s.name}' ({field})"
        if s.column >= len(cells):
            if field == "t":
                raise LogError(f"the row has {len(cells)} cells, no time", file=str(path), line=lineno, field=where)
            continue
        cell = cells[s.column].strip()
        if not cell:
            if field == "t":
                raise LogError("empty time", file=str(path), line=lineno, field=where)
            continue
        try:
            v = _time(cell, s.scale) if field == "t" else float(cell) * s.scale
        except (ValueError, OverflowError):
            raise LogError(f"not a number{' nor an ISO 8601 time' if field == 't' else ''}: {cell[:40]!r}",
                           file=str(path), line=lineno, field=where) from None
        if not math.isfinite(v):
            raise LogError(f"not finite: {cell[:40]!r}", file=str(path), line=lineno, field=where)
        vals[field] = v
    return vals


def _records(v: dict[str, float], frame: LocalFrame | None, src: dict[str, Source], path: Path, lineno: int
             ) -> tuple[list[Record], LocalFrame | None]:
    t = v["t"]
    out: list[Record] = []

    def need(field: str, group: str) -> float:
        if field not in src:
            raise LogError(f"a {group} needs {field} ({TARGETS[field].meaning}): map a column or give a number, "
                           f"e.g. --columns {field}=3", file=str(path), line=lineno, field=field)
        return v[field]

    if "lat" in v and "lon" in v:
        if not -90.0 <= v["lat"] <= 90.0:
            raise LogError(f"latitude {v['lat']:g} outside [-90, 90]", file=str(path), line=lineno,
                           field=f"column '{src['lat'].name}' (lat)")
        if frame is None:
            frame = LocalFrame(v["lat"], v["lon"])
        x, y = frame.to_local(v["lat"], v["lon"])
        out.append(Gnss(t, float(x), float(y), need("sigma", "GNSS fix")))
    elif "x" in v and "y" in v:
        out.append(Gnss(t, v["x"], v["y"], need("sigma", "GNSS fix")))
    if "heading" in v:
        out.append(Heading(t, heading_deg_to_yaw(math.degrees(v["heading"])), need("heading_sigma", "heading")))
    elif "yaw" in v:
        out.append(Heading(t, v["yaw"], need("heading_sigma", "heading")))
    sig = v.get("velocity_sigma", math.nan)
    if "sog" in v and "cog" in v:
        out.append(GnssVelocity(t, v["sog"] * math.sin(v["cog"]), v["sog"] * math.cos(v["cog"]), sig))
    elif "vx" in v and "vy" in v:
        out.append(GnssVelocity(t, v["vx"], v["vy"], sig))
    if "stw" in v:
        out.append(WaterSpeed(t, v["stw"], v.get("stw_sigma", math.nan)))
    if "v" in v and "w" in v:
        out.append(Odometry(t, v["v"], v["w"]))
    return out, frame


__all__ = ["CSV_SUFFIXES", "TARGETS", "parse_columns", "read_csv_log"]
