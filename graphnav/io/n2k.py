"""NMEA 2000 (CAN) logs and streams -> navigation records.

**Line formats** (one message or CAN frame per line, detected per line):

* canboat's plain and ``FAST`` text (``analyzer`` input, Signal K's ``.data`` logs):
  ``TIMESTAMP,PRIO,PGN,SRC,DST,LEN,b0,b1,...`` with the bytes in hex and ``TIMESTAMP`` ISO 8601 UTC
  (``2026-08-03T04:27:20.588Z``, or ``2021-07-29-09:00:42.386``). A line of more than 8 bytes is a
  whole message; after a ``# format=FAST`` line, or once a fast-packet PGN came whole, every line is;
  otherwise 8-byte lines of a fast-packet PGN are CAN frames and are reassembled.
* Yacht Devices RAW (YDWG/YDEN gateways): ``hh:mm:ss.sss R 19F80123 b0 b1 ...``: one CAN frame, the
  29-bit identifier in hex (priority, PGN, source, destination), ``R``/``T`` received/sent.
* Actisense N2K ASCII (W2K-1, NGX): ``Ahhmmss.sss SSDDP PPPPP hexbytes``: a whole message (source,
  destination, priority; PGN; payload).

The two time-of-day formats take the day from ``date`` (``--date``); without it ``t`` is seconds since
midnight (``meta["date"]``), as NMEA 0183 logs without a date (docs/nmea.md). Fast-packet frames
are joined by canboat's reassembler and payloads decoded by canboat's PGN database (both from the
``nmea2000`` package, the ``[marine]`` extra: compiled canboat, Apache-2.0); only the PGNs below
are decoded, the rest are counted (``meta["pgns"]``).

**PGNs -> records** (field meanings and units: canboat's ``pgns.json``; angles radians, speeds m/s;
yaw CCW from east, docs/conventions.md). Every record keeps its N2K source address as ``source``
(``"52"``), so that two receivers of one quantity stay apart (choose: ``--drop gnss@52``; fuse: both):

* 129029 GNSS Position Data -> ``gnss``, sigma = HDOP x UERE of its method (the GGA fix qualities
  of NMEA 0183, :data:`graphnav.io.nmea.UERE_M`); method "no GNSS" is no fix (counted).
* 129025 Position, Rapid Update -> ``gnss``, sigma from the same source's last 129029 (HDOP, method)
  within :data:`HOLD_S`, else ``DEFAULT_HDOP`` x 3 m.
* 129026 COG & SOG, Rapid Update -> ``gnss_velocity`` (``vx = SOG sin COG``, ``vy = SOG cos COG``;
  COG referenced to true north only; magnetic COG is counted, not used).
* 127250 Vessel Heading -> ``heading`` (true: as given, sigma 0.5 deg; magnetic: plus deviation and
  variation, sigma 2 deg, widened by ``UNKNOWN_VARIATION_SIGMA_DEG`` when no variation is known).
* 127251 Rate of Turn (positive to starboard) -> ``odometry`` (``w = -rate``, ``v`` = the newest SOG
  of any source no older than ``SOG_MAX_AGE_S``).
* 127257 Attitude (roll positive starboard down, pitch positive bow up) -> ``attitude`` (REP-103:
  pitch negated); its yaw (clockwise from true north: a satellite compass's heading, e.g. the Furuno
  SCX-20 of ``canboat/furuno-*``, which sends no 127250) -> ``heading`` as a true 127250, unless the same
  source sends 127250 (then the yaw is counted, not used).
* 128259 Speed (water referenced) -> ``water_speed``.

Errors: a line that is none of the formats, a bad hex byte, a length that does not match, a value
out of range is a :class:`LogError` naming file, line and field; ``lenient`` skips and counts it.
"""

from __future__ import annotations

import calendar
import logging
import math
import re
from collections import Counter
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from typing import Any

from ..errors import LogError, require
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

#: The PGNs decoded (the rest are counted in ``meta["pgns"]["ignored"]``).
HANDLED = {129025: "position rapid", 129029: "gnss position", 129026: "cog/sog", 127250: "heading",
           127251: "rate of turn", 127257: "attitude", 128259: "speed"}
