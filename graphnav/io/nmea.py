"""NMEA 0183 reader (via pynmea2): GGA/RMC fixes, VTG/RMC speed, HDT/HDG/THS heading, ROT, ZDA time.

How sentences become records (full description in docs/nmea.md):

* **Position** -- GGA (preferred) and RMC fixes -> :class:`~graphnav.log.Gnss` in the local
  east-north tangent frame (:class:`graphnav.geodesy.LocalFrame`) at ``origin`` (the first fix
  unless given; stored in ``log.meta["origin"]``). ``sigma`` per axis = HDOP x UERE(fix quality)
  (:data:`UERE_M`; ``DEFAULT_HDOP`` when HDOP is missing, RMC carries none). An RMC position is
  used only when no GGA was seen within ``GGA_HOLD_S`` of sentence time, and at most one fix is
  kept per time stamp, so a receiver sending both does not count each fix twice. GGA quality 0 /
  RMC status ``V`` / mode ``N`` are "no fix" (counted in ``meta["no_fix"]``, not errors).
* **Speed and course** -- SOG/COG (VTG, RMC) are over ground, along the course, not body
  odometry, and the log has no course record. SOG is combined with ROT: at every valid ROT
  sentence, when a SOG no older than ``SOG_MAX_AGE_S`` exists, an
  :class:`~graphnav.log.Odometry` ``(v = SOG, w = -radians(ROT)/60)`` is produced (NMEA ROT is
  deg/min, positive turning to starboard). SOG/COG themselves are returned by
  :func:`parse_nmea` (``NmeaParse.sog_cog``) for movement comparisons, not put in the log.
* **Heading** -- HDT and THS (true) and HDG (magnetic sensor heading + deviation + variation,
  east positive; variation from HDG, else the last RMC variation, else none -- counted in
  ``meta["hdg_without_variation"]``) -> :class:`~graphnav.log.Heading` (yaw via
  :func:`graphnav.geometry.heading_deg_to_yaw`), sigma :data:`HEADING_SIGMA_DEG`.
* **Time** -- from the sentences' UTC time of day (GGA, RMC, ZDA). The date comes from RMC or ZDA:
  with a date, ``t`` is POSIX seconds (UTC); without any, ``t`` is seconds since midnight of the
  first day. Midnight rollovers (time of day dropping by more than 12 h) advance the day.
  Sentences without a time (VTG, HDT, HDG, THS, ROT) take the last time seen; those before the
  first timed sentence take the first time seen. A ZDA moves the clock forward only; a GGA/RMC up to
  ``ZDA_MAX_LEAD_S`` behind a ZDA-set clock is stamped with its own time (``meta["zda_ahead"]``).
* **Errors** -- checksum mismatches and malformed sentences raise :class:`LogError` naming the
  file, line and field; ``lenient=True`` skips them (``meta["skipped"]``, first messages in
  ``meta["skipped_errors"]``); there a bad optional field (variation, SOG, COG, HDOP, date, ...) is
  dropped and counted per field in ``meta["dropped_fields"]``, the sentence kept. Sentence types not
  listed above (GSV, GSA, AIS ``!`` lines, ...) are ignored and counted per type in ``meta["ignored"]``.
"""

from __future__ import annotations

import calendar
import math
import re
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from typing import Any

import pynmea2

from ..errors import LogError
from ..geodesy import LocalFrame
from ..geometry import heading_deg_to_yaw
from ..log import Gnss, Heading, Limits, NavLog, Odometry, Record, check_record, default_limits
from .textlines import Lines, note_truncation

KNOT = 1852.0 / 3600.0  # m/s
#: User-equivalent range error [m] per GGA fix quality: sigma per axis = HDOP * UERE.
UERE_M: dict[int, float] = {1: 3.0, 2: 1.0, 3: 3.0, 4: 0.02, 5: 0.3, 6: 10.0, 7: 3.0, 8: 10.0, 9: 1.0}
#: RMC mode indicator -> GGA quality (A autonomous, D differential, R RTK fixed, F float, E estimated).
MODE_QUALITY = {"A": 1, "D": 2, "P": 3, "R": 4, "F": 5, "E": 6, "M": 7, "S": 8}
DEFAULT_HDOP = 1.5
HEADING_SIGMA_DEG = {"HDT": 0.5, "THS": 0.5, "HDG": 2.0}
SOG_MAX_AGE_S = 2.0
GGA_HOLD_S = 5.0
#: A fix time up to this far behind a ZDA-set clock is the fix's own epoch, not time going backwards
#: (receivers send the ZDA of the coming second(s) before its GGA/RMC: 1 s on et-332, mr-350p, 2 s
#: on the AC12 of the GPSD corpus).
ZDA_MAX_LEAD_S = 2.0
DAY = 86400.0


