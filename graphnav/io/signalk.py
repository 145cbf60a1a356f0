"""Signal K delta JSON in and out (https://signalk.org/specification, "Delta format").

**In** (files: one delta per line, optionally ``.gz``; live: a server's websocket stream,
:mod:`graphnav.online.signalk_ws`): every update's ``values`` are read by path (SI units, angles in
radians clockwise from north as Signal K states them), time from the update's ``timestamp``
(ISO 8601 UTC), ``source`` from its ``$source`` (else ``source.label`` + ``.`` + ``source.src``):

* ``navigation.position`` ``{latitude, longitude}`` -> ``gnss`` (sigma: ``navigation.gnss.horizontalDilution``
  of the same source x the UERE of its ``navigation.gnss.methodQuality``, else 1.5 x 3 m; or the
  ``uncertainty`` [m] a ``meta`` entry of the same update states, as graphnav publishes it);
* ``navigation.speedOverGround`` + ``navigation.courseOverGroundTrue`` (the same source, within
  ``SOG_MAX_AGE_S``) -> ``gnss_velocity``;
* ``navigation.headingTrue`` -> ``heading`` (0.5 deg); ``navigation.headingMagnetic`` ->
  ``heading`` plus ``navigation.magneticVariation`` when known (2 deg; else widened as NMEA's HDG);
* ``navigation.rateOfTurn`` (positive to starboard) -> ``odometry`` (``w = -rate``, ``v`` the newest SOG);
* ``navigation.attitude`` ``{roll, pitch}`` -> ``attitude`` (pitch negated: Signal K's bow up is positive);
* ``navigation.speedThroughWater`` -> ``water_speed``.

Only the own vessel is read: ``context`` absent or ``vessels.self``, the ``self`` of the server's hello
message, else the first delta's context (AIS targets' deltas are counted in ``meta["contexts"]``).
Other paths are counted (``meta["paths"]``). A line that is not a JSON object, a missing or bad
``timestamp``, a value of the wrong type or range is a :class:`LogError` naming file, line and field
(the path); ``lenient`` skips and counts it.

**Out**: :func:`solution_delta` turns an :class:`~graphnav.result.Estimate` into one delta
(``navigation.position``, ``headingTrue``, ``speedOverGround``, ``courseOverGroundTrue``,
``rateOfTurn``; the 1-sigma uncertainties in the update's ``meta``), :func:`record_delta` one log record.
"""

from __future__ import annotations

import calendar
import json
import logging
import math
import re
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import LogError
from ..geodesy import LocalFrame
from ..geometry import heading_deg_to_yaw
from ..log import (
    Attitude,
    Gnss,
    GnssVelocity,
    Heading,
    Limits,
    NavLog,
    Odometry,
    Record,
    WaterSpeed,
    check_record,
    note_rot_odometry,
)
from .nmea_fields import (
    DEFAULT_HDOP,
    HEADING_SIGMA_DEG,
    SOG_MAX_AGE_S,
    UERE_M,
    UNKNOWN_VARIATION_SIGMA_DEG,
    velocity_sigma,
    water_speed_sigma,
)
from .textlines import Lines, note_truncation

log_ = logging.getLogger(__name__)

#: The longest line (one delta) read [bytes]: a server batches at most a few hundred values.
MAX_LINE = 1 << 20
#: Signal K's ``navigation.gnss.methodQuality`` -> the NMEA 0183 GGA quality of :data:`UERE_M`.
METHOD_QUALITY = {"gnss fix": 1, "dgnss fix": 2, "precise gnss": 3, "rtk fixed integer": 4, "rtk float": 5,
                  "estimated (dr) mode": 6, "manual input": 7, "simulator mode": 8}
#: ``navigation.gnss.methodQuality`` of a dead-reckoned (coasted) solution
DR_MODE = "Estimated (DR) mode"
#: ``navigation.gnss.methodQuality`` when there is no solution (coasting stopped at ``coast_max_s``)
NO_FIX = "no GPS"
#: Resolution assumed for values without one (Signal K carries doubles): SOG 0.01 m/s, COG 1e-4 rad.
SOG_STEP, COG_STEP, STW_STEP = 0.01, 1e-4, 0.01
#: The paths read (the rest are counted).
PATHS = ("navigation.position", "navigation.speedOverGround", "navigation.courseOverGroundTrue",
         "navigation.headingTrue", "navigation.headingMagnetic", "navigation.magneticVariation",
         "navigation.rateOfTurn", "navigation.attitude", "navigation.speedThroughWater",
         "navigation.gnss.horizontalDilution", "navigation.gnss.methodQuality")
