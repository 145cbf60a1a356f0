"""NMEA 0183 reader (via pynmea2): the records a boat's instruments give.

Which sentence gives which record (full description in docs/nmea.md):

* **Position** -- GGA and GNS (preferred: they carry HDOP), RMC and GLL fixes ->
  :class:`~graphnav.log.Gnss` in the local east-north tangent frame
  (:class:`graphnav.geodesy.LocalFrame`) at ``origin`` (the first fix unless given; stored in
  ``log.meta["origin"]``). ``sigma`` per axis = HDOP x UERE(fix quality) (:data:`UERE_M`;
  ``DEFAULT_HDOP`` when HDOP is missing), or from the GST of the fix's time stamp when the log has
  GST (``sqrt((sd_lat^2 + sd_lon^2) / 2)``). An RMC/GLL position is used only when no GGA/GNS came
  within ``GGA_HOLD_S``, and at most one fix is kept per time stamp. GGA quality 0 / RMC, GLL status
  ``V`` / mode ``N`` are "no fix" (counted, not errors).
* **Velocity over ground** -- SOG/COG of RMC and VTG -> :class:`~graphnav.log.GnssVelocity`
  (``vx = SOG sin(COG)``, ``vy = SOG cos(COG)``: COG is degrees true, clockwise from north), one per
  time stamp, ``sigma`` per axis :func:`velocity_sigma` (:data:`VELOCITY_SIGMA_MPS` combined with the
  fields' rounding). SOG is also combined with ROT: at every valid ROT sentence, when a SOG no older
  than ``SOG_MAX_AGE_S`` exists, an :class:`~graphnav.log.Odometry` ``(v = SOG, w = -radians(ROT)/60)``
  is produced (NMEA ROT is deg/min, positive turning to starboard).
* **Speed through water** -- VHW -> :class:`~graphnav.log.WaterSpeed`, ``sigma_v``
  :func:`water_speed_sigma`. VHW's heading fields are not read (HDG/HDT are the heading sources).
* **Heading** -- HDT and THS (true), HDG (magnetic sensor heading + deviation + variation, east
  positive) and HDM (magnetic + variation) -> :class:`~graphnav.log.Heading` (yaw via
  :func:`graphnav.geometry.heading_deg_to_yaw`), sigma :data:`HEADING_SIGMA_DEG`. The variation of
  an HDG/HDM that carries none: the last RMC's, else (file reader) the file's first RMC variation, else
  ``variation_deg`` when given; else the magnetic heading stands for the true one with its sigma
  widened by :data:`UNKNOWN_VARIATION_SIGMA_DEG` (counted in ``meta["hdg_without_variation"]``).
* **Attitude** -- PASHR and XDR (angular displacement ``A``/``D`` named ROLL/HEEL and
  PTCH/PITCH/TRIM) -> :class:`~graphnav.log.Attitude` (REP-103: NMEA roll is starboard-down positive,
  as ours; NMEA pitch is bow-up positive, ours bow-down: negated).
* **Time** -- from the sentences' UTC time of day (GGA, GNS, RMC, GLL, ZDA). The date comes from RMC
  or ZDA (a two-digit ZDA year is read as RMC's: 69-99 -> 19xx, 00-68 -> 20xx): with a date, ``t``
  is POSIX seconds (UTC); without one in the log, ``date`` (CLI ``--date YYYY-MM-DD``) is the day of
  the first time of day; without either, ``t`` is seconds since midnight of the first day
  (``meta["date"]["source"] = "none"``, a warning names ``--date``). Midnight rollovers (time of
  day dropping by more than 12 h) advance the day. Sentences without a time (VTG, VHW, HDT, HDG,
  HDM, THS, ROT, XDR) take the last time seen; those before the first timed sentence take the first
  time seen. GST and PASHR records carry their own time stamp but do not move the clock. A ZDA
  moves the clock forward only; a GGA/RMC up to ``ZDA_MAX_LEAD_S`` behind a ZDA-set clock is stamped
  with its own time (``meta["zda_ahead"]``).
* **Errors** -- checksum mismatches and malformed sentences raise :class:`LogError` naming the
  file, line and field; ``lenient=True`` skips them (``meta["skipped"]``, first messages in
  ``meta["skipped_errors"]``); there a bad optional field (variation, SOG, COG, HDOP, date, ...) is
  dropped and counted per field in ``meta["dropped_fields"]``, the sentence kept. Sentence types not
  listed above (GSV, GSA, MWV, AIS ``!`` lines, ...) are ignored and counted per type in
  ``meta["ignored"]``. ``meta["sentences"]`` counts, per talker + type (``GPGGA``, ``IIHDG``), the
  sentences read and those skipped with the reason.
"""

from __future__ import annotations

import calendar
import logging
import math
import re
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from datetime import date
from pathlib import Path
from typing import Any

import pynmea2
from pynmea2.types.proprietary.ash import ASHRATT

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
    default_limits,
)
from .textlines import Lines, note_truncation

log_ = logging.getLogger(__name__)

