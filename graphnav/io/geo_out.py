"""Tracks in WGS84 for GIS and chart plotters: GeoJSON (RFC 7946), GPX 1.1, KML 2.2.

A track is a :class:`~graphnav.trajectory.Trajectory` in the local frame converted with the log's
geodetic origin (:func:`graphnav.geodesy.origin_frame`; without one nothing is written -- an origin
is never invented). Times are the log's seconds read as POSIX (UTC): a log whose times are not POSIX
(a simulation from ``t = 0``) starts on 1970-01-01, as :mod:`graphnav.io.nmea_out` does; the raw
``t`` is kept in GeoJSON's properties. Headings are degrees clockwise from true north. The files of
``run``/``compare --out`` hold at most :data:`MAX_RATE_HZ` poses a second per track (:func:`thinned`;
the TUM files every pose); ``graphnav export --to gpx|kml|geojson`` writes every pose.

* GeoJSON: a FeatureCollection with, per track, a ``LineString`` (``kind: "track"``) and one
  ``Point`` per pose (``kind: "pose"``, properties ``t``, ``time``, ``heading_deg``); coordinates
  ``[lon, lat]`` (RFC 7946 section 3.1.1) to 1e-8 deg (~1 mm), no ``crs`` member (WGS84 by definition).
* GPX 1.1 (the document gpxpy writes, written directly): one ``<trk>`` per track, ``<trkpt lat lon><time>``
  per pose (GPX 1.1 has no heading).
* KML 2.2: one ``Placemark`` with a ``LineString`` and a ``TimeSpan`` per track.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import GraphnavError
from ..geodesy import LocalFrame, origin_frame
from ..geometry import yaw_to_heading_deg
from ..trajectory import Trajectory
from .outputs import OutDir, write_text_atomic

FORMATS = ("geojson", "gpx", "kml")
#: KML colours (aabbggrr) for successive tracks; the truth is drawn black.
_KML_COLOURS = ("ff0000ff", "ffff0000", "ff00a000", "ff00a5ff", "ffff00ff", "ffa0a000", "ff808080", "ff004080")


@dataclass
class GeoTrack:
    """One track in WGS84: times [s], latitude and longitude [deg], heading [deg from north] (NaN: unknown)."""

    name: str
    t: NDArray[np.float64]
    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    heading_deg: NDArray[np.float64]

    @classmethod
    def from_trajectory(cls, traj: Trajectory, frame: LocalFrame, name: str | None = None) -> GeoTrack:
        """The trajectory's poses converted by ``frame`` (poses with a non-finite position or time, a
        time beyond :data:`MAX_TIME` or a position off the Earth are left out); the name keeps only
        the characters XML allows."""
        ok = np.isfinite(traj.t) & (np.abs(traj.t) <= MAX_TIME) & np.isfinite(traj.x) & np.isfinite(traj.y)
        ok &= (np.abs(traj.x) <= MAX_COORD) & (np.abs(traj.y) <= MAX_COORD)
        lat, lon = (np.atleast_1d(v) for v in frame.to_geodetic(traj.x[ok], traj.y[ok]))
        good = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90.0)
        yaw = traj.yaw[ok][good]
        heading = np.where(np.isfinite(yaw), yaw_to_heading_deg(np.nan_to_num(yaw)), np.nan)
        return cls(xml_safe(name if name is not None else (traj.name or "")), traj.t[ok][good], lat[good], lon[good],
                   np.atleast_1d(heading))

    def times(self) -> list[datetime]:
        return [datetime.fromtimestamp(round(float(t), 6), UTC) for t in self.t]


MAX_TIME = 1e10
"""[s] The largest |t| a track's time may have (POSIX seconds reach 1e10 in 2286; :class:`graphnav.log.Limits`)."""
MAX_COORD = 1e7
"""[m] The largest |x|, |y| of a local-frame position (:class:`graphnav.log.Limits`)."""
_XML_BAD = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def xml_safe(text: str) -> str:
    """``text`` without the characters XML 1.0 cannot hold (NUL, other C0 controls, lone surrogates)."""
    return _XML_BAD.sub("", str(text))