_ISO = re.compile(r"^(\d{4})-(\d{2})-(\d{2})T(\d{2}):(\d{2}):(\d{2}(?:\.\d+)?)(Z|[+-]00:?00)?$")


def parse_time(raw: Any, name: str = "timestamp") -> float:
    """ISO 8601 UTC (``2014-08-15T19:00:00.540Z``) -> POSIX seconds; LogError naming ``name``."""
    if not isinstance(raw, str):
        raise LogError(f"expected an ISO 8601 time string, got {type(raw).__name__}", field=name)
    m = _ISO.match(raw.strip())
    if m is None:
        raise LogError(f"{raw[:32]!r} is not YYYY-MM-DDThh:mm:ss[.sss]Z", field=name)
    y, mo, d, h, mi = (int(m[i]) for i in range(1, 6))
    s = float(m[6])
    if not (1970 <= y <= 2200 and h <= 23 and mi <= 59 and s < 61):
        raise LogError(f"{raw[:32]!r} out of range", field=name)
    try:
        midnight = calendar.timegm(date(y, mo, d).timetuple())
    except ValueError:
        raise LogError(f"{raw[:32]!r}: no such date", field=name) from None
    return midnight + h * 3600.0 + mi * 60.0 + s


def iso_time(t: float) -> str:
    """POSIX seconds -> ``YYYY-MM-DDThh:mm:ss.sssZ`` (Signal K's timestamps)."""
    d = datetime.fromtimestamp(round(t, 3), UTC)
    return d.strftime("%Y-%m-%dT%H:%M:%S.") + f"{d.microsecond // 1000:03d}Z"


def _num(v: Any, name: str, lo: float = -math.inf, hi: float = math.inf) -> float | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise LogError(f"expected a number, got {type(v).__name__}", field=name)
    try:
        x = float(v)
    except OverflowError:
        raise LogError("number beyond float range", field=name) from None
    if not math.isfinite(x) or not lo <= x <= hi:
        raise LogError(f"{x:.6g} out of range [{lo:g}, {hi:g}]", field=name)
    return x


def _source(upd: dict) -> str:
    s = upd.get("$source")
    if isinstance(s, str) and s:
        return s[:64]
    src = upd.get("source")
    if isinstance(src, dict):
        label, addr = src.get("label"), src.get("src", src.get("talker"))
        return ".".join(str(p) for p in (label, addr) if p not in (None, ""))[:64]
    return ""


def is_signalk_text(lines: list[str]) -> bool:
    """Whether the first non-empty line is a Signal K delta or hello (a JSON object with ``updates``,
    or ``self`` + ``version``)."""
    for s in lines:
        s = s.strip()
        if not s or s.startswith("#"):
            continue
        try:
            obj = json.loads(s)
        except (ValueError, RecursionError):
            return False
        return isinstance(obj, dict) and ("updates" in obj or ("self" in obj and "version" in obj)) \
            and "type" not in obj
    return False