class THS(pynmea2.TalkerSentence):
    """True heading and status (IEC 61162-1), not built into pynmea2."""

    fields = (("Heading", "heading", float), ("Mode indicator", "mode"))


# ----------------------------------------------------------------------------- field helpers

def _float(raw: str, name: str, *, lo: float = -math.inf, hi: float = math.inf) -> float:
    try:
        v = float(raw)
    except ValueError:
        raise LogError(f"not a number: {raw[:20]!r}", field=name) from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise LogError(f"{raw[:20]!r} out of range [{lo}, {hi}]", field=name)
    return v


def _field(msg: pynmea2.NMEASentence, i: int) -> str:
    return msg.data[i] if i < len(msg.data) else ""


def _num(msg: pynmea2.NMEASentence, name: str, *, lo: float = -math.inf, hi: float = math.inf) -> float | None:
    """Numeric field ``name`` by pynmea2's attribute (its parsed number; None when empty; the raw
    text when pynmea2 could not parse it, or the field has no type there), checked to be finite and
    in ``[lo, hi]``; LogError naming the field otherwise."""
    v = getattr(msg, name, None)
    if v is None:
        return None
    if isinstance(v, str):
        if v.strip() == "":
            return None
        return _float(v, name, lo=lo, hi=hi)
    x = float(v)
    if not math.isfinite(x) or not lo <= x <= hi:
        raise LogError(f"{str(v)[:20]!r} out of range [{lo}, {hi}]", field=name)
    return x


def _tod(msg: pynmea2.NMEASentence) -> float | None:
    """Seconds since midnight from the sentence's time field (GGA, RMC, ZDA: the first), by
    :func:`parse_time_of_day`."""
    return parse_time_of_day(_field(msg, 0))


def _variation(msg: pynmea2.NMEASentence, value: str, direction: str) -> float | None:
    """A magnetic variation or deviation [deg, east positive] from a value and an E/W field."""
    v = _num(msg, value, lo=0.0, hi=180.0)
    if v is None:
        return None
    e = str(getattr(msg, direction, "") or "").strip()
    if e not in ("E", "W"):
        raise LogError(f"direction {e[:5]!r} is not E/W", field=direction)
    return v if e == "E" else -v


def _zda_date(msg: pynmea2.NMEASentence) -> date | None:
    """ZDA's day, month, year (pynmea2 integers); None when all three are empty."""
    parts = [getattr(msg, n, None) for n in ("day", "month", "year")]
    if all(p is None for p in parts):
        return None
    if any(not isinstance(p, int) for p in parts):
        raise LogError(f"date {'/'.join(str(p) for p in parts)[:30]} is not numeric", field="day")
    dd, mm, yy = parts
    if not 1900 <= yy <= 2200:
        raise LogError(f"year {yy} out of range [1900, 2200]", field="year")
    try:
        return date(yy, mm, dd)
    except (ValueError, OverflowError):  # OverflowError: a 40-digit day
        raise LogError(f"date {str(dd)[:12]}/{str(mm)[:12]}/{yy} does not exist", field="day") from None


_TIME = re.compile(r"^([0-9]{2})([0-9]{2})([0-9]{2})(\.[0-9]+)?$")
_DDMM = {True: re.compile(r"^[0-9]{2}([0-9]{2}(?:\.[0-9]*)?)$"),  # ddmm[.mmm]: the minutes' group
         False: re.compile(r"^[0-9]{3}([0-9]{2}(?:\.[0-9]*)?)$")}  # dddmm[.mmm]