KNOT = 1852.0 / 3600.0  # m/s
#: User-equivalent range error [m] per GGA fix quality: sigma per axis = HDOP * UERE.
UERE_M: dict[int, float] = {1: 3.0, 2: 1.0, 3: 3.0, 4: 0.02, 5: 0.3, 6: 10.0, 7: 3.0, 8: 10.0, 9: 1.0}
#: RMC/GLL/GNS mode indicator -> GGA quality (A autonomous, D differential, R RTK fixed, F float, E estimated).
MODE_QUALITY = {"A": 1, "D": 2, "P": 3, "R": 4, "F": 5, "E": 6, "M": 7, "S": 8}
DEFAULT_HDOP = 1.5
HEADING_SIGMA_DEG = {"HDT": 0.5, "THS": 0.5, "HDG": 2.0, "HDM": 2.0}
#: An HDG/HDM whose magnetic variation is unknown stands for the true heading with its sigma widened
#: by this much [deg] (root sum of squares): |variation| is below 10 deg over most navigable water
#: at mid latitudes, and can reach 20-30 deg at high latitudes.
UNKNOWN_VARIATION_SIGMA_DEG = 10.0
#: 1-sigma [m/s] per axis of a GNSS (Doppler) velocity: twice the 0.05 m/s speed accuracy that
#: consumer receivers' datasheets state (u-blox M8/F9), for older receivers and multipath.
VELOCITY_SIGMA_MPS = 0.1
#: Modes whose SOG/COG is no GNSS measurement: N no fix, E dead reckoning, M manual input.
VELOCITY_BAD_MODES = frozenset("NEM")
#: 1-sigma of a speed log through water: an absolute part [m/s] and a part proportional to the speed
#: (paddle-wheel and ultrasonic logs are calibrated to a few percent; fouling and heel add more).
WATER_SPEED_SIGMA_MPS = 0.1
WATER_SPEED_SIGMA_FRACTION = 0.05
#: XDR transducer names (angular displacement, degrees) read as roll and as pitch.
XDR_ROLL = frozenset({"ROLL", "HEEL"})
XDR_PITCH = frozenset({"PTCH", "PITCH", "TRIM"})
SOG_MAX_AGE_S = 2.0
GGA_HOLD_S = 5.0
#: A GST is used for a fix without one of its own time stamp when at most this old [s].
GST_MAX_AGE_S = 2.0
#: A fix time up to this far behind a ZDA-set clock is the fix's own epoch, not time going backwards
#: (receivers send the ZDA of the coming second(s) before its GGA/RMC: 1 s on et-332, mr-350p, 2 s
#: on the AC12 of the GPSD corpus).
ZDA_MAX_LEAD_S = 2.0
DAY = 86400.0
#: The sentences graphnav reads (by pynmea2's sentence type; PASHR is pynmea2's ``ASHRATT``).
HANDLED = {"GGA", "GNS", "RMC", "GLL", "GST", "ZDA", "VTG", "VHW", "HDT", "THS", "HDG", "HDM", "ROT", "XDR", "PASHR"}
#: Sentences without a time of day: before the first timed sentence they wait for it.
UNTIMED = ("VTG", "VHW", "HDT", "THS", "HDG", "HDM", "ROT", "XDR")


def velocity_sigma(sog: float, sog_step: float, cog_step: float) -> float:
    """1-sigma per axis [m/s] of a velocity from SOG [m/s] and COG: :data:`VELOCITY_SIGMA_MPS`
    combined (root sum of squares) with the rounding of the fields: a uniform rounding error of step
    ``q`` has sigma ``q / sqrt(12)``; ``sog_step`` [m/s] is the SOG field's last digit, ``cog_step``
    [rad] the COG field's (across the course it moves the velocity by ``sog * cog_step``)."""
    return math.sqrt(VELOCITY_SIGMA_MPS ** 2 + (sog_step ** 2 + (sog * cog_step) ** 2) / 12.0)


def water_speed_sigma(v: float, step: float) -> float:
    """1-sigma [m/s] of a speed through water ``v`` [m/s] whose field rounds to ``step`` [m/s]:
    ``sqrt(WATER_SPEED_SIGMA_MPS^2 + (WATER_SPEED_SIGMA_FRACTION v)^2 + step^2 / 12)``."""
    return math.sqrt(WATER_SPEED_SIGMA_MPS ** 2 + (WATER_SPEED_SIGMA_FRACTION * v) ** 2 + step ** 2 / 12.0)


def field_step(raw: str) -> float:
    """The step of a numeric field's last digit (``"04.7"`` -> 0.1, ``"310"`` -> 1)."""
    raw = raw.strip()
    if "." not in raw:
        return 1.0
    return 10.0 ** -len(raw.split(".", 1)[1])


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


def _raw(msg: pynmea2.NMEASentence, name: str) -> str:
    """The text of field ``name`` (pynmea2's attribute name) as it came, "" when absent."""
    names = [f[1] for f in msg.fields]
    return str(_field(msg, names.index(name))) if name in names else ""