@dataclass
class SignalKDecoder:
    """Deltas in, records out, one at a time (the file reader and live mode). ``frame`` is the local
    frame (from the first fix when None); per-source state is a few numbers per source (at most
    :data:`MAX_SOURCES` sources are tracked: memory stays flat)."""

    frame: LocalFrame | None = None
    limits: Limits | None = None
    self_context: str | None = None
    counts: Counter = field(default_factory=Counter)
    hdop: dict[str, tuple[float, float]] = field(default_factory=dict)  # source -> (hdop, uere)
    sog: dict[str, tuple[float, float]] = field(default_factory=dict)  # source -> (t, m/s)
    cog: dict[str, tuple[float, float]] = field(default_factory=dict)  # source -> (t, rad)
    last_sog: tuple[float, float] | None = None
    variation: float | None = None

    MAX_SOURCES = 256

    def _remember(self, d: dict, key: str, val: Any) -> None:
        if key not in d and len(d) >= self.MAX_SOURCES:
            d.pop(next(iter(d)))
        d[key] = val

    def feed(self, obj: Any) -> list[Record]:
        """One decoded JSON message -> the records its updates give (a hello sets the own context)."""
        if not isinstance(obj, dict):
            raise LogError("a delta must be a JSON object", field="delta")
        if "updates" not in obj:
            if isinstance(obj.get("self"), str):  # the server's hello
                self.self_context = obj["self"]
                return []
            self.counts["message:" + ("hello" if "version" in obj else "other")] += 1
            return []
        ctx = obj.get("context")
        if ctx is not None and not isinstance(ctx, str):
            raise LogError("context must be a string", field="context")
        if ctx not in (None, "vessels.self"):
            if self.self_context is None:
                self.self_context = ctx
            elif ctx != self.self_context and not self.self_context.endswith(ctx) \
                    and not ctx.endswith(self.self_context.removeprefix("vessels.")):
                self.counts["context:" + ctx[:80]] += 1
                return []
        updates = obj["updates"]
        if not isinstance(updates, list):
            raise LogError("updates must be a list", field="updates")
        out: list[Record] = []
        for upd in updates[:1000]:
            if not isinstance(upd, dict):
                raise LogError("an update must be a JSON object", field="updates")
            values = upd.get("values", [])
            if not isinstance(values, list):
                raise LogError("values must be a list", field="values")
            if not values:
                continue
            t = parse_time(upd.get("timestamp"))
            src = _source(upd)
            sigmas = self._meta_sigmas(upd.get("meta"))
            vals: dict[str, Any] = {}
            for pv in values[:1000]:
                if not isinstance(pv, dict) or not isinstance(pv.get("path"), str):
                    raise LogError("each value needs a string 'path'", field="values")
                p = pv["path"]
                if p not in PATHS:
                    self.counts["path:" + p[:80]] += 1
                    continue
                self.counts["path:" + p] += 1
                vals[p] = pv.get("value")
            out.extend(self._records(t, src, vals, sigmas))
        for r in out:
            check_record(r, self.limits)
        return out

    def _meta_sigmas(self, meta: Any) -> dict[str, float]:
        out: dict[str, float] = {}
        if isinstance(meta, list):
            for m in meta[:100]:
                if isinstance(m, dict) and isinstance(m.get("path"), str) and isinstance(m.get("value"), dict):
                    u = _num(m["value"].get("uncertainty"), m["path"] + ".uncertainty", 0.0, 1e6)
                    if u is not None and u > 0:
                        out[m["path"]] = u
        return out

    def _fix(self, t: float, src: str, pos: Any, sigma: float) -> list[Record]:
        if not isinstance(pos, dict):
            raise LogError("expected {latitude, longitude}", field="navigation.position")
        lat = _num(pos.get("latitude"), "navigation.position.latitude", -90.0, 90.0)
        lon = _num(pos.get("longitude"), "navigation.position.longitude", -180.0, 180.0)
        if lat is None or lon is None:
            self.counts["skip:position without latitude/longitude"] += 1
            return []
        if self.frame is None:
            self.frame = LocalFrame(lat, lon, 0.0)
        x, y = self.frame.to_local(lat, lon)
        return [Gnss(t, float(x), float(y), sigma, source=src)]

    def _records(self, t: float, src: str, v: dict[str, Any], sigmas: dict[str, float]) -> list[Record]:
        out: list[Record] = []
        P = "navigation."
        if P + "gnss.horizontalDilution" in v or P + "gnss.methodQuality" in v:
            hdop, uere = self.hdop.get(src, (DEFAULT_HDOP, UERE_M[1]))
            h = _num(v.get(P + "gnss.horizontalDilution"), P + "gnss.horizontalDilution", 0.0, 100.0)
            q = v.get(P + "gnss.methodQuality")
            if isinstance(q, str) and q.strip().lower() in METHOD_QUALITY:
                uere = UERE_M[METHOD_QUALITY[q.strip().lower()]]
            self._remember(self.hdop, src, (h if h else hdop, uere))
        if P + "magneticVariation" in v:
            self.variation = _num(v[P + "magneticVariation"], P + "magneticVariation", -math.pi, math.pi)
        if P + "position" in v:
            hdop, uere = self.hdop.get(src, (DEFAULT_HDOP, UERE_M[1]))
            out += self._fix(t, src, v[P + "position"], sigmas.get(P + "position", hdop * uere))
        sog = _num(v.get(P + "speedOverGround"), P + "speedOverGround", 0.0, 1e3)
        cog = _num(v.get(P + "courseOverGroundTrue"), P + "courseOverGroundTrue", -2 * math.pi, 4 * math.pi)
        if sog is not None:
            self._remember(self.sog, src, (t, sog))
            self.last_sog = (t, sog)
        if cog is not None:
            self._remember(self.cog, src, (t, cog))
        if sog is not None or cog is not None:
            s, c = self.sog.get(src), self.cog.get(src)
            if s is not None and c is not None and abs(s[0] - c[0]) <= SOG_MAX_AGE_S:
                sg = velocity_sigma(s[1], SOG_STEP, COG_STEP)
                out.append(GnssVelocity(t, s[1] * math.sin(c[1]), s[1] * math.cos(c[1]), sg, source=src))
        for path, true in ((P + "headingTrue", True), (P + "headingMagnetic", False)):
            h = _num(v.get(path), path, -2 * math.pi, 4 * math.pi)
            if h is None:
                continue
            sig = HEADING_SIGMA_DEG["HDT" if true else "HDG"]
            if not true:
                if self.variation is None:
                    sig = math.hypot(sig, UNKNOWN_VARIATION_SIGMA_DEG)
                    self.counts["heading without variation"] += 1
                h += self.variation or 0.0
            sig_rad = sigmas.get(path, math.radians(sig))
            out.append(Heading(t, float(heading_deg_to_yaw(math.degrees(h))), sig_rad, source=src))
        rot = _num(v.get(P + "rateOfTurn"), P + "rateOfTurn", -100.0, 100.0)
        if rot is not None:
            if self.last_sog is not None and abs(t - self.last_sog[0]) <= SOG_MAX_AGE_S:
                out.append(Odometry(t, self.last_sog[1], -rot, source=src))
            else:
                self.counts["skip:rateOfTurn without a recent SOG"] += 1
        if P + "attitude" in v:
            a = v[P + "attitude"]
            if not isinstance(a, dict):
                raise LogError("expected {roll, pitch, yaw}", field=P + "attitude")
            roll = _num(a.get("roll"), P + "attitude.roll", -math.pi / 2, math.pi / 2)
            pitch = _num(a.get("pitch"), P + "attitude.pitch", -math.pi / 2, math.pi / 2)
            if roll is not None and pitch is not None:
                out.append(Attitude(t, roll, -pitch, source=src))
        stw = _num(v.get(P + "speedThroughWater"), P + "speedThroughWater", -1e3, 1e3)
        if stw is not None:
            out.append(WaterSpeed(t, stw, water_speed_sigma(stw, STW_STEP), source=src))
        return out