def parse_time_of_day(raw: str) -> float | None:
    """``hhmmss[.sss]`` -> seconds since midnight (None when empty).

    The value is pynmea2's (``nmea_utils.timestamp``, what ``msg.timestamp`` gives) once the text is
    checked here, field by field: pynmea2 alone takes ``" 9"`` or ``"+9"`` as a number and gives no
    message naming the field. A leap second (``ss`` = 60, which :class:`datetime.time` cannot hold)
    is the 60th second of its minute."""
    raw = raw.strip()
    if raw == "":
        return None
    m = _TIME.match(raw)
    if m is None:
        raise LogError(f"time {raw[:20]!r} is not hhmmss[.sss]", field="timestamp")
    h, mi, s = int(m[1]), int(m[2]), int(m[3])
    if h > 23 or mi > 59 or s > 60:
        raise LogError(f"time {raw[:20]!r} out of range", field="timestamp")
    if s == 60:
        return h * 3600.0 + mi * 60.0 + float(raw[4:])
    ts = pynmea2.nmea_utils.timestamp(raw)
    return ts.hour * 3600.0 + ts.minute * 60.0 + ts.second + ts.microsecond * 1e-6


def parse_latlon(val: str, hemi: str, *, lat: bool) -> float | None:
    """``ddmm.mmmm``/``dddmm.mmmm`` + N/S/E/W -> signed degrees (None when both empty).

    The value is pynmea2's (``nmea_utils.dm_to_sd``, what ``msg.latitude``/``msg.longitude`` give)
    once the text is checked here: pynmea2 alone reads an empty field or a missing hemisphere as 0 deg,
    and accepts minutes >= 60 and latitudes beyond 90 deg. ``ddmm`` without decimals is accepted."""
    name = "lat" if lat else "lon"
    if val.strip() == "" and hemi.strip() == "":
        return None
    if hemi not in (("N", "S") if lat else ("E", "W")):
        raise LogError(f"hemisphere {hemi[:5]!r} is not {'N/S' if lat else 'E/W'}", field=name + "_dir")
    m = _DDMM[lat].match(val)
    if m is None:
        raise LogError(f"{val[:20]!r} is not {'dd' if lat else 'ddd'}mm.mmmm", field=name)
    minutes = float(m[1])
    if minutes >= 60.0:
        raise LogError(f"minutes {minutes} >= 60", field=name)
    d = pynmea2.nmea_utils.dm_to_sd(val + ("0" if val.endswith(".") else "" if "." in val else ".0"))
    if d > (90.0 if lat else 180.0):
        raise LogError(f"{d:.6f} deg out of range", field=name)
    return -d if hemi in ("S", "W") else d


def parse_date(raw: str, name: str = "datestamp") -> date | None:
    """RMC ``ddmmyy`` -> a date by pynmea2 (``nmea_utils.datestamp``, what ``msg.datestamp`` gives:
    ``strptime``'s years 69-99 -> 19xx, 00-68 -> 20xx) once the text is checked to be six digits
    (``strptime`` alone also takes ``"1199"`` or ``" 11199"``)."""
    raw = raw.strip()
    if raw == "":
        return None
    if len(raw) != 6 or not raw.isdigit():
        raise LogError(f"date {raw[:20]!r} is not ddmmyy", field=name)
    try:
        return pynmea2.nmea_utils.datestamp(raw)
    except ValueError:
        raise LogError(f"date {raw!r} does not exist", field=name) from None


def _posix_midnight(d: date) -> float:
    return float(calendar.timegm(d.timetuple()))


def parse_sentence(line: str, *, require_checksum: bool = False) -> pynmea2.NMEASentence:
    """Parse one sentence with pynmea2; any problem is a :class:`LogError` naming the field."""
    try:
        return pynmea2.parse(line, check=require_checksum)
    except pynmea2.ChecksumError as exc:
        raise LogError(str(exc.args[0]) if exc.args else "checksum error", field="checksum") from None
    except pynmea2.SentenceTypeError as exc:
        raise LogError(f"unknown sentence type: {str(exc.args[0])[:40]}", field="sentence") from None
    except (pynmea2.ParseError, ValueError, TypeError, IndexError, AttributeError, KeyError) as exc:
        raise LogError(f"not an NMEA sentence ({exc.__class__.__name__})", field="sentence") from None


# ----------------------------------------------------------------------------- the decoder

@dataclass
class NmeaParse:
    """Everything a stream of sentences gave: records, SOG/COG samples and counters."""

    records: list[Record] = field(default_factory=list)
    sog_cog: list[tuple[float, float, float]] = field(default_factory=list)  # (t, sog m/s, cog deg | nan)
    counts: Counter = field(default_factory=Counter)