#: A 129025 takes HDOP and method from its source's 129029 when that is at most this old [s].
HOLD_S = 5.0
#: The longest payload (bytes) a message may have: ISO transport carries up to 1785.
MAX_PAYLOAD = 1785
#: The longest line read [bytes] (a whole 1785-byte message in canboat's text is ~5.4 kB).
MAX_LINE = 16_384
#: Resolution [unit] of the decoded fields (canboat's pgns.json): SOG 0.01 m/s, COG 1e-4 rad, STW 0.01 m/s.
SOG_STEP, COG_STEP, STW_STEP = 0.01, 1e-4, 0.01
DAY = 86400.0

_ISO = re.compile(r"^(\d{4})-(\d{2})-(\d{2})[T\- ](\d{2}):(\d{2}):(\d{2}(?:\.\d+)?)Z?$")
_TOD = re.compile(r"^(\d{2}):?(\d{2}):?(\d{2}(?:\.\d+)?)$")
_HEX2 = re.compile(r"^[0-9A-Fa-f]{1,2}$")


@dataclass(frozen=True, slots=True)
class Frame:
    """One line: time (POSIX s, or seconds of the day when ``tod``), header, payload bytes and whether
    the payload is a whole message (else one CAN frame, perhaps of a fast-packet)."""

    t: float
    tod: bool
    prio: int
    pgn: int
    src: int
    dst: int
    data: bytes
    whole: bool


_MIDNIGHTS: dict[str, float] = {}  # "YYYY-MM-DD" -> POSIX midnight (a log spans few days; bounded below)


def _iso_time(raw: str) -> float:
    m = _ISO.match(raw.strip())
    if m is None:
        raise LogError(f"timestamp {raw[:32]!r} is not YYYY-MM-DDThh:mm:ss[.sss]Z", field="timestamp")
    h, mi, s = int(m[4]), int(m[5]), float(m[6])
    if not (h <= 23 and mi <= 59 and s < 61):
        raise LogError(f"timestamp {raw[:32]!r} out of range", field="timestamp")
    day = f"{m[1]}-{m[2]}-{m[3]}"
    midnight = _MIDNIGHTS.get(day)
    if midnight is None:
        y, mo, d = int(m[1]), int(m[2]), int(m[3])
        try:
            if not 1970 <= y <= 2200:
                raise ValueError
            midnight = float(calendar.timegm(date(y, mo, d).timetuple()))
        except ValueError:
            raise LogError(f"date in {raw[:32]!r} does not exist (or is before 1970 / after 2200)",
                           field="timestamp") from None
        if len(_MIDNIGHTS) > 1000:
            _MIDNIGHTS.clear()
        _MIDNIGHTS[day] = midnight
    return midnight + h * 3600.0 + mi * 60.0 + s


def _tod(raw: str) -> float:
    m = _TOD.match(raw.strip())
    if m is None:
        raise LogError(f"time {raw[:20]!r} is not hh:mm:ss[.sss]", field="timestamp")
    h, mi, s = int(m[1]), int(m[2]), float(m[3])
    if h > 23 or mi > 59 or s >= 61:
        raise LogError(f"time {raw[:20]!r} out of range", field="timestamp")
    return h * 3600.0 + mi * 60.0 + s


def _int(raw: str, name: str, hi: int, base: int = 10) -> int:
    try:
        v = int(raw.strip(), base)
    except ValueError:
        raise LogError(f"{raw[:20]!r} is not an integer", field=name) from None
    if not 0 <= v <= hi:
        raise LogError(f"{v} out of range [0, {hi}]", field=name)
    return v


def _hexbytes(parts: list[str], name: str = "data") -> bytes:
    try:  # the usual two digits a byte
        if all(len(p) == 2 for p in parts):
            return bytes.fromhex("".join(parts))
    except ValueError:
        pass
    for p in parts:
        if not _HEX2.match(p):
            raise LogError(f"{p[:8]!r} is not a hex byte", field=name)
    return bytes(int(p, 16) for p in parts)


