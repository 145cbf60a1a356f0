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

import logging
import math
from collections import Counter
from collections.abc import Iterable, Iterator
from datetime import date
from pathlib import Path
from typing import Any

import pynmea2

from ..errors import LogError
from ..geodesy import LocalFrame
from ..log import Limits, NavLog, Record, check_record, note_rot_odometry
from .nmea_clock import SentenceClock
from .nmea_fields import (  # noqa: F401  (the constants and field parsers are part of this module's API)
    DAY,
    DEFAULT_HDOP,
    GGA_HOLD_S,
    HANDLED,
    HEADING_SIGMA_DEG,
    KNOT,
    MODE_QUALITY,
    SOG_MAX_AGE_S,
    THS,
    UERE_M,
    UNKNOWN_VARIATION_SIGMA_DEG,
    UNTIMED,
    VELOCITY_BAD_MODES,
    VELOCITY_SIGMA_MPS,
    WATER_SPEED_SIGMA_FRACTION,
    WATER_SPEED_SIGMA_MPS,
    field_at,
    field_step,
    num,
    parse_date,
    parse_latlon,
    parse_sentence,
    parse_time_of_day,
    posix_midnight,
    raw_field,
    sentence_key,
    sentence_kind,
    time_of_day,
    two_digit_year,
    variation_field,
    velocity_sigma,
    water_speed_sigma,
    zda_date,
)
from .nmea_heading import HeadingSentences
from .nmea_motion import MotionSentences
from .nmea_position import PositionSentences
from .nmea_state import DecodeContext, NmeaParse
from .textlines import Lines, note_truncation

log_ = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- the decoder

#: Which part of :class:`NmeaDecoder` reads which sentence (RMC and ZDA: the decoder itself).
_READERS = {"GGA": ("positions", "gga"), "GNS": ("positions", "gns"), "GLL": ("positions", "gll"),
            "GST": ("positions", "gst"), "VTG": ("motion", "vtg"), "VHW": ("motion", "vhw"),
            "ROT": ("motion", "rot"), "HDT": ("headings", "hdt"), "THS": ("headings", "ths"),
            "HDG": ("headings", "hdg"), "HDM": ("headings", "hdm"), "XDR": ("headings", "xdr"),
            "PASHR": ("headings", "pashr")}
_PARTS = ("ctx", "clock", "positions", "motion", "headings")
DECODER_STATE = tuple(f"{part}.{k}" for part, cls in zip(
    _PARTS, (DecodeContext, SentenceClock, PositionSentences, MotionSentences, HeadingSentences), strict=True)
    for k in cls.STATE)
