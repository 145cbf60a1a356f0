"""Positions from NMEA 0183: GGA and GNS (preferred: they carry HDOP), RMC and GLL fixes, GST sigmas.

``sigma`` per axis = HDOP x UERE(fix quality) (:data:`~graphnav.io.nmea_fields.UERE_M`; ``DEFAULT_HDOP``
when HDOP is missing), or the GST of the fix's epoch (``sqrt((sd_lat^2 + sd_lon^2) / 2)``). An RMC/GLL
position is used only when no GGA/GNS came within ``GGA_HOLD_S``; one fix per time stamp."""

from __future__ import annotations

import math
from dataclasses import replace

import pynmea2

from ..errors import LogError
from ..geodesy import LocalFrame
from ..log import Gnss, Record, check_record
from .nmea_clock import SentenceClock
from .nmea_fields import (
    DEFAULT_HDOP,
    GGA_HOLD_S,
    GST_MAX_AGE_S,
    MODE_QUALITY,
    UERE_M,
    field_at,
    num,
    parse_latlon,
    parse_time_of_day,
    time_of_day,
)
from .nmea_state import DecodeContext, Stateful


class PositionSentences(Stateful):
    """GGA, GNS, GLL and GST (RMC's position through :meth:`fix`). ``frame``: the local frame (set
    from the first fix when None); ``last_fix``: (t, index in ``out.records``) of the last fix kept,
    for a GST of the same epoch that comes after it."""

    STATE = ("frame", "last_gga_t", "last_fix_t", "last_fix", "last_gst")

    def __init__(self, ctx: DecodeContext, clock: SentenceClock, frame: LocalFrame | None,
                 default_hdop: float = DEFAULT_HDOP) -> None:
        self.ctx, self.clock = ctx, clock
        self.frame = frame
        self.default_hdop = default_hdop
        self.last_gga_t = -math.inf  # the last GGA/GNS fix (they carry HDOP: RMC/GLL positions wait)
        self.last_fix_t = -math.inf
        self.last_fix: tuple[float, int] | None = None
        self.last_gst: tuple[float, float] | None = None  # (t, sigma m) of the last GST

    def fix(self, t: float | None, lat: float, lon: float, quality: int, hdop: float | None,
            src: str) -> list[Record]:
        """A :class:`~graphnav.log.Gnss` at ``t`` (none for a second fix of the same epoch)."""
        if t is None:
            raise LogError("a fix before any time stamp", field="timestamp")
        if t <= self.last_fix_t:  # one fix per epoch (GGA and RMC of the same epoch)
            return self.ctx.skip("duplicate fix (same time stamp)", "duplicate_fix")
        if self.frame is None:
            self.frame = LocalFrame(lat, lon, 0.0)
        x, y = self.frame.to_local(lat, lon)
        h = self.default_hdop if hdop is None or hdop <= 0 else hdop
        sigma = h * UERE_M.get(quality, UERE_M[1])
        gst = self.last_gst
        if gst is not None and (abs(gst[0] - t) < 1e-3 or 0.0 <= t - gst[0] <= GST_MAX_AGE_S):
            sigma = gst[1]
            self.ctx.counts["fix_sigma_from_gst"] += 1
        self.last_fix_t = t
        self.ctx.counts[f"fix_{src}"] += 1
        return [Gnss(t, float(x), float(y), float(sigma))]

    def fix_quiet(self, t: float | None, lat: float, lon: float, quality: int, src: str) -> list[Record]:
        """:meth:`fix` for a sentence that gave another record already (a duplicate fix is then no
        reason to call the sentence skipped)."""
        why = self.ctx.why
        recs = self.fix(t, lat, lon, quality, None, src)
        self.ctx.why = why
        return recs

    def kept(self, recs: list[Record], end: int) -> None:
        """Note the fix among ``recs``, just appended to ``out.records`` (which now ends at ``end``)."""
        for i, r in enumerate(recs):
            if isinstance(r, Gnss):
                self.last_fix = (r.t, end - len(recs) + i)

    def gga(self, msg: pynmea2.NMEASentence) -> list[Record]:
        tod = time_of_day(msg)
        q = num(msg, "gps_qual", lo=0, hi=9)
        quality = 0 if q is None else int(q)
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        hdop = self.ctx.optional(num, msg, "horizontal_dil", lo=0.0, hi=100.0)
        t = self.clock.stamp(tod)
        self.clock.fix_clock = self.clock.fix_clock or tod is not None
        if quality == 0 or lat is None or lon is None:
            return self.ctx.skip("no fix", "no_fix")
        if t is not None:
            self.last_gga_t = t
        return self.fix(t, lat, lon, quality, hdop, "gga")

    def gns(self, msg: pynmea2.NMEASentence) -> list[Record]:
        tod = time_of_day(msg)
        mode = str(field_at(msg, 5)).strip().upper()
        if any(c not in MODE_QUALITY and c != "N" for c in mode):
            raise LogError(f"mode indicator {mode[:8]!r} is not of A/D/P/R/F/E/M/S/N", field="mode_indicator")
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        hdop = self.ctx.optional(num, msg, "hdop", lo=0.0, hi=100.0)
        t = self.clock.stamp(tod)
        self.clock.fix_clock = self.clock.fix_clock or tod is not None
        used = [c for c in mode if c != "N"]  # one character per constellation
        if not used or lat is None or lon is None:
            return self.ctx.skip("no fix", "no_fix")
        if t is not None:
            self.last_gga_t = t
        quality = min((MODE_QUALITY[c] for c in used), key=lambda q: UERE_M[q])  # the best constellation's
        return self.fix(t, lat, lon, quality, hdop, "gns")

    def gll(self, msg: pynmea2.NMEASentence) -> list[Record]:
        lat = parse_latlon(msg.lat, msg.lat_dir, lat=True)
        lon = parse_latlon(msg.lon, msg.lon_dir, lat=False)
        tod = parse_time_of_day(field_at(msg, 4))
        status = str(field_at(msg, 5)).strip()
        mode = str(field_at(msg, 6)).strip()[:1]
        # the clock is GGA/GNS/RMC's once they have set it (a GLL's time may differ from theirs by a few
        # ms: eXplorist 210); before that (GLL-only logs, GLL + ZDA) a GLL sets it
        t = self.clock.own_time(tod) if self.clock.fix_clock else self.clock.stamp(tod)
        if status != "A" or mode in ("N", "V") or lat is None or lon is None:  # eXplorist 110: status N, mode V
            return self.ctx.skip("no fix", "no_fix")
        if t is None:
            return self.ctx.skip("no time (GLL without its time field)", "untimed")
        if t - self.last_gga_t <= GGA_HOLD_S:
            return self.ctx.skip("position from GGA/GNS")
        return self.fix(t, lat, lon, MODE_QUALITY.get(mode, 1), None, "gll")

    def gst(self, msg: pynmea2.NMEASentence) -> list[Record]:
        tod = time_of_day(msg)
        sd = [num(msg, n, lo=0.0, hi=1e5) for n in ("std_dev_latitude", "std_dev_longitude")]
        if None in sd:  # some receivers give the error ellipse only
            sd = [num(msg, n, lo=0.0, hi=1e5) for n in ("std_dev_major", "std_dev_minor")]
        if None in sd or not (sd[0] > 0 and sd[1] > 0):
            return self.ctx.skip("no standard deviations", "gst_empty")
        t = self.clock.own_time(tod)
        if t is None:
            return self.ctx.skip("before any time", "untimed")
        sigma = math.sqrt(0.5 * (sd[0] ** 2 + sd[1] ** 2))
        self.last_gst = (t, sigma)
        out = self.ctx.out
        if self.ctx.keep and self.last_fix is not None and abs(self.last_fix[0] - t) < 1e-3:
            i = self.last_fix[1]  # the fix of this GST's epoch came first: it gets the GST's sigma
            rec = out.records[i] if i < len(out.records) else None
            if isinstance(rec, Gnss) and rec.t == self.last_fix[0] and rec.sigma != sigma:
                new = replace(rec, sigma=float(sigma))
                check_record(new, self.ctx.limits)
                out.records[i] = new
                out.counts["fix_sigma_from_gst"] += 1
        return []