def can_id_split(can_id: int) -> tuple[int, int, int, int]:
    """A 29-bit CAN identifier -> (priority, PGN, source, destination) (ISO 11783: PDU1 formats, PF <
    240, carry a destination in the low byte; PDU2 formats broadcast, destination 255)."""
    prio = (can_id >> 26) & 0x7
    src = can_id & 0xFF
    dp_pf = (can_id >> 16) & 0x3FF  # data page + PDU format
    ps = (can_id >> 8) & 0xFF
    if (dp_pf & 0xFF) < 240:
        return prio, dp_pf << 8, src, ps
    return prio, (dp_pf << 8) | ps, src, 255


def parse_line(line: str, *, fast: bool = False) -> Frame | None:
    """One text line -> :class:`Frame` (None for a blank line or a ``#`` comment). ``fast``: canboat
    lines of at most 8 bytes are whole messages too (``# format=FAST``)."""
    s = line.strip()
    if not s or s.startswith("#"):
        return None
    if "," in s:  # canboat: TIMESTAMP,PRIO,PGN,SRC,DST,LEN,bytes...
        parts = s.split(",")
        if len(parts) < 6:
            raise LogError(f"{len(parts)} comma-separated fields, canboat's format has at least 6", field="line")
        t = _iso_time(parts[0])
        prio, pgn = _int(parts[1], "prio", 7), _int(parts[2], "pgn", 0xFFFFF)
        src, dst = _int(parts[3], "src", 255), _int(parts[4], "dst", 255)
        n = _int(parts[5], "len", MAX_PAYLOAD)
        if len(parts) - 6 != n:
            raise LogError(f"{len(parts) - 6} bytes but len says {n}", field="len")
        data = _hexbytes(parts[6:]) if pgn in HANDLED else b""  # the others are only counted
        if pgn in HANDLED and len(data) != n:
            raise LogError(f"{len(data)} bytes but len says {n}", field="len")
        return Frame(t, False, prio, pgn, src, dst, data, fast or n > 8)
    parts = s.split()
    if parts[0][:1] in "Aa" and len(parts) == 4:  # Actisense N2K ASCII: Ahhmmss.sss SSDDP PPPPP hex
        t = _tod(parts[0][1:])
        hdr = parts[1]
        if len(hdr) != 5:
            raise LogError(f"{hdr[:10]!r} is not SSDDP (source, destination, priority in hex)", field="header")
        src, dst, prio = _int(hdr[0:2], "src", 255, 16), _int(hdr[2:4], "dst", 255, 16), _int(hdr[4], "prio", 7, 16)
        pgn = _int(parts[2], "pgn", 0x3FFFF, 16)
        hx = parts[3]
        if len(hx) % 2 or len(hx) > 2 * MAX_PAYLOAD:
            raise LogError("payload is not an even number of hex digits (at most 3570)", field="data")
        data = _hexbytes([hx[i:i + 2] for i in range(0, len(hx), 2)])
        return Frame(t, True, prio, pgn, src, dst, data, True)
    if len(parts) >= 3 and parts[1] in ("R", "T", "r", "t"):  # Yacht Devices RAW: hh:mm:ss.sss R ID bytes
        t = _tod(parts[0])
        can_id = _int(parts[2], "can_id", 0x1FFFFFFF, 16)
        data = _hexbytes(parts[3:])
        if len(data) > 8:
            raise LogError(f"{len(data)} data bytes in one CAN frame (at most 8)", field="data")
        prio, pgn, src, dst = can_id_split(can_id)
        return Frame(t, True, prio, pgn, src, dst, data, False)
    raise LogError("not an NMEA 2000 line (canboat TIMESTAMP,PRIO,PGN,SRC,DST,LEN,bytes; Yacht Devices "
                   "'hh:mm:ss.sss R ID bytes'; Actisense 'Ahhmmss.sss SSDDP PGN hex')", field="line")