def read_signalk(path: str | Path, *, lenient: bool = False, limits: Limits | None = None,
                 origin: tuple[float, float] | None = None, **_: Any) -> NavLog:
    """Read a file of Signal K deltas (one JSON object a line, optionally ``.gz``) into a
    :class:`NavLog` (see the module docstring). ``origin`` (lat, lon) degrees of the local frame
    (default: the first fix). Strict: the first bad line raises :class:`LogError` naming file, line
    and field; ``lenient`` skips and counts it (``meta["skipped"]``)."""
    path = Path(path)
    frame = LocalFrame(float(origin[0]), float(origin[1]), 0.0) if origin is not None else None
    dec = SignalKDecoder(frame, limits)
    records: list[Record] = []
    skipped: list[str] = []
    lines = Lines(path, lenient=lenient, max_line=MAX_LINE)
    for lineno, raw in lines:
        try:
            s = raw.strip()
            if not s or s.startswith(b"#"):
                continue
            try:
                obj = json.loads(s)
            except (ValueError, RecursionError):  # JSONDecodeError, UnicodeDecodeError, too deep
                raise LogError("not a JSON object", field="delta") from None
            records.extend(dec.feed(obj))
        except LogError as err:
            err = err.located(file=str(path), line=lineno)
            if not lenient:
                raise err from None
            skipped.append(str(err))
    meta: dict[str, Any] = {"source": str(path), "format": "signalk", "time": "posix"}
    if dec.frame is not None:
        meta["origin"] = {"lat": dec.frame.lat0, "lon": dec.frame.lon0, "h": 0.0}
    if dec.self_context:
        meta["context"] = dec.self_context
    c = dec.counts
    meta["paths"] = {k[5:]: n for k, n in sorted(c.items()) if k.startswith("path:")}
    if ctx := {k[8:]: n for k, n in sorted(c.items()) if k.startswith("context:")}:
        meta["contexts"] = ctx
    if lenient:
        note_truncation(meta, lines, skipped)
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    note_rot_odometry(meta, records)
    return NavLog.from_unsorted(records, (), meta)


# ----------------------------------------------------------------------------- out

def _course(yaw: float) -> float:
    """Yaw [rad, CCW from east] -> a Signal K course/heading [rad, clockwise from true north, 0..2pi)."""
    return float((math.pi / 2 - yaw) % (2 * math.pi))