def _xml_text(text: str) -> str:
    """``text`` as XML character data: ``&``, ``<``, ``>`` escaped and a carriage return as ``&#13;`` (a
    parser would read a raw one as a newline)."""
    from xml.sax.saxutils import escape

    return escape(text, {"\r": "&#13;"})


def check_track(traj: Trajectory, where: str) -> None:
    """A :class:`GraphnavError` naming ``where`` when a pose's time or position cannot be a date or a
    place: a non-finite time, |t| beyond :data:`MAX_TIME`, a finite position beyond :data:`MAX_COORD`."""
    t = np.asarray(traj.t, dtype=float)
    bad = ~np.isfinite(t) | (np.abs(np.nan_to_num(t)) > MAX_TIME)
    if bad.any():
        i = int(np.argmax(bad))
        raise GraphnavError(f"pose {i}: time {float(t[i])!r} s is not a date (|t| <= {MAX_TIME:g} s)", where=where)
    xy = np.column_stack([traj.x, traj.y])
    far = np.isfinite(xy).all(axis=1) & (np.abs(np.nan_to_num(xy)) > MAX_COORD).any(axis=1)
    if far.any():
        i = int(np.argmax(far))
        raise GraphnavError(f"pose {i}: position ({xy[i, 0]:g}, {xy[i, 1]:g}) m is beyond {MAX_COORD:g} m of the "
                            "origin: not a place on Earth", where=where)


def _c(v: float) -> float:
    return round(float(v), 8)


def _iso_times(t: NDArray[np.float64], unit: str = "ms") -> list[str]:
    """The ISO 8601 UTC times (to the millisecond, or ``unit="us"``; ``Z``) of POSIX seconds ``t``: ``isoformat``
    of :meth:`GeoTrack.times`, vectorised (the microseconds as ``datetime.fromtimestamp`` of ``round(t, 6)``
    makes them, then floored to the unit as ``isoformat`` does)."""
    r = np.array([round(v, 6) for v in np.asarray(t, dtype=float).tolist()])
    frac, whole = np.modf(r)
    us = whole.astype(np.int64) * 1_000_000 + np.rint(frac * 1e6).astype(np.int64)
    d = us.astype("datetime64[us]").astype(f"datetime64[{unit}]")
    return [s + "Z" for s in np.datetime_as_string(d, unit=unit).tolist()]


def _coord_pairs(tr: GeoTrack) -> list[str]:
    """``[lon,lat]`` per pose as JSON text, to 1e-8 deg (:func:`_c`, the float's shortest repr)."""
    lon = np.round(tr.lon.astype(float), 8).tolist()
    lat = np.round(tr.lat.astype(float), 8).tolist()
    return [f"[{lo!r},{la!r}]" for lo, la in zip(lon, lat, strict=True)]


def geojson(tracks: list[GeoTrack]) -> dict[str, Any]:
    """An RFC 7946 FeatureCollection (see the module docstring)."""
    return json.loads(geojson_text(tracks))


def geojson_text(tracks: list[GeoTrack]) -> str:
    """:func:`geojson` as compact JSON text, written directly (a few hundred thousand pose features of a
    compare's 100 Hz filters took seconds through dicts and ``json.dumps``)."""
    parts: list[str] = []
    for tr in tracks:
        times = _iso_times(tr.t)
        coords = _coord_pairs(tr)
        name = json.dumps(tr.name)
        if len(coords) >= 2:
            parts.append(f'{{"type":"Feature","geometry":{{"type":"LineString","coordinates":[{",".join(coords)}]}},'
                         f'"properties":{{"name":{name},"kind":"track","poses":{len(coords)},'
                         f'"start":"{times[0]}","end":"{times[-1]}"}}}}')
        head = '{"type":"Feature","geometry":{"type":"Point","coordinates":'
        props = f'}},"properties":{{"name":{name},"kind":"pose","t":'
        hd = np.round(tr.heading_deg.astype(float), 3).tolist()
        for c, t, tm, h in zip(coords, tr.t.astype(float).tolist(), times, hd, strict=True):
            tail = f',"heading_deg":{h!r}}}}}' if math.isfinite(h) else "}}"
            parts.append(f'{head}{c}{props}{t!r},"time":"{tm}"{tail}')
    out = '{"type":"FeatureCollection","features":[' + ",".join(parts) + "]"
    lats = np.concatenate([tr.lat for tr in tracks]) if tracks else np.empty(0)
    lons = np.concatenate([tr.lon for tr in tracks]) if tracks else np.empty(0)
    if lats.size:
        box = [_c(lons.min()), _c(lats.min()), _c(lons.max()), _c(lats.max())]
        out += f',"bbox":{json.dumps(box, separators=(",", ":"))}'
    return out + "}"


