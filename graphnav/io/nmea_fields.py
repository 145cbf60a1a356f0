"""NMEA 0183 fields and constants: the checked parsing of each field a sentence carries (by pynmea2,
with the field named in every error) and the accuracies assumed per sentence (docs/nmea.md).

Used by the sentence decoders (:mod:`graphnav.io.nmea_position`, :mod:`~graphnav.io.nmea_motion`,
:mod:`~graphnav.io.nmea_heading`) and by the NMEA 2000 / Signal K readers for their shared constants."""

from __future__ import annotations

import calendar
import math
import re
from datetime import date
from functools import lru_cache

import pynmea2
from pynmea2.types.proprietary.ash import ASHRATT

from ..errors import LogError

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

def float_field(raw: str, name: str, *, lo: float = -math.inf, hi: float = math.inf) -> float:
    try:
        v = float(raw)
    except ValueError:
        raise LogError(f"not a number: {raw[:20]!r}", field=name) from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise LogError(f"{raw[:20]!r} out of range [{lo}, {hi}]", field=name)
    return v


def field_at(msg: pynmea2.NMEASentence, i: int) -> str:
    return msg.data[i] if i < len(msg.data) else ""


def raw_field(msg: pynmea2.NMEASentence, name: str) -> str:
    """The text of field ``name`` (pynmea2's attribute name: its index in ``name_to_idx``, the map pynmea2's
    own attributes read) as it came, "" when absent."""
    i = getattr(type(msg), "name_to_idx", {}).get(name)
    return "" if i is None else str(field_at(msg, i))


def two_digit_year(msg: pynmea2.NMEASentence) -> bool:
    return len(str(raw_field(msg, "year")).strip()) <= 2


def num(msg: pynmea2.NMEASentence, name: str, *, lo: float = -math.inf, hi: float = math.inf) -> float | None:
    """Numeric field ``name`` by pynmea2's attribute (its parsed number; None when empty; the raw
    text when pynmea2 could not parse it, or the field has no type there), checked to be finite and
    in ``[lo, hi]``; LogError naming the field otherwise."""
    v = getattr(msg, name, None)
    if v is None:
        return None
    if isinstance(v, str):
        if v.strip() == "":
            return None
        return float_field(v, name, lo=lo, hi=hi)
    x = float(v)
    if not math.isfinite(x) or not lo <= x <= hi:
        raise LogError(f"{str(v)[:20]!r} out of range [{lo}, {hi}]", field=name)
    return x


def time_of_day(msg: pynmea2.NMEASentence) -> float | None:
    """Seconds since midnight from the sentence's time field (GGA, RMC, ZDA: the first), by
    :func:`parse_time_of_day`."""
    return parse_time_of_day(field_at(msg, 0))


def variation_field(msg: pynmea2.NMEASentence, value: str, direction: str) -> float | None:
    """A magnetic variation or deviation [deg, east positive] from a value and an E/W field."""
    v = num(msg, value, lo=0.0, hi=180.0)
    if v is None:
        return None
    e = str(getattr(msg, direction, "") or "").strip()
    if e not in ("E", "W"):
        raise LogError(f"direction {e[:5]!r} is not E/W", field=direction)
    return v if e == "E" else -v


def zda_date(msg: pynmea2.NMEASentence) -> date | None:
    """ZDA's day, month, year (pynmea2 integers; a two-digit year as RMC's: 69-99 -> 19xx, 00-68 ->
    20xx); None when all three are empty."""
    parts = [getattr(msg, n, None) for n in ("day", "month", "year")]
    if all(p is None for p in parts):
        return None
    if any(not isinstance(p, int) for p in parts):
        raise LogError(f"date {'/'.join(str(p) for p in parts)[:30]} is not numeric", field="day")
    dd, mm, yy = parts
    if 0 <= yy <= 99 and two_digit_year(msg):  # a two-digit year (Navico GoFree): RMC's rule
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
    return _seconds_of_day(raw)


@lru_cache(maxsize=8)
def _seconds_of_day(raw: str) -> float:
    """pynmea2's time of a checked ``hhmmss[.sss]`` in seconds (kept for the few sentences of one epoch)."""
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
        return _datestamp(raw)
    except ValueError:
        raise LogError(f"date {raw!r} does not exist", field=name) from None


@lru_cache(maxsize=8)
def _datestamp(raw: str) -> date:
    """pynmea2's date of six digits (``strptime``; kept: a log's RMCs repeat one date for a day)."""
    return pynmea2.nmea_utils.datestamp(raw)


@lru_cache(maxsize=8)
def posix_midnight(d: date) -> float:
    """POSIX time of the UTC midnight that starts day ``d`` (kept: every RMC of a day gives it)."""
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


def sentence_key(msg: pynmea2.NMEASentence) -> str:
    """Talker + type of a parsed sentence (``"GPGGA"``, ``"IIHDG"``; ``"PASHR"``, ``"P"`` + maker
    for other proprietary sentences)."""
    if isinstance(msg, ASHRATT):
        return "PASHR"
    kind = getattr(msg, "sentence_type", None)
    if kind is None:
        return "P" + str(getattr(msg, "manufacturer", "") or type(msg).__name__)
    return str(getattr(msg, "talker", "") or "") + kind


def sentence_kind(msg: pynmea2.NMEASentence) -> str:
    """The sentence type (``"GGA"``; ``"PASHR"`` for pynmea2's ``ASHRATT``)."""
    return "PASHR" if isinstance(msg, ASHRATT) else getattr(msg, "sentence_type", type(msg).__name__)