def _two_digit_year(msg: pynmea2.NMEASentence) -> bool:
    return len(str(_raw(msg, "year")).strip()) <= 2


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
    """ZDA's day, month, year (pynmea2 integers; a two-digit year as RMC's: 69-99 -> 19xx, 00-68 ->
    20xx); None when all three are empty."""
    parts = [getattr(msg, n, None) for n in ("day", "month", "year")]
    if all(p is None for p in parts):
        return None
    if any(not isinstance(p, int) for p in parts):
        raise LogError(f"date {'/'.join(str(p) for p in parts)[:30]} is not numeric", field="day")
    dd, mm, yy = parts
    if 0 <= yy <= 99 and _two_digit_year(msg):  # a two-digit year (Navico GoFree): RMC's rule
        yy += 1900 if yy >= 69 else 2000
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


def sentence_key(msg: pynmea2.NMEASentence) -> str:
    """Talker + type of a parsed sentence (``"GPGGA"``, ``"IIHDG"``; ``"PASHR"``, ``"P"`` + maker
    for other proprietary sentences)."""
    if isinstance(msg, ASHRATT):
        return "PASHR"
    kind = getattr(msg, "sentence_type", None)
    if kind is None:
        return "P" + str(getattr(msg, "manufacturer", "") or type(msg).__name__)
    return str(getattr(msg, "talker", "") or "") + kind


def _kind(msg: pynmea2.NMEASentence) -> str:
    return "PASHR" if isinstance(msg, ASHRATT) else getattr(msg, "sentence_type", type(msg).__name__)


DECODER_STATE = ("frame", "clock_src", "back_ok", "day0", "days", "last_tod", "t", "sog", "variation", "fix_clock",
                 "last_gga_t", "last_fix_t", "last_vel_t", "last_fix", "gst", "why")
"""The attributes of :class:`NmeaDecoder` a sentence can change (each a scalar, a tuple or an immutable
frame): its state, saved by ``snapshot()`` and put back by ``restore()``."""