def is_n2k_text(lines: list[str]) -> bool:
    """Whether the first non-comment lines of a file are NMEA 2000 text (any format above)."""
    seen = 0
    for s in lines:
        if not s.strip() or s.lstrip().startswith("#"):
            continue
        try:
            if parse_line(s) is None:
                continue
        except LogError:
            return False
        seen += 1
        if seen >= 3:
            break
    return seen > 0


def _canboat():
    """nmea2000's compiled canboat (the ``[marine]`` extra), or one line naming the extra."""
    require("nmea2000", "reading NMEA 2000")
    from nmea2000 import _canboat, backend

    return _canboat, backend


@dataclass
class N2kDecoder:
    """Frames in, records out, one at a time (shared by the file reader and live mode).

    ``feed(frame)`` returns the records the frame completes (fast-packets: on their last frame).
    ``frame`` is the local frame (set from the first fix when None); ``day0`` the POSIX midnight
    added to time-of-day formats (None: seconds of the day, a drop of more than 12 h is the next
    day). Per-source state is a few numbers per address (at most 256 addresses): memory stays flat.
    """

    frame: LocalFrame | None = None
    day0: float | None = None
    limits: Limits | None = None
    sog_max_age: float = SOG_MAX_AGE_S
    counts: Counter = field(default_factory=Counter)  # "pgn:N" read, "ignored:N", "skip:why"
    days: int = 0
    last_tod: float | None = None
    fix_info: dict[int, tuple[float, float, int]] = field(default_factory=dict)  # src -> (t, hdop, method)
    sog: tuple[float, float] | None = None  # (t, m/s): the newest SOG of any source
    variation: float | None = None  # rad, east positive: the last 127250 variation seen
    heading_sources: set[str] = field(default_factory=set)  # sources that send 127250 (their 127257 yaw is not used)

    def __post_init__(self) -> None:
        self._cb, self._backend = _canboat()
        self._reasm = self._cb.Reassembler()

    def time(self, fr: Frame) -> float:
        """The frame's time: POSIX as given, or a time of day placed on ``day0`` (+ rollovers)."""
        if not fr.tod:
            return fr.t
        if self.last_tod is not None and fr.t < self.last_tod - DAY / 2:
            self.days += 1
        self.last_tod = fr.t
        return (self.day0 or 0.0) + self.days * DAY + fr.t

    def payload(self, fr: Frame) -> bytes | None:
        """The whole message of ``fr`` (None while a fast-packet waits for more frames)."""
        if fr.whole or not self._backend.is_fast_pgn(fr.pgn):
            return fr.data
        try:
            return self._reasm.push(fr.pgn, fr.data, fr.src, fr.dst, fr.prio)
        except self._cb.ReassemblyError:
            self.counts["skip:fast-packet frame out of sequence"] += 1
            return None

    def feed(self, fr: Frame) -> list[Record]:
        t = self.time(fr)
        if fr.pgn not in HANDLED:
            self.counts[f"ignored:{fr.pgn}"] += 1
            return []
        data = self.payload(fr)
        if data is None:
            return []
        self.counts[f"pgn:{fr.pgn}"] += 1
        msg = self._backend.decode(fr.pgn, bytes(data), fr.src, fr.dst, fr.prio, "si")
        if msg is None:
            raise LogError(f"PGN {fr.pgn} does not decode ({len(data)} bytes)", field="data")
        v = {f.id: f.value for f in msg.fields}
        raw = {f.id: f.raw_value for f in msg.fields}
        recs = self._records(fr.pgn, t, str(fr.src), fr.src, v, raw)
        for r in recs:
            check_record(r, self.limits)
        return recs

    def _num(self, v: dict, name: str) -> float | None:
        x = v.get(name)
        if x is None:
            return None
        if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
            raise LogError(f"{str(x)[:20]!r} is not a number", field=name)
        return float(x)

    def _fix(self, t: float, src: str, lat: float | None, lon: float | None, sigma: float) -> list[Record]:
        if lat is None or lon is None:
            self.counts["skip:position not available"] += 1
            return []
        if not -90.0 <= lat <= 90.0:
            raise LogError(f"latitude {lat:.7g} out of [-90, 90]", field="latitude")
        if not -180.0 <= lon <= 180.0:
            raise LogError(f"longitude {lon:.7g} out of [-180, 180]", field="longitude")
        if self.frame is None:
            self.frame = LocalFrame(lat, lon, 0.0)
        x, y = self.frame.to_local(lat, lon)
        return [Gnss(t, float(x), float(y), sigma, source=src)]

    def _records(self, pgn: int, t: float, src: str, addr: int, v: dict, raw: dict) -> list[Record]:
        if pgn == 129029:
            method = raw.get("method")
            if method is None or method == 0 or method not in UERE_M:
                self.counts["skip:129029 without a fix"] += 1
                return []
            hdop = self._num(v, "hdop")
            hdop = hdop if hdop is not None and hdop > 0 else DEFAULT_HDOP
            self.fix_info[addr] = (t, hdop, int(method))
            return self._fix(t, src, self._num(v, "latitude"), self._num(v, "longitude"), hdop * UERE_M[int(method)])
        if pgn == 129025:
            info = self.fix_info.get(addr)
            hdop, method = (info[1], info[2]) if info is not None and t - info[0] <= HOLD_S else (DEFAULT_HDOP, 1)
            return self._fix(t, src, self._num(v, "latitude"), self._num(v, "longitude"), hdop * UERE_M[method])
        if pgn == 129026:
            cog, sog = self._num(v, "cog"), self._num(v, "sog")
            if sog is None:
                self.counts["skip:129026 without SOG"] += 1
                return []
            self.sog = (t, sog)
            if cog is None or raw.get("cogReference") != 0:
                self.counts["skip:129026 COG not true"] += 1
                return []
            sig = velocity_sigma(sog, SOG_STEP, COG_STEP)
            return [GnssVelocity(t, sog * math.sin(cog), sog * math.cos(cog), sig, source=src)]
        if pgn == 127250:
            self.heading_sources.add(src)
            hdg = self._num(v, "heading")
            var = self._num(v, "variation")
            if var is not None:
                self.variation = var
            if hdg is None:
                self.counts["skip:127250 without heading"] += 1
                return []
            ref = raw.get("reference")
            if ref == 0:
                return [_true_heading(t, hdg, src)]
            if ref != 1:
                self.counts["skip:127250 reference not true/magnetic"] += 1
                return []
            sig = HEADING_SIGMA_DEG["HDG"]
            dev = self._num(v, "deviation") or 0.0
            var = self.variation
            if var is None:
                sig = math.hypot(sig, UNKNOWN_VARIATION_SIGMA_DEG)
                self.counts["heading without variation"] += 1
                var = 0.0
            true = hdg + dev + var
            return [Heading(t, float(heading_deg_to_yaw(math.degrees(true))), math.radians(sig), source=src)]
        if pgn == 127251:
            rate = self._num(v, "rate")
            if rate is None:
                self.counts["skip:127251 without rate"] += 1
                return []
            if self.sog is None or t - self.sog[0] > self.sog_max_age or t < self.sog[0] - self.sog_max_age:
                self.counts["skip:127251 without a recent SOG"] += 1
                return []
            return [Odometry(t, self.sog[1], -rate, source=src)]
        if pgn == 127257:
            roll, pitch, yaw = self._num(v, "roll"), self._num(v, "pitch"), self._num(v, "yaw")
            out: list[Record] = []
            if yaw is not None:  # a satellite compass's (or AHRS's) heading, true: as a 127250 true heading
                if src in self.heading_sources:
                    self.counts["skip:127257 yaw of a source that sends 127250"] += 1
                else:
                    out.append(_true_heading(t, yaw, src))
            if roll is None or pitch is None:
                self.counts["skip:127257 without roll and pitch"] += 1
                return out
            return [*out, Attitude(t, roll, -pitch, source=src)]
        stw = self._num(v, "speedWaterReferenced")  # 128259
        if stw is None:
            self.counts["skip:128259 without speed through water"] += 1
            return []
        return [WaterSpeed(t, stw, water_speed_sigma(stw, STW_STEP), source=src)]