def gpx_text(tracks: list[GeoTrack]) -> str:
    """GPX 1.1: one track per :class:`GeoTrack`, with times; the document gpxpy writes, written directly
    (gpxpy's ``to_xml`` took seconds for a compare's 100 Hz filters; tests read it back with gpxpy)."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<gpx xmlns="http://www.topografix.com/GPX/1/1" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
             'xsi:schemaLocation="http://www.topografix.com/GPX/1/1 http://www.topografix.com/GPX/1/1/gpx.xsd" '
             'version="1.1" creator="graphnav">']
    for tr in tracks:
        lines += ["  <trk>", f"    <name>{_xml_text(tr.name)}</name>", "    <trkseg>"]
        times = _iso_times(tr.t, "us")
        lines += [f'      <trkpt lat="{la!r}" lon="{lo!r}">\n        <time>{tm}</time>\n      </trkpt>'
                  for la, lo, tm in zip(tr.lat.astype(float).tolist(), tr.lon.astype(float).tolist(), times,
                                        strict=True)]
        lines += ["    </trkseg>", "  </trk>"]
    return "\n".join([*lines, "</gpx>"])


def kml_text(tracks: list[GeoTrack]) -> str:
    """KML 2.2: one LineString placemark per track, with its colour, width and time span; the document
    simplekml writes, written directly (tests read both back the same)."""
    styles, marks = [], []
    for i, tr in enumerate(tracks):
        colour = "ff000000" if tr.name == "truth" else _KML_COLOURS[i % len(_KML_COLOURS)]
        styles.append(f'        <Style id="track{i}">\n            <LineStyle>\n'
                      f"                <color>{colour}</color>\n"
                      "                <colorMode>normal</colorMode>\n                <width>2</width>\n"
                      "            </LineStyle>\n        </Style>")
        span = ""
        if len(tr.t):
            times = _iso_times(tr.t[[0, -1]])
            span = (f"            <TimeSpan>\n                <begin>{times[0]}</begin>\n"
                    f"                <end>{times[1]}</end>\n            </TimeSpan>\n")
        coords = " ".join(f"{lo!r},{la!r},0.0" for la, lo in zip(tr.lat.astype(float).tolist(),
                                                                 tr.lon.astype(float).tolist(), strict=True))
        marks.append(f"        <Placemark>\n            <name>{_xml_text(tr.name)}</name>\n{span}"
                     f"            <styleUrl>#track{i}</styleUrl>\n            <LineString>\n"
                     f"                <coordinates>{coords}</coordinates>\n            </LineString>\n"
                     "        </Placemark>")
    return "\n".join(['<?xml version="1.0" encoding="UTF-8"?>',
                      '<kml xmlns="http://www.opengis.net/kml/2.2" xmlns:gx="http://www.google.com/kml/ext/2.2">',
                      "    <Document>", *styles, "        <name>graphnav</name>", *marks, "    </Document>",
                      "</kml>"]) + "\n"


def render(tracks: list[GeoTrack], fmt: str) -> str:
    """The text of ``fmt`` (one of :data:`FORMATS`)."""
    if fmt == "geojson":
        return geojson_text(tracks) + "\n"
    if fmt == "gpx":
        return gpx_text(tracks)
    if fmt == "kml":
        return kml_text(tracks)
    raise ValueError(f"unknown track format {fmt!r}: one of {', '.join(FORMATS)}")


MAX_RATE_HZ = 10.0
"""[Hz] The most poses per second a track keeps in the WGS84 files by default: a 100 Hz filter's track
is drawn at 10 Hz (0.1-0.3 m apart at a boat's speeds, finer than any GNSS fix); the TUM files keep
every pose. Without it a 10-minute harbour compare wrote 160 MB of GeoJSON/GPX/KML."""


def thinned(traj: Trajectory, max_rate_hz: float | None) -> Trajectory:
    """``traj`` with at most ``max_rate_hz`` poses per second: the first pose, then each pose at least
    ``1 / max_rate_hz`` after the last one kept, and the last pose (``None`` or a track already that
    sparse: ``traj`` itself)."""
    t = np.asarray(traj.t, dtype=float)
    if max_rate_hz is None or len(t) < 3 or not max_rate_hz > 0:
        return traj
    dt = 1.0 / float(max_rate_hz)
    if np.all(np.diff(t) >= dt):
        return traj
    keep, last, tol = [0], t[0], 1e-3 * dt  # (times of a fixed rate differ from it by their rounding)
    for i in range(1, len(t) - 1):
        if t[i] - last >= dt - tol:
            keep.append(i)
            last = t[i]
    keep.append(len(t) - 1)
    return traj.subset(np.array(keep))


def write_wgs84(out: OutDir | str | Path, trajectories: Mapping[str, Trajectory], meta: dict, *,
                stem: str = "trajectory", max_rate_hz: float | None = MAX_RATE_HZ) -> dict[str, Any]:
    """Write ``stem.geojson``, ``stem.gpx`` and ``stem.kml`` (atomically; an :class:`OutDir` records
    them in its manifest) when ``meta`` has a geodetic origin, each track :func:`thinned` to
    ``max_rate_hz`` (``None``: every pose). Returns the summary entry: ``{"wgs84": {"origin": {...},
    "files": [...], "tracks": [...], "max_rate_hz": ...}}``, or ``{"wgs84": None, "wgs84_reason": why}``
    when nothing was written."""
    return write_texts(out, *wgs84_texts(trajectories, meta, stem=stem, max_rate_hz=max_rate_hz))


def wgs84_texts(trajectories: Mapping[str, Trajectory], meta: dict, *, stem: str = "trajectory",
                max_rate_hz: float | None = MAX_RATE_HZ) -> tuple[dict[str, Any], dict[str, str]]:
    """What :func:`write_wgs84` writes, nothing written yet: its summary entry and ``{file name: text}``
    (empty without a geodetic origin)."""
    frame, reason = origin_frame(meta)
    if frame is None:
        return {"wgs84": None, "wgs84_reason": f"{reason}: no GeoJSON/GPX/KML written"}, {}
    tracks = [GeoTrack.from_trajectory(thinned(tr, max_rate_hz), frame, name)
              for name, tr in trajectories.items() if len(tr)]
    texts = {f"{stem}.{fmt}": render(tracks, fmt) for fmt in FORMATS}
    return {"wgs84": {"origin": origin_dict(frame), "files": list(texts), "tracks": [t.name for t in tracks],
                      "max_rate_hz": max_rate_hz}}, texts


def write_texts(out: OutDir | str | Path, entry: dict[str, Any], texts: Mapping[str, str]) -> dict[str, Any]:
    """Write ``texts`` (``{file name: text}``, from :func:`wgs84_texts`) into ``out``, each atomically
    (an :class:`OutDir` records it first); returns ``entry``."""
    for name, text in texts.items():
        write_text_atomic(out.file(name) if isinstance(out, OutDir) else Path(out) / name, text)
    return entry


def origin_dict(frame: LocalFrame) -> dict[str, float]:
    return {"lat": frame.lat0, "lon": frame.lon0, "h": frame.h0}


def record_origin(meta: dict) -> dict[str, float] | None:
    """The log's geodetic origin as ``{"lat", "lon", "h"}`` for a summary (None when it has none)."""
    frame, _ = origin_frame(meta)
    return None if frame is None else origin_dict(frame)