class NmeaDecoder:
    """Turns parsed sentences into records, one at a time (shared by the file reader and live mode).

    ``feed(msg)`` returns the records this sentence completes (often none); with ``keep`` they are
    also collected in ``out`` (the file reader), without (live mode) memory stays flat. ``frame`` is the
    local frame (set from the first fix when None). ``day0`` is the POSIX time of midnight of
    day 0 (``None``: no date yet, ``t`` counts from midnight of the first day until a date arrives).
    """

    def __init__(self, frame: LocalFrame | None = None, *, day0: float | None = None,
                 heading_sigma_deg: dict[str, float] | None = None, default_hdop: float = DEFAULT_HDOP,
                 sog_max_age: float = SOG_MAX_AGE_S, keep: bool = True, limits: Limits | None = None,
                 drop_bad_fields: bool = False, keep_sog_cog: bool = True) -> None:
        self.frame = frame
        self.drop_bad_fields = drop_bad_fields  # lenient: a bad optional field is dropped, the sentence kept
        self.clock_src = ""  # "fix" or "zda": what set the clock last
        self.back_ok = False  # the last sentence moved the clock back by the ZDA rule
        self.limits = limits  # physical validity of every record (graphnav.log.check_record)
        self.keep = keep  # False (live mode): do not accumulate records/SOG samples
        self.keep_sog_cog = keep_sog_cog  # False (read_nmea): count the SOG/COG samples, do not hold them
        self.day0 = day0
        self.days = 0
        self.last_tod: float | None = None
        self.t: float | None = None
        self.heading_sigma_deg = {**HEADING_SIGMA_DEG, **(heading_sigma_deg or {})}
        self.default_hdop = default_hdop
        self.sog_max_age = sog_max_age
        self.sog: tuple[float, float] | None = None  # (t, m/s)
        self.variation: float | None = None  # deg, east positive (from RMC)
        self.last_gga_t = -math.inf
        self.last_fix_t = -math.inf
        self.out = NmeaParse()

    # -- time
    def _stamp(self, tod: float | None, kind: str = "fix") -> float | None:
        """Move the clock to the time of day ``tod`` of a ``"fix"`` (GGA/RMC) or ``"zda"`` sentence.

        The time rule (docs/nmea.md): a time of day that drops by more than 12 h is the next day;
        a fix time up to :data:`ZDA_MAX_LEAD_S` behind a clock that a ZDA set is the fix's own epoch
        (receivers send the ZDA of the coming second before its GGA/RMC): the clock goes back to it
        (``back_ok``, counted in ``zda_ahead``), across midnight too. A ZDA only moves the clock
        forward (:meth:`_zda`)."""
        self.back_ok = False
        if tod is None:
            return self.t
        days, t = self._absolute(tod)
        if self.t is not None and kind == "fix" and self.clock_src == "zda":
            if t - self.t > DAY / 2:  # the ZDA crossed midnight before this fix of the old day
                days -= 1
                t -= DAY
            if 0.0 < self.t - t <= ZDA_MAX_LEAD_S:
                self.back_ok = True
                self.out.counts["zda_ahead"] += 1
        self.days, self.last_tod, self.t, self.clock_src = days, tod, t, kind
        return self.t

    def _absolute(self, tod: float) -> tuple[int, float]:
        """(day count, time) of a time of day: the next day when it drops by more than 12 h."""
        days = self.days
        if self.last_tod is not None and tod < self.last_tod - DAY / 2:
            days += 1
        return days, (self.day0 or 0.0) + days * DAY + tod

    def _set_date(self, d: date | None) -> None:
        if d is not None:
            self.day0 = _posix_midnight(d) - self.days * DAY
            if self.last_tod is not None:
                self.t = self.day0 + self.days * DAY + self.last_tod

    def _optional(self, parse: Any, *args: Any, **kw: Any) -> Any:
        """An optional field parsed by ``parse``: its value, or (``drop_bad_fields``) None when it is
        bad, counted per field in ``dropped_field:<name>`` (the sentence is kept)."""
        try:
            return parse(*args, **kw)
        except LogError as err:
            if not self.drop_bad_fields:
                raise
            self.out.counts["dropped_field:" + (err.field or "?")] += 1
            return None

    def _sog(self, msg: pynmea2.NMEASentence, name: str, unit: float) -> float | None:
        """Speed over ground [m/s] from field ``name`` (``unit`` m/s per field unit), checked against
        the plausible speed (:class:`graphnav.log.Limits`)."""
        v = _num(msg, name, lo=0.0, hi=math.inf)
        if v is None:
            return None
        top = (self.limits or default_limits()).max_speed
        if v * unit > top:
            raise LogError(f"speed {v * unit:.4g} m/s beyond the plausible limit {top:g} m/s", field=name)
        return v * unit

    # -- records
    def _fix(self, t: float | None, lat: float, lon: float, quality: int, hdop: float | None,
             src: str) -> list[Record]:
        if t is None:
            raise LogError("a fix before any time stamp", field="timestamp")
        if t <= self.last_fix_t:  # one fix per epoch (GGA and RMC of the same epoch)
            self.out.counts["duplicate_fix"] += 1
            return []
        if self.frame is None:
            self.frame = LocalFrame(lat, lon, 0.0)
        x, y = self.frame.to_local(lat, lon)
        h = self.default_hdop if hdop is None or hdop <= 0 else hdop
        sigma = h * UERE_M.get(quality, UERE_M[1])
        self.last_fix_t = t
        self.out.counts[f"fix_{src}"] += 1
        return [Gnss(t, float(x), float(y), float(sigma))]

    def feed(self, msg: pynmea2.NMEASentence) -> list[Record]:
        """Decode one parsed sentence. Raises :class:`LogError` (with the field) if malformed."""
        kind = getattr(msg, "sentence_type", type(msg).__name__)
        handler = getattr(self, "_" + kind.lower(), None) if kind in HANDLED else None
        if handler is None:
            self.out.counts["ignored:" + kind] += 1
            return []
        self.back_ok = False
        recs = handler(msg)
        for r in recs:
            check_record(r, self.limits)
        if self.keep:
            self.out.records.extend(recs)
        return recs

    def _gga(self, msg) -> list[Record]:
        tod = _tod(msg)
        q = _num(msg, "gps_qual", lo=0, hi=9)
        quality = 0 if q is None else int(q)
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        hdop = self._optional(_num, msg, "horizontal_dil", lo=0.0, hi=100.0)
        t = self._stamp(tod)
        if quality == 0 or lat is None or lon is None:
            self.out.counts["no_fix"] += 1
            return []
        if t is not None:
            self.last_gga_t = t
        return self._fix(t, lat, lon, quality, hdop, "gga")

    def _rmc(self, msg) -> list[Record]:
        tod = _tod(msg)
        status = str(msg.status).strip()
        if status not in ("A", "V"):
            raise LogError(f"status {status[:5]!r} is not A/V", field="status")
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        mode = str(msg.mode_indicator).strip()[:1]
        d = self._optional(parse_date, str(msg.data[8]) if len(msg.data) > 8 else "")
        sog = self._optional(self._sog, msg, "spd_over_grnd", KNOT)
        cog = self._optional(_num, msg, "true_course", lo=0.0, hi=360.0)
        var = self._optional(_variation, msg, "mag_variation", "mag_var_dir")
        if tod is not None and d is not None:  # the date belongs to this sentence's time
            self._stamp(tod)
            self._set_date(d)
        t = self._stamp(tod)
        if var is not None:
            self.variation = var
        if status == "V" or mode == "N" or lat is None or lon is None:
            self.out.counts["no_fix"] += 1
            return []
        if t is not None and sog is not None:
            self._speed(t, sog, cog)
        if t is not None and t - self.last_gga_t <= GGA_HOLD_S:
            return []
        return self._fix(t, lat, lon, MODE_QUALITY.get(mode, 1), None, "rmc")

    def _zda(self, msg) -> list[Record]:
        tod = _tod(msg)
        if tod is None:  # a receiver without time yet sends empty ZDAs: no time, not an error
            self.out.counts["zda_without_time"] += 1
            return []
        d = self._optional(_zda_date, msg)
        if self.t is not None and not 0.0 <= self._absolute(tod)[1] - self.t <= DAY / 2:
            self.out.counts["zda_behind"] += 1  # behind the clock (or before midnight of a day passed): no new time
            return []
        self._stamp(tod, "zda")
        self._set_date(d)
        return []

    def _speed(self, t: float, sog: float, cog_deg: float | None) -> None:
        self.sog = (t, sog)
        self.out.counts["sog_cog_samples"] += 1
        if self.keep and self.keep_sog_cog:
            self.out.sog_cog.append((t, sog, math.nan if cog_deg is None else cog_deg))

    def _vtg(self, msg) -> list[Record]:
        cog = self._optional(_num, msg, "true_track", lo=0.0, hi=360.0)
        kts = self._optional(self._sog, msg, "spd_over_grnd_kts", KNOT)
        kmh = self._optional(self._sog, msg, "spd_over_grnd_kmph", 1.0 / 3.6)
        if str(msg.faa_mode).strip()[:1] == "N" or (kts is None and kmh is None):
            self.out.counts["no_speed"] += 1
            return []
        if self.t is None:
            self.out.counts["untimed"] += 1
            return []
        self._speed(self.t, kts if kts is not None else kmh, cog)
        return []

    def _heading(self, heading_deg: float, src: str) -> list[Record]:
        if self.t is None:
            self.out.counts["untimed"] += 1
            return []
        sigma = math.radians(self.heading_sigma_deg[src])
        return [Heading(self.t, float(heading_deg_to_yaw(heading_deg % 360.0)), sigma)]

    def _hdt(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        return [] if h is None else self._heading(h, "HDT")

    def _ths(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        if h is None or str(msg.mode).strip()[:1] == "V":
            self.out.counts["invalid_heading"] += 1
            return []
        return self._heading(h, "THS")

    def _hdg(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        if h is None:
            return []
        dev = self._optional(_variation, msg, "deviation", "dev_dir")
        var = self._optional(_variation, msg, "variation", "var_dir")
        if var is None:  # none (or a bad one) in the sentence: the last RMC's
            var = self.variation
            if var is None:
                self.out.counts["hdg_without_variation"] += 1
        return self._heading(h + (dev or 0.0) + (var or 0.0), "HDG")

    def _rot(self, msg) -> list[Record]:
        rot = _num(msg, "rate_of_turn", lo=-1e5, hi=1e5)
        if rot is None or str(msg.status).strip()[:1] == "V":
            self.out.counts["invalid_rot"] += 1
            return []
        if self.t is None:
            self.out.counts["untimed"] += 1
            return []
        if self.sog is None or self.t - self.sog[0] > self.sog_max_age:
            self.out.counts["rot_without_sog"] += 1
            return []
        return [Odometry(self.t, self.sog[1], -math.radians(rot) / 60.0)]


HANDLED = {"GGA", "RMC", "ZDA", "VTG", "HDT", "THS", "HDG", "ROT"}


# ----------------------------------------------------------------------------- files

class _Sentences:
    """The file's sentences (``\r\n``, ``\n`` or ``\r`` separated), decompressed when ``.gz``, read
    afresh on every iteration (two passes, nothing held); a damaged stream:
    :class:`graphnav.io.textlines.Lines` (LogError, or lenient: the lines before it)."""

    def __init__(self, path: Path, lenient: bool, *, quiet: bool = False) -> None:
        self.path, self.lenient, self.quiet = path, lenient, quiet
        self.reader: Lines | None = None

    def __iter__(self) -> Iterator[bytes]:
        self.reader = Lines(self.path, lenient=self.lenient, quiet=self.quiet)
        for _n, raw in self.reader:
            yield from raw.splitlines()


def _decode(raw: bytes) -> str:
    try:
        s = raw.decode("ascii")
    except UnicodeDecodeError:
        raise LogError("non-ASCII bytes in a sentence", field="sentence") from None
    return s.strip().lstrip("\ufeff")


def _first_date_day0(lines: Iterable[bytes]) -> float | None:
    """POSIX midnight of day 0 from the first dated sentence (RMC/ZDA), following rollovers.

    A cheap first pass: only GGA/RMC/ZDA lines are parsed, bad ones are passed over (the main
    pass reports them)."""
    probe = NmeaDecoder(drop_bad_fields=True)
    for raw in lines:
        if raw[3:6] not in (b"GGA", b"RMC", b"ZDA"):
            continue
        try:
            msg = parse_sentence(_decode(raw))
            kind = msg.sentence_type
            if kind == "RMC":
                probe._rmc(msg)
            elif kind == "ZDA":
                probe._zda(msg)
            else:
                probe._stamp(_tod(msg))
        except (LogError, AttributeError):
            continue
        if probe.day0 is not None:
            return probe.day0
    return None


def parse_nmea(path: str | Path, *, lenient: bool = False, origin: tuple[float, float] | None = None,
               require_checksum: bool = False, **decoder_options: Any) -> tuple[NmeaParse, dict[str, Any]]:
    """Decode a file into an :class:`NmeaParse` plus ``meta`` (see the module docstring).

    Sentences are parsed and decoded one line at a time (errors come in line order); only the
    records are kept."""
    path = Path(path)
    lines = _Sentences(path, lenient)
    skipped: list[str] = []
    ignored: Counter = Counter()

    def bad(err: LogError, lineno: int) -> None:
        err = err.located(file=str(path), line=lineno)
        if not lenient:
            raise err from None
        skipped.append(str(err))

    def sentences() -> Iterator[tuple[int, pynmea2.NMEASentence]]:
        for lineno, raw in enumerate(lines, start=1):
            s = ""
            try:
                s = _decode(raw)
                if not s or s.startswith("#"):
                    continue
                if s.startswith("!"):  # AIS and other encapsulated data: not navigation input
                    ignored["!" + s[1:6]] += 1
                    continue
                msg = parse_sentence(s, require_checksum=require_checksum)
            except LogError as err:
                if err.field == "sentence" and err.message.startswith("unknown sentence type"):
                    ignored[s[3:6] if len(s) > 6 else s] += 1
                    continue
                bad(err, lineno)
                continue
            yield lineno, msg

    frame = LocalFrame(float(origin[0]), float(origin[1]), 0.0) if origin is not None else None
    decoder_options.setdefault("drop_bad_fields", lenient)
    dec = NmeaDecoder(frame, day0=_first_date_day0(_Sentences(path, True, quiet=True)), **decoder_options)
    pending: list[tuple[int, pynmea2.NMEASentence]] = []  # untimed sentences before the first time
    last_t = -math.inf
    for lineno, msg in sentences():
        n_before = len(dec.out.records)
        try:
            if dec.t is None and getattr(msg, "sentence_type", "") in ("VTG", "HDT", "THS", "HDG", "ROT"):
                pending.append((lineno, msg))
                continue
            dec.feed(msg)
            back_ok = dec.back_ok  # a fix behind a ZDA by the time rule
            if pending and dec.t is not None:
                todo, pending = pending, []
                for ln, m in todo:
                    try:
                        dec.feed(m)
                    except LogError as err:
                        bad(err, ln)
            if dec.t is not None:
                if dec.t < last_t and not back_ok:
                    raise LogError(f"time goes backwards ({dec.t!r} after {last_t!r})", field="timestamp")
                last_t = dec.t
        except LogError as err:
            del dec.out.records[n_before:]
            bad(err, lineno)
    for _ln, m in pending:  # no sentence carried a time at all
        ignored["untimed:" + getattr(m, "sentence_type", "?")] += 1
    out = dec.out
    meta: dict[str, Any] = {"source": str(path), "format": "nmea0183",
                            "time": "posix" if dec.day0 is not None else "seconds since first UTC midnight"}
    if dec.frame is not None:
        meta["origin"] = {"lat": dec.frame.lat0, "lon": dec.frame.lon0, "h": dec.frame.h0}
    for k, v in sorted(out.counts.items()):
        if k.startswith("ignored:"):
            ignored[k.split(":", 1)[1]] += v
        elif k.startswith("dropped_field:"):
            meta.setdefault("dropped_fields", {})[k.split(":", 1)[1]] = v
        elif k in ("no_fix", "rot_without_sog", "hdg_without_variation", "untimed", "duplicate_fix", "zda_ahead",
                   "zda_behind", "zda_without_time"):
            meta[k] = v
    if ignored:
        meta["ignored"] = dict(sorted(ignored.items()))
    meta["sog_cog_samples"] = out.counts["sog_cog_samples"]
    if lenient:
        note_truncation(meta, lines.reader, skipped)
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    return out, meta


def read_nmea(path: str | Path, *, lenient: bool = False, origin: tuple[float, float] | None = None,
              **options: Any) -> NavLog:
    """Read an NMEA 0183 file (``.nmea``, ``.txt``, ``.log``, optionally ``.gz``) into a :class:`NavLog`.

    ``origin`` = (lat, lon) degrees of the local frame (default: the first fix). Strict by
    default: the first bad sentence raises :class:`LogError` with file, line and field.
    """
    options.setdefault("keep_sog_cog", False)  # the samples are not log records: not held
    out, meta = parse_nmea(path, lenient=lenient, origin=origin, **options)
    return NavLog.from_unsorted(out.records, (), meta)