"""The state a sentence can change, per part of :class:`NmeaDecoder` (``"clock.t"``): saved by
``snapshot()`` and put back by ``restore()``."""


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

    The decoder coordinates its parts: the clock (:class:`~graphnav.io.nmea_clock.SentenceClock`),
    positions (:class:`~graphnav.io.nmea_position.PositionSentences`), motion
    (:class:`~graphnav.io.nmea_motion.MotionSentences`), heading and attitude
    (:class:`~graphnav.io.nmea_heading.HeadingSentences`); it reads RMC (date, position, velocity and
    variation at once) and ZDA itself.
    """

    def __init__(self, frame: LocalFrame | None = None, *, day0: float | None = None,
                 heading_sigma_deg: dict[str, float] | None = None, default_hdop: float = DEFAULT_HDOP,
                 sog_max_age: float = SOG_MAX_AGE_S, keep: bool = True, limits: Limits | None = None,
                 drop_bad_fields: bool = False, keep_sog_cog: bool = True, variation_deg: float | None = None,
                 first_variation: float | None = None) -> None:
        self.ctx = DecodeContext(keep=keep, keep_sog_cog=keep_sog_cog, limits=limits,
                                 drop_bad_fields=drop_bad_fields)
        self.clock = SentenceClock(self.ctx, day0)
        self.positions = PositionSentences(self.ctx, self.clock, frame, default_hdop)
        self.motion = MotionSentences(self.ctx, self.clock, sog_max_age)
        self.headings = HeadingSentences(self.ctx, self.clock, sigma_deg=heading_sigma_deg,
                                         variation_deg=variation_deg, first_variation=first_variation)
        self.readers = {kind: getattr(getattr(self, part), name) for kind, (part, name) in _READERS.items()}
        self.readers.update(RMC=self._rmc, ZDA=self._zda)

    # -- what the reader and live mode ask
    @property
    def out(self) -> NmeaParse:
        return self.ctx.out

    @property
    def t(self) -> float | None:
        return self.clock.t

    @property
    def day0(self) -> float | None:
        return self.clock.day0

    @property
    def back_ok(self) -> bool:
        return self.clock.back_ok

    @property
    def frame(self) -> LocalFrame | None:
        return self.positions.frame

    @frame.setter
    def frame(self, frame: LocalFrame | None) -> None:
        self.positions.frame = frame

    def snapshot(self) -> tuple[Any, ...]:
        """The decoder's state (:data:`DECODER_STATE`), for :meth:`restore`."""
        return tuple(getattr(self, part).snapshot() for part in _PARTS)

    def restore(self, state: tuple[Any, ...]) -> None:
        """Put back a :meth:`snapshot`: as if the sentences since were never fed (``out`` aside)."""
        for part, s in zip(_PARTS, state, strict=True):
            getattr(self, part).restore(s)

    def drop_since(self, n: int) -> None:
        """Forget the records kept since there were ``n`` (a sentence that failed after them)."""
        del self.out.records[n:]
        last = self.positions.last_fix
        if last is not None and last[1] >= len(self.out.records):
            self.positions.last_fix = None

    def feed(self, msg: pynmea2.NMEASentence) -> list[Record]:
        """Decode one parsed sentence. Raises :class:`LogError` (with the field) if malformed."""
        kind = sentence_kind(msg)
        key = sentence_key(msg)
        counts = self.ctx.counts
        reader = self.readers.get(kind) if kind in HANDLED else None
        if reader is None:
            counts["ignored:" + kind] += 1
            counts["skip\x1f" + key + "\x1fnot read by graphnav"] += 1
            return []
        self.clock.back_ok = False
        self.ctx.why = None
        recs = reader(msg)
        for r in recs:
            check_record(r, self.ctx.limits)
        if self.ctx.keep:
            self.out.records.extend(recs)
            self.positions.kept(recs, len(self.out.records))
        if recs or self.ctx.why is None:
            counts["read\x1f" + key] += 1
        else:
            counts["skip\x1f" + key + "\x1f" + self.ctx.why] += 1
        return recs

    def _stamp(self, tod: float | None) -> float | None:
        return self.clock.stamp(tod)

    def _rmc(self, msg: pynmea2.NMEASentence) -> list[Record]:
        """RMC: the date, the variation, the velocity and (when no GGA/GNS came) the position."""
        ctx, clock = self.ctx, self.clock
        tod = time_of_day(msg)
        status = str(msg.status).strip()
        if status not in ("A", "V"):
            raise LogError(f"status {status[:5]!r} is not A/V", field="status")
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        mode = str(msg.mode_indicator).strip()[:1]
        d = ctx.optional(parse_date, str(msg.data[8]) if len(msg.data) > 8 else "")
        sog = ctx.optional(self.motion.sog_field, msg, "spd_over_grnd", KNOT)
        cog = ctx.optional(num, msg, "true_course", lo=0.0, hi=360.0)
        var = ctx.optional(variation_field, msg, "mag_variation", "mag_var_dir")
        if tod is not None and d is not None:  # the date belongs to this sentence's time
            clock.stamp(tod)
            clock.set_date(d)
        t = clock.stamp(tod)
        clock.fix_clock = clock.fix_clock or tod is not None
        if var is not None:
            self.headings.variation = var
        if status == "V" or mode == "N" or lat is None or lon is None:
            return ctx.skip("no fix", "no_fix")
        out: list[Record] = []
        if t is not None and sog is not None:
            self.motion.speed(t, sog, cog)
            if mode not in VELOCITY_BAD_MODES:
                out += self.motion.velocity(t, sog, cog, field_step(raw_field(msg, "spd_over_grnd")) * KNOT,
                                            raw_field(msg, "true_course"))
        if t is not None and t - self.positions.last_gga_t <= GGA_HOLD_S:
            return out
        quality = MODE_QUALITY.get(mode, 1)
        if out:
            return out + self.positions.fix_quiet(t, lat, lon, quality, "rmc")
        return self.positions.fix(t, lat, lon, quality, None, "rmc")

    def _zda(self, msg: pynmea2.NMEASentence) -> list[Record]:
        """ZDA: time and date; it moves the clock forward only."""
        ctx, clock = self.ctx, self.clock
        tod = time_of_day(msg)
        if tod is None:  # a receiver without time yet sends empty ZDAs: no time, not an error
            return ctx.skip("no time yet (empty)", "zda_without_time")
        d = ctx.optional(zda_date, msg)
        if d is not None and two_digit_year(msg):
            ctx.counts["zda_two_digit_year"] += 1
        if clock.t is not None and not 0.0 <= clock.absolute(tod)[1] - clock.t <= DAY / 2:
            # behind the clock (or before midnight of a day passed): no new time
            return ctx.skip("behind the clock", "zda_behind")
        clock.stamp(tod, "zda")
        clock.set_date(d)
        return []


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
        if day0 is not None and not _rmc_variation_text(raw):  # (pynmea2 would read none: not parsed)
            continue
        try:
            msg = parse_sentence(_decode(raw))
            kind = msg.sentence_type
            if kind == "RMC":
                var = variation_field(msg, "mag_variation", "mag_var_dir")
                if day0 is None:
                    probe._rmc(msg)
                if variation is None:
                    variation = var
            elif kind == "ZDA":
                probe._zda(msg)
            else:
                probe._stamp(parse_time_of_day(field_at(msg, 4 if kind == "GLL" else 0)))
        except (LogError, AttributeError):
            continue
        if day0 is None:
            day0 = probe.day0
        if day0 is not None and variation is not None:
            break
    return day0, variation


def _rmc_variation_text(raw: bytes) -> bytes:
    """An RMC line's magnetic-variation field as pynmea2 splits it (the 10th after the type, before the
    checksum), stripped: empty when the field is empty or absent."""
    fields = raw.split(b"*", 1)[0].split(b",", 11)
    return fields[10].strip() if len(fields) > 10 else b""


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
        day0, date_source = posix_midnight(given_date), "--date"
    decoder_options.setdefault("first_variation", first_var)
    dec = NmeaDecoder(frame, day0=day0, **decoder_options)
    pending: list[tuple[int, pynmea2.NMEASentence]] = []  # untimed sentences before the first time
    last_t = -math.inf
    for lineno, msg in sentences():
        n_before = len(dec.out.records)
        try:
            if dec.t is None and sentence_kind(msg) in UNTIMED:
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
            dec.drop_since(n_before)
            bad(err, lineno, sentence_key(msg))
    for _ln, m in pending:  # no sentence carried a time at all
        ignored["untimed:" + sentence_kind(m)] += 1
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
    note_rot_odometry(meta, out.records)
    # every record passed check_record with ``limits`` as the decoder made it (NmeaDecoder.feed; a GST's
    # re-sigma'd fix too): the navigator need not check them again
    return NavLog.from_unsorted(out.records, (), meta).mark_checked(options.get("limits"))