def solution_delta(t: float, vec, frame: LocalFrame, *, cov=None, sog: float | None = None,
                   cog_yaw: float | None = None, w: float | None = None, source: str = "graphnav",
                   context: str = "vessels.self", coasted: bool | None = None) -> dict[str, Any]:
    """One Signal K delta of a navigation solution at ``t``: ``vec`` (x, y, yaw) in ``frame``, its
    3x3 covariance ``cov`` (x, y, yaw; None: no uncertainty), speed/course over ground, yaw rate.
    Uncertainties (1-sigma, SI) go in the update's ``meta`` as ``{"path", "value": {"uncertainty"}}``:
    the position's is the root mean square of the east and north sigmas [m]. ``coasted`` (not None):
    ``navigation.gnss.methodQuality`` is ``"Estimated (DR) mode"`` (a prediction through a gap without
    records, as GGA quality 6) or ``"GNSS Fix"`` (as GGA quality 1): the values of the Signal K
    specification's enum (:data:`METHOD_QUALITY`)."""
    x, y, yaw = (float(a) for a in np.asarray(vec, dtype=float).reshape(3))
    lat, lon = frame.to_geodetic(x, y)
    values: list[dict[str, Any]] = [
        {"path": "navigation.position", "value": {"latitude": float(lat), "longitude": float(lon)}},
        {"path": "navigation.headingTrue", "value": _course(yaw)},
    ]
    if sog is not None and math.isfinite(sog):
        values.append({"path": "navigation.speedOverGround", "value": float(sog)})
    if cog_yaw is not None and math.isfinite(cog_yaw):
        values.append({"path": "navigation.courseOverGroundTrue", "value": _course(cog_yaw)})
    if w is not None and math.isfinite(w):
        values.append({"path": "navigation.rateOfTurn", "value": -float(w)})
    if coasted is not None:
        values.append({"path": "navigation.gnss.methodQuality", "value": DR_MODE if coasted else "GNSS Fix"})
    upd: dict[str, Any] = {"$source": source, "source": {"label": source, "type": "graphnav"},
                           "timestamp": iso_time(t), "values": values}
    if cov is not None:
        c = np.asarray(cov, dtype=float)
        if c.shape == (3, 3) and np.all(np.isfinite(c[:2, :2])) and np.isfinite(c[2, 2]):
            upd["meta"] = [
                {"path": "navigation.position",
                 "value": {"uncertainty": math.sqrt(max(0.0, 0.5 * (c[0, 0] + c[1, 1]))), "units": "m"}},
                {"path": "navigation.headingTrue", "value": {"uncertainty": math.sqrt(max(0.0, c[2, 2])),
                                                             "units": "rad"}},
            ]
    return {"context": context, "updates": [upd]}


def no_fix_delta(t: float, source: str = "graphnav", context: str = "vessels.self") -> dict[str, Any]:
    """The Signal K delta of "no solution" at ``t``: ``navigation.gnss.methodQuality`` "no GPS"
    (:data:`NO_FIX`, the specification's enum) and no position."""
    return {"context": context, "updates": [{"$source": source, "source": {"label": source, "type": "graphnav"},
                                             "timestamp": iso_time(t),
                                             "values": [{"path": "navigation.gnss.methodQuality", "value": NO_FIX}]}]}


def record_delta(rec: Record, frame: LocalFrame, *, source: str | None = None,
                 context: str = "vessels.self") -> dict[str, Any] | None:
    """One log record as a Signal K delta (None for kinds Signal K has no path for): the inverse of
    the reader, for replaying a log to Signal K clients and for tests."""
    if isinstance(rec, Gnss):
        lat, lon = frame.to_geodetic(rec.x, rec.y)
        vals = [{"path": "navigation.position", "value": {"latitude": float(lat), "longitude": float(lon)}}]
    elif isinstance(rec, Heading):
        vals = [{"path": "navigation.headingTrue", "value": _course(rec.yaw)}]
    elif isinstance(rec, GnssVelocity):
        vals = [{"path": "navigation.speedOverGround", "value": math.hypot(rec.vx, rec.vy)},
                {"path": "navigation.courseOverGroundTrue", "value": float(math.atan2(rec.vx, rec.vy) % (2 * math.pi))}]
    elif isinstance(rec, Odometry):
        vals = [{"path": "navigation.rateOfTurn", "value": -rec.w}]
    elif isinstance(rec, Attitude):
        vals = [{"path": "navigation.attitude", "value": {"roll": rec.roll, "pitch": -rec.pitch}}]
    elif isinstance(rec, WaterSpeed):
        vals = [{"path": "navigation.speedThroughWater", "value": rec.v}]
    else:
        return None
    src = source if source is not None else (getattr(rec, "source", "") or "graphnav")
    return {"context": context, "updates": [{"$source": src, "timestamp": iso_time(rec.t), "values": vals}]}


__all__ = ["SignalKDecoder", "is_signalk_text", "iso_time", "parse_time", "read_signalk", "record_delta",
           "solution_delta"]