def _true_heading(t: float, heading: float, src: str) -> Heading:
    """A true heading [rad, clockwise from north] as a record (sigma of an HDT)."""
    return Heading(t, float(heading_deg_to_yaw(math.degrees(heading))), math.radians(HEADING_SIGMA_DEG["HDT"]),
                   source=src)


def _as_day0(d: date | str | None) -> float | None:
    if d is None:
        return None
    if isinstance(d, str):
        try:
            d = date.fromisoformat(d)
        except ValueError:
            raise LogError(f"date {d[:20]!r} is not YYYY-MM-DD", field="date") from None
    return float(calendar.timegm(d.timetuple()))


def read_n2k(path: str | Path, *, lenient: bool = False, limits: Limits | None = None,
             origin: tuple[float, float] | None = None, date: date | str | None = None, **_: Any) -> NavLog:
    """Read an NMEA 2000 text log (any format of the module docstring, optionally ``.gz``) into a
    :class:`NavLog`. ``origin`` (lat, lon) degrees of the local frame (default: the first fix);
    ``date``: the UTC day of time-of-day formats. Strict: the first bad line raises :class:`LogError`
    naming file, line and field; ``lenient`` skips and counts it (``meta["skipped"]``)."""
    path = Path(path)
    frame = LocalFrame(float(origin[0]), float(origin[1]), 0.0) if origin is not None else None
    dec = N2kDecoder(frame, _as_day0(date), limits)
    records: list[Record] = []
    skipped: list[str] = []
    fast = False
    any_tod = False
    lines = Lines(path, lenient=lenient, max_line=MAX_LINE)
    for lineno, raw in lines:
        try:
            s = raw.decode("ascii")
        except UnicodeDecodeError:
            s = None
        try:
            if s is None:
                raise LogError("non-ASCII bytes", field="line")
            if s.lstrip().lower().startswith("# format=fast"):
                fast = True
            fr = parse_line(s, fast=fast)
            if fr is None:
                continue
            if fr.whole and fr.pgn in HANDLED and len(fr.data) > 8 and dec._backend.is_fast_pgn(fr.pgn):
                fast = True  # canboat's FAST text: every line is a whole message
            any_tod |= fr.tod
            records.extend(dec.feed(fr))
        except LogError as err:
            err = err.located(file=str(path), line=lineno)
            if not lenient:
                raise err from None
            skipped.append(str(err))
            dec.counts["skip:bad line"] += 1
    meta: dict[str, Any] = {"source": str(path), "format": "nmea2000"}
    if dec.frame is not None:
        meta["origin"] = {"lat": dec.frame.lat0, "lon": dec.frame.lon0, "h": 0.0}
    if any_tod:
        meta["time"] = "posix" if dec.day0 is not None else "seconds since first UTC midnight"
        meta["date"] = {"source": "--date" if dec.day0 is not None else "none"}
        if dec.day0 is None and records:
            log_.warning("%s: a time-of-day format without --date: times are seconds since UTC midnight", path)
    else:
        meta["time"] = "posix"
    c = dec.counts
    meta["pgns"] = {"read": {k[4:]: n for k, n in sorted(c.items()) if k.startswith("pgn:")},
                    "ignored": {k[8:]: n for k, n in sorted(c.items()) if k.startswith("ignored:")},
                    "skipped": {k[5:]: n for k, n in sorted(c.items()) if k.startswith("skip:")}}
    if lenient:
        note_truncation(meta, lines, skipped)
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    note_rot_odometry(meta, records)
    return NavLog.from_unsorted(records, (), meta)


def record_sources(log: NavLog) -> dict[str, dict[str, int]]:
    """Per record kind, the number of records of each ``source`` (only kinds with a stated source)."""
    out: dict[str, Counter] = {}
    for r in log.records:
        src = getattr(r, "source", "")
        if src:
            out.setdefault(r.kind, Counter())[src] += 1
    return {k: dict(sorted(c.items())) for k, c in out.items()}