class NmeaDecoder:
    """Turns parsed sentences into records, one at a time (shared by the file reader and live mode).

    ``feed(msg)`` returns the records this sentence completes (often none); with ``keep`` they are
    also collected in ``out`` (the file reader), without (live mode) memory stays flat. ``frame`` is the
    local frame (set from the first fix when None). ``day0`` is the POSIX time of midnight of
    day 0 (``None``: no date yet, ``t`` counts from midnight of the first day until a date arrives).
    ``variation_deg`` is the magnetic variation [deg, east positive] for HDG/HDM when neither they nor
    an RMC give one (``first_variation``: the file's first RMC variation, found by the file reader).
    :meth:`snapshot` / :meth:`restore` save and put back the state a sentence can change (live mode
    undoes a sentence whose time stamp it rejects).
    """


    def __init__(self, frame: LocalFrame | None = None, *, day0: float | None = None,
                 heading_sigma_deg: dict[str, float] | None = None, default_hdop: float = DEFAULT_HDOP,
                 sog_max_age: float = SOG_MAX_AGE_S, keep: bool = True, limits: Limits | None = None,
                 drop_bad_fields: bool = False, keep_sog_cog: bool = True, variation_deg: float | None = None,
                 first_variation: float | None = None) -> None:
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
        self.first_variation = first_variation
        self.variation_deg = variation_deg
        self.fix_clock = False  # a GGA, GNS or RMC time has set the clock
        self.last_gga_t = -math.inf  # the last GGA/GNS fix (they carry HDOP: RMC/GLL positions wait)
        self.last_fix_t = -math.inf
        self.last_vel_t = -math.inf
        self.last_fix: tuple[float, int] | None = None  # (t, index in out.records) of the last fix kept
        self.gst: tuple[float, float] | None = None  # (t, sigma m) of the last GST
        self.why: str | None = None  # why the current sentence gave nothing (None: it was read)
        self.out = NmeaParse()

    def snapshot(self) -> tuple[Any, ...]:
        """The decoder's state (:data:`DECODER_STATE`), for :meth:`restore`."""
        return tuple(getattr(self, k) for k in DECODER_STATE)

    def restore(self, state: tuple[Any, ...]) -> None:
        """Put back a :meth:`snapshot`: as if the sentences since were never fed (``out`` aside)."""
        for k, v in zip(DECODER_STATE, state, strict=True):
            setattr(self, k, v)

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

    def _own_time(self, tod: float | None) -> float | None:
        """The time of a sentence that carries a time of day but does not move the clock (GST,
        PASHR): the nearest day to the clock's; the clock's time when it has none."""
        if tod is None:
            return self.t
        t = self._absolute(tod)[1]
        if self.t is not None and t - self.t > DAY / 2:
            t -= DAY
        return t

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

    def _skip(self, reason: str, counter: str | None = None) -> list[Record]:
        """Nothing from this sentence, for ``reason`` (in ``meta["sentences"]``); ``counter`` also
        counts it under that name (the older per-reason meta keys)."""
        self.why = reason
        if counter:
            self.out.counts[counter] += 1
        return []

    def _speed_value(self, v: float, name: str, unit: float) -> float:
        """A speed field's value [field unit] -> m/s, checked against the plausible speed
        (:class:`graphnav.log.Limits`)."""
        top = (self.limits or default_limits()).max_speed
        if v * unit > top:
            raise LogError(f"speed {v * unit:.4g} m/s beyond the plausible limit {top:g} m/s", field=name)
        return v * unit

    def _sog(self, msg: pynmea2.NMEASentence, name: str, unit: float) -> float | None:
        """Speed [m/s] from field ``name`` (``unit`` m/s per field unit), checked against the
        plausible speed."""
        v = _num(msg, name, lo=0.0, hi=math.inf)
        return None if v is None else self._speed_value(v, name, unit)

    # -- records
    def _fix(self, t: float | None, lat: float, lon: float, quality: int, hdop: float | None,
             src: str) -> list[Record]:
        if t is None:
            raise LogError("a fix before any time stamp", field="timestamp")
        if t <= self.last_fix_t:  # one fix per epoch (GGA and RMC of the same epoch)
            return self._skip("duplicate fix (same time stamp)", "duplicate_fix")
        if self.frame is None:
            self.frame = LocalFrame(lat, lon, 0.0)
        x, y = self.frame.to_local(lat, lon)
        h = self.default_hdop if hdop is None or hdop <= 0 else hdop
        sigma = h * UERE_M.get(quality, UERE_M[1])
        if self.gst is not None and (abs(self.gst[0] - t) < 1e-3 or 0.0 <= t - self.gst[0] <= GST_MAX_AGE_S):
            sigma = self.gst[1]
            self.out.counts["fix_sigma_from_gst"] += 1
        self.last_fix_t = t
        self.out.counts[f"fix_{src}"] += 1
        return [Gnss(t, float(x), float(y), float(sigma))]

    def feed(self, msg: pynmea2.NMEASentence) -> list[Record]:
        """Decode one parsed sentence. Raises :class:`LogError` (with the field) if malformed."""
        kind = _kind(msg)
        key = sentence_key(msg)
        handler = getattr(self, "_" + kind.lower(), None) if kind in HANDLED else None
        if handler is None:
            self.out.counts["ignored:" + kind] += 1
            self.out.counts["skip\x1f" + key + "\x1fnot read by graphnav"] += 1
            return []
        self.back_ok = False
        self.why = None
        recs = handler(msg)
        for r in recs:
            check_record(r, self.limits)
        if self.keep:
            self.out.records.extend(recs)
            for i, r in enumerate(recs):
                if isinstance(r, Gnss):
                    self.last_fix = (r.t, len(self.out.records) - len(recs) + i)
        if recs or self.why is None:
            self.out.counts["read\x1f" + key] += 1
        else:
            self.out.counts["skip\x1f" + key + "\x1f" + self.why] += 1
        return recs

    def _gga(self, msg) -> list[Record]:
        tod = _tod(msg)
        q = _num(msg, "gps_qual", lo=0, hi=9)
        quality = 0 if q is None else int(q)
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        hdop = self._optional(_num, msg, "horizontal_dil", lo=0.0, hi=100.0)
        t = self._stamp(tod)
        self.fix_clock = self.fix_clock or tod is not None
        if quality == 0 or lat is None or lon is None:
            return self._skip("no fix", "no_fix")
        if t is not None:
            self.last_gga_t = t
        return self._fix(t, lat, lon, quality, hdop, "gga")

    def _gns(self, msg) -> list[Record]:
        tod = _tod(msg)
        mode = str(_field(msg, 5)).strip().upper()
        if any(c not in MODE_QUALITY and c != "N" for c in mode):
            raise LogError(f"mode indicator {mode[:8]!r} is not of A/D/P/R/F/E/M/S/N", field="mode_indicator")
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        hdop = self._optional(_num, msg, "hdop", lo=0.0, hi=100.0)
        t = self._stamp(tod)
        self.fix_clock = self.fix_clock or tod is not None
        used = [c for c in mode if c != "N"]  # one character per constellation
        if not used or lat is None or lon is None:
            return self._skip("no fix", "no_fix")
        if t is not None:
            self.last_gga_t = t
        quality = min((MODE_QUALITY[c] for c in used), key=lambda q: UERE_M[q])  # the best constellation's
        return self._fix(t, lat, lon, quality, hdop, "gns")

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
        self.fix_clock = self.fix_clock or tod is not None
        if var is not None:
            self.variation = var
        if status == "V" or mode == "N" or lat is None or lon is None:
            return self._skip("no fix", "no_fix")
        out: list[Record] = []
        if t is not None and sog is not None:
            self._speed(t, sog, cog)
            if mode not in VELOCITY_BAD_MODES:
                out += self._velocity(t, sog, cog, field_step(_raw(msg, "spd_over_grnd")) * KNOT,
                                      _raw(msg, "true_course"))
        if t is not None and t - self.last_gga_t <= GGA_HOLD_S:
            return out
        if out:
            return out + self._fix_quiet(t, lat, lon, MODE_QUALITY.get(mode, 1), "rmc")
        return self._fix(t, lat, lon, MODE_QUALITY.get(mode, 1), None, "rmc")

    def _fix_quiet(self, t: float | None, lat: float, lon: float, quality: int, src: str) -> list[Record]:
        """:meth:`_fix` for a sentence that gave another record already (a duplicate fix is then no
        reason to call the sentence skipped)."""
        why = self.why
        recs = self._fix(t, lat, lon, quality, None, src)
        self.why = why
        return recs

    def _gll(self, msg) -> list[Record]:
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        tod = parse_time_of_day(_field(msg, 4))
        status = str(_field(msg, 5)).strip()
        mode = str(_field(msg, 6)).strip()[:1]
        # the clock is GGA/GNS/RMC's once they have set it (a GLL's time may differ from theirs by a few
        # ms: eXplorist 210); before that (GLL-only logs, GLL + ZDA) a GLL sets it
        t = self._own_time(tod) if self.fix_clock else self._stamp(tod)
        if status != "A" or mode in ("N", "V") or lat is None or lon is None:  # eXplorist 110: status N, mode V
            return self._skip("no fix", "no_fix")
        if t is None:
            return self._skip("no time (GLL without its time field)", "untimed")
        if t - self.last_gga_t <= GGA_HOLD_S:
            return self._skip("position from GGA/GNS")
        return self._fix(t, lat, lon, MODE_QUALITY.get(mode, 1), None, "gll")

    def _gst(self, msg) -> list[Record]:
        tod = _tod(msg)
        sd = [_num(msg, n, lo=0.0, hi=1e5) for n in ("std_dev_latitude", "std_dev_longitude")]
        if None in sd:  # some receivers give the error ellipse only
            sd = [_num(msg, n, lo=0.0, hi=1e5) for n in ("std_dev_major", "std_dev_minor")]
        if None in sd or not (sd[0] > 0 and sd[1] > 0):
            return self._skip("no standard deviations", "gst_empty")
        t = self._own_time(tod)
        if t is None:
            return self._skip("before any time", "untimed")
        sigma = math.sqrt(0.5 * (sd[0] ** 2 + sd[1] ** 2))
        self.gst = (t, sigma)
        if self.keep and self.last_fix is not None and abs(self.last_fix[0] - t) < 1e-3:
            i = self.last_fix[1]  # the fix of this GST's epoch came first: it gets the GST's sigma
            rec = self.out.records[i] if i < len(self.out.records) else None
            if isinstance(rec, Gnss) and rec.t == self.last_fix[0] and rec.sigma != sigma:
                new = replace(rec, sigma=float(sigma))
                check_record(new, self.limits)
                self.out.records[i] = new
                self.out.counts["fix_sigma_from_gst"] += 1
        return []

    def _zda(self, msg) -> list[Record]:
        tod = _tod(msg)
        if tod is None:  # a receiver without time yet sends empty ZDAs: no time, not an error
            return self._skip("no time yet (empty)", "zda_without_time")
        d = self._optional(_zda_date, msg)
        if d is not None and _two_digit_year(msg):
            self.out.counts["zda_two_digit_year"] += 1
        if self.t is not None and not 0.0 <= self._absolute(tod)[1] - self.t <= DAY / 2:
            # behind the clock (or before midnight of a day passed): no new time
            return self._skip("behind the clock", "zda_behind")
        self._stamp(tod, "zda")
        self._set_date(d)
        return []

    def _speed(self, t: float, sog: float, cog_deg: float | None) -> None:
        self.sog = (t, sog)
        self.out.counts["sog_cog_samples"] += 1
        if self.keep and self.keep_sog_cog:
            self.out.sog_cog.append((t, sog, math.nan if cog_deg is None else cog_deg))

    def _velocity(self, t: float, sog: float, cog_deg: float | None, sog_step: float,
                  cog_raw: str) -> list[Record]:
        """A :class:`GnssVelocity` from SOG [m/s] and COG [deg true] (one per time stamp; a SOG above
        zero without a course gives none)."""
        if t <= self.last_vel_t:
            self.out.counts["duplicate_velocity"] += 1
            return []
        if cog_deg is None and sog > 0.0:
            self.out.counts["sog_without_cog"] += 1
            return []
        c = math.radians(cog_deg or 0.0)
        sigma = velocity_sigma(sog, sog_step, math.radians(field_step(cog_raw)) if cog_raw.strip() else math.pi)
        self.last_vel_t = t
        return [GnssVelocity(t, sog * math.sin(c), sog * math.cos(c), sigma)]

    def _vtg(self, msg) -> list[Record]:
        cog = self._optional(_num, msg, "true_track", lo=0.0, hi=360.0)
        kts = self._optional(self._sog, msg, "spd_over_grnd_kts", KNOT)
        kmh = self._optional(self._sog, msg, "spd_over_grnd_kmph", 1.0 / 3.6)
        mode = str(msg.faa_mode).strip()[:1]
        if mode == "N" or (kts is None and kmh is None):
            return self._skip("no speed", "no_speed")
        if self.t is None:
            return self._skip("before any time", "untimed")
        sog = kts if kts is not None else kmh
        self._speed(self.t, sog, cog)
        if mode in VELOCITY_BAD_MODES:
            return self._skip(f"mode {mode}: not a GNSS velocity")
        step = field_step(_raw(msg, "spd_over_grnd_kts")) * KNOT if kts is not None else \
            field_step(_raw(msg, "spd_over_grnd_kmph")) / 3.6
        recs = self._velocity(self.t, sog, cog, step, _raw(msg, "true_track") if cog is not None else "")
        if not recs:
            return self._skip("duplicate velocity (same time stamp)" if self.t <= self.last_vel_t
                              else "speed without a course")
        return recs

    def _vhw(self, msg) -> list[Record]:
        kts = self._optional(_num, msg, "water_speed_knots", lo=0.0, hi=math.inf)
        kmh = self._optional(_num, msg, "water_speed_km", lo=0.0, hi=math.inf)
        if kts is None and kmh is None:
            return self._skip("no speed", "no_water_speed")
        if self.t is None:
            return self._skip("before any time", "untimed")
        if kts is not None:
            v = self._speed_value(kts, "water_speed_knots", KNOT)
            step = field_step(_raw(msg, "water_speed_knots")) * KNOT
        else:
            v = self._speed_value(kmh, "water_speed_km", 1.0 / 3.6)
            step = field_step(_raw(msg, "water_speed_km")) / 3.6
        return [WaterSpeed(self.t, v, water_speed_sigma(v, step))]

    def _heading(self, heading_deg: float, src: str, extra_sigma_deg: float = 0.0) -> list[Record]:
        if self.t is None:
            return self._skip("before any time", "untimed")
        sigma = math.radians(math.hypot(self.heading_sigma_deg[src], extra_sigma_deg))
        return [Heading(self.t, float(heading_deg_to_yaw(heading_deg % 360.0)), sigma)]

    def _hdt(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        return self._skip("empty") if h is None else self._heading(h, "HDT")

    def _ths(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        if h is None or str(msg.mode).strip()[:1] == "V":
            return self._skip("invalid (mode V) or empty", "invalid_heading")
        return self._heading(h, "THS")

    def _known_variation(self) -> float | None:
        """The variation for an HDG/HDM without one: the last RMC's, the file's first, the stated one."""
        for v in (self.variation, self.first_variation, self.variation_deg):
            if v is not None:
                return v
        return None

    def _magnetic(self, h: float, var: float | None, src: str) -> list[Record]:
        if var is None:
            var = self._known_variation()
        if var is None:  # no variation anywhere: the magnetic heading, its sigma widened
            if self.t is not None:
                self.out.counts["hdg_without_variation"] += 1
            return self._heading(h, src, UNKNOWN_VARIATION_SIGMA_DEG)
        return self._heading(h + var, src)

    def _hdg(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        if h is None:
            return self._skip("empty")
        dev = self._optional(_variation, msg, "deviation", "dev_dir")
        var = self._optional(_variation, msg, "variation", "var_dir")
        return self._magnetic(h + (dev or 0.0), var, "HDG")

    def _hdm(self, msg) -> list[Record]:
        h = _num(msg, "heading", lo=0.0, hi=360.0)
        if h is None:
            return self._skip("empty")
        return self._magnetic(h, None, "HDM")

    def _rot(self, msg) -> list[Record]:
        rot = _num(msg, "rate_of_turn", lo=-1e5, hi=1e5)
        if rot is None or str(msg.status).strip()[:1] == "V":
            return self._skip("invalid (status V) or empty", "invalid_rot")
        if self.t is None:
            return self._skip("before any time", "untimed")
        if self.sog is None or self.t - self.sog[0] > self.sog_max_age:
            return self._skip("no recent SOG", "rot_without_sog")
        return [Odometry(self.t, self.sog[1], -math.radians(rot) / 60.0)]

    def _attitude(self, t: float | None, roll_deg: float | None, pitch_deg: float | None,
                  sigma_deg: float = math.nan) -> list[Record]:
        if roll_deg is None or pitch_deg is None:
            return self._skip("no roll and pitch", "attitude_incomplete")
        if t is None:
            return self._skip("before any time", "untimed")
        return [Attitude(t, math.radians(roll_deg), -math.radians(pitch_deg), math.radians(sigma_deg))]

    def _xdr(self, msg) -> list[Record]:
        roll = pitch = None
        data = msg.data
        for i in range(0, len(data) - 3, 4):
            typ, raw, unit, name = (str(x).strip() for x in data[i:i + 4])
            which = "roll" if name.upper() in XDR_ROLL else "pitch" if name.upper() in XDR_PITCH else None
            if which is None or typ != "A" or raw == "":
                continue
            if unit != "D":
                raise LogError(f"unit {unit[:5]!r} of an angle is not D (degrees)", field=name)
            v = self._optional(_float, raw, name, lo=-90.0, hi=90.0)
            if which == "roll":
                roll = v
            else:
                pitch = v
        return self._attitude(self.t, roll, pitch)

    def _pashr(self, msg) -> list[Record]:
        tod = parse_time_of_day(_field(msg, 1))
        roll = _num(msg, "roll", lo=-90.0, hi=90.0)
        pitch = _num(msg, "pitch", lo=-90.0, hi=90.0)
        acc = [self._optional(_num, msg, n, lo=0.0, hi=90.0) for n in ("roll_accuracy", "pitch_accuracy")]
        sigma = max((a for a in acc if a is not None and a > 0.0), default=math.nan)
        return self._attitude(self._own_time(tod), roll, pitch, sigma)


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


def _first_date_day0(lines: Iterable[bytes]) -> tuple[float | None, float | None]:
    """(POSIX midnight of day 0 from the first dated sentence (RMC/ZDA), following rollovers; the
    first RMC magnetic variation [deg, east positive]).

    A cheap first pass: only GGA/GNS/GLL/RMC/ZDA lines are parsed, bad ones are passed over (the main
    pass reports them)."""
    probe = NmeaDecoder(drop_bad_fields=True, keep=False)
    day0 = variation = None
    for raw in lines:
        kind = raw[3:6]
        if kind not in (b"GGA", b"RMC", b"ZDA", b"GNS", b"GLL") or (day0 is not None and kind != b"RMC"):
            continue
        try:
            msg = parse_sentence(_decode(raw))
            kind = msg.sentence_type
            if kind == "RMC":
                var = _variation(msg, "mag_variation", "mag_var_dir")
                if day0 is None:
                    probe._rmc(msg)
                if variation is None:
                    variation = var
            elif kind == "ZDA":
                probe._zda(msg)
            else:
                probe._stamp(parse_time_of_day(_field(msg, 4 if kind == "GLL" else 0)))
        except (LogError, AttributeError):
            continue
        if day0 is None:
            day0 = probe.day0
        if day0 is not None and variation is not None:
            break
    return day0, variation


def _as_date(value: date | str | None) -> date | None:
    """``date`` or ``"YYYY-MM-DD"`` (the ``--date`` flag) -> a date; ValueError naming the form."""
    if value is None or isinstance(value, date):
        return value
    try:
        return date.fromisoformat(str(value).strip())
    except ValueError:
        raise ValueError(f"--date {str(value)[:30]!r}: expected YYYY-MM-DD") from None


def sentence_table(counts: Counter) -> dict[str, dict[str, Any]]:
    """``{"GPGGA": {"read": n, "skipped": {reason: n}}}`` from a decoder's counts (sorted)."""
    out: dict[str, dict[str, Any]] = {}
    for k, v in counts.items():
        parts = k.split("\x1f")
        if parts[0] == "read":
            out.setdefault(parts[1], {})["read"] = v
        elif parts[0] == "skip":
            out.setdefault(parts[1], {}).setdefault("skipped", {})[parts[2]] = v
    return {k: {"read": out[k].get("read", 0), **({"skipped": dict(sorted(out[k]["skipped"].items()))}
                                                  if "skipped" in out[k] else {})} for k in sorted(out)}


def parse_nmea(path: str | Path, *, lenient: bool = False, origin: tuple[float, float] | None = None,
               require_checksum: bool = False, date: date | str | None = None,
               **decoder_options: Any) -> tuple[NmeaParse, dict[str, Any]]:
    """Decode a file into an :class:`NmeaParse` plus ``meta`` (see the module docstring).

    ``date`` (a :class:`datetime.date` or ``"YYYY-MM-DD"``) is the UTC day of the first time of day
    in a log that has no date of its own (RMC, dated ZDA); a log's own date wins. Sentences are
    parsed and decoded one line at a time (errors come in line order); only the records are kept."""
    path = Path(path)
    given_date = _as_date(date)
    lines = _Sentences(path, lenient)
    skipped: list[str] = []
    ignored: Counter = Counter()
    counts: Counter = Counter()

    def bad(err: LogError, lineno: int, key: str) -> None:
        err = err.located(file=str(path), line=lineno)
        if not lenient:
            raise err from None
        skipped.append(str(err))
        counts["skip\x1f" + key + "\x1f" + f"bad field {err.field or '?'}"] += 1

    def raw_key(s: str) -> str:
        head = s[1:6] if len(s) > 6 and s[0] in "$!" else ""
        return head if head.isalnum() and head.isupper() else "?"

    def sentences() -> Iterator[tuple[int, pynmea2.NMEASentence]]:
        for lineno, raw in enumerate(lines, start=1):
            s = ""
            try:
                s = _decode(raw)
                if not s or s.startswith("#"):
                    continue
                if s.startswith("!"):  # AIS and other encapsulated data: not navigation input
                    ignored["!" + s[1:6]] += 1
                    counts["skip\x1f!" + raw_key(s) + "\x1fencapsulated (AIS): not navigation input"] += 1
                    continue
                msg = parse_sentence(s, require_checksum=require_checksum)
            except LogError as err:
                if err.field == "sentence" and err.message.startswith("unknown sentence type"):
                    ignored[s[3:6] if len(s) > 6 else s] += 1
                    counts["skip\x1f" + raw_key(s) + "\x1funknown to pynmea2"] += 1
                    continue
                bad(err, lineno, raw_key(s))
                continue
            yield lineno, msg

    frame = LocalFrame(float(origin[0]), float(origin[1]), 0.0) if origin is not None else None
    decoder_options.setdefault("drop_bad_fields", lenient)
    day0, first_var = _first_date_day0(_Sentences(path, True, quiet=True))
    date_source = "log" if day0 is not None else "none"
    if day0 is None and given_date is not None:
        day0, date_source = _posix_midnight(given_date), "--date"
    decoder_options.setdefault("first_variation", first_var)
    dec = NmeaDecoder(frame, day0=day0, **decoder_options)
    pending: list[tuple[int, pynmea2.NMEASentence]] = []  # untimed sentences before the first time
    last_t = -math.inf
    for lineno, msg in sentences():
        n_before = len(dec.out.records)
        try:
            if dec.t is None and _kind(msg) in UNTIMED:
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
                        bad(err, ln, sentence_key(m))
            if dec.t is not None:
                if dec.t < last_t and not back_ok:
                    raise LogError(f"time goes backwards ({dec.t!r} after {last_t!r})", field="timestamp")
                last_t = dec.t
        except LogError as err:
            del dec.out.records[n_before:]
            if dec.last_fix is not None and dec.last_fix[1] >= len(dec.out.records):
                dec.last_fix = None
            bad(err, lineno, sentence_key(msg))
    for _ln, m in pending:  # no sentence carried a time at all
        ignored["untimed:" + _kind(m)] += 1
        counts["skip\x1f" + sentence_key(m) + "\x1fno sentence in the log carries a time"] += 1
    out = dec.out
    meta: dict[str, Any] = {"source": str(path), "format": "nmea0183",
                            "time": "posix" if dec.day0 is not None else "seconds since first UTC midnight"}
    meta["date"] = _date_meta(date_source, dec.day0, given_date)
    if date_source == "none" and out.records:
        log_.warning("%s: no date in the log (no RMC, no dated ZDA): times are seconds since UTC midnight of the "
                     "first day; give the date with --date YYYY-MM-DD (API: date=) for POSIX times", path)
    if dec.frame is not None:
        meta["origin"] = {"lat": dec.frame.lat0, "lon": dec.frame.lon0, "h": dec.frame.h0}
    for k, v in sorted(out.counts.items()):
        if k.startswith("ignored:"):
            ignored[k.split(":", 1)[1]] += v
        elif k.startswith("dropped_field:"):
            meta.setdefault("dropped_fields", {})[k.split(":", 1)[1]] = v
        elif k in ("no_fix", "rot_without_sog", "hdg_without_variation", "untimed", "duplicate_fix", "zda_ahead",
                   "zda_behind", "zda_without_time", "zda_two_digit_year", "duplicate_velocity", "sog_without_cog",
                   "fix_sigma_from_gst", "attitude_incomplete"):
            meta[k] = v
    if ignored:
        meta["ignored"] = dict(sorted(ignored.items()))
    meta["sog_cog_samples"] = out.counts["sog_cog_samples"]
    meta["sentences"] = sentence_table(out.counts + counts)
    if lenient:
        note_truncation(meta, lines.reader, skipped)
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    return out, meta


def _date_meta(source: str, day0: float | None, given: date | None) -> dict[str, Any]:
    """``meta["date"]``: where the date came from and the UTC day of ``t``'s first midnight."""
    import datetime as _dt

    out: dict[str, Any] = {"source": source}
    if day0 is not None:
        out["day0"] = _dt.datetime.fromtimestamp(day0, _dt.UTC).date().isoformat()
    if given is not None and source == "log":
        out["note"] = f"--date {given.isoformat()} not used: the log has its own date"
    if source == "none":
        out["note"] = ("no date in the log (RMC, dated ZDA): t is seconds since UTC midnight of the first day; "
                       "--date YYYY-MM-DD gives POSIX time")
    return out


def read_nmea(path: str | Path, *, lenient: bool = False, origin: tuple[float, float] | None = None,
              date: date | str | None = None, **options: Any) -> NavLog:
    """Read an NMEA 0183 file (``.nmea``, ``.txt``, ``.log``, optionally ``.gz``) into a :class:`NavLog`.

    ``origin`` = (lat, lon) degrees of the local frame (default: the first fix). ``date``
    (``"YYYY-MM-DD"`` or a :class:`datetime.date`): the UTC day of a log without a date of its own.
    Strict by default: the first bad sentence raises :class:`LogError` with file, line and field.
    """
    options.setdefault("keep_sog_cog", False)  # the samples are not log records: not held
    out, meta = parse_nmea(path, lenient=lenient, origin=origin, date=date, **options)
    return NavLog.from_unsorted(out.records, (), meta)
