"""Motion from NMEA 0183: velocity over ground (RMC/VTG SOG + COG), speed through water (VHW), and
rate of turn (ROT, combined with the last SOG into an odometry record).

``vx = SOG sin(COG)``, ``vy = SOG cos(COG)`` (COG degrees true, clockwise from north), one per time
stamp, sigma :func:`~graphnav.io.nmea_fields.velocity_sigma`; ROT is deg/min, positive to starboard:
``w = -radians(ROT) / 60``."""

from __future__ import annotations

import math

import pynmea2

from ..log import GnssVelocity, Odometry, Record, WaterSpeed
from .nmea_clock import SentenceClock
from .nmea_fields import (
    KNOT,
    SOG_MAX_AGE_S,
    VELOCITY_BAD_MODES,
    field_step,
    num,
    raw_field,
    velocity_sigma,
    water_speed_sigma,
)
from .nmea_state import DecodeContext, Stateful


class MotionSentences(Stateful):
    """VTG, VHW and ROT (RMC's speed through :meth:`speed` and :meth:`velocity`). ``sog``: (t, m/s) of
    the last SOG, for ROT (no older than ``sog_max_age`` [s])."""

    STATE = ("sog", "last_vel_t")

    def __init__(self, ctx: DecodeContext, clock: SentenceClock, sog_max_age: float = SOG_MAX_AGE_S) -> None:
        self.ctx, self.clock = ctx, clock
        self.sog_max_age = sog_max_age
        self.sog: tuple[float, float] | None = None
        self.last_vel_t = -math.inf

    def sog_field(self, msg: pynmea2.NMEASentence, name: str, unit: float) -> float | None:
        """Speed [m/s] from field ``name`` (``unit`` m/s per field unit), checked against the
        plausible speed."""
        v = num(msg, name, lo=0.0, hi=math.inf)
        return None if v is None else self.ctx.speed_value(v, name, unit)

    def speed(self, t: float, sog: float, cog_deg: float | None) -> None:
        """A SOG/COG sample (kept for ROT and, in the file reader, in ``out.sog_cog``)."""
        self.sog = (t, sog)
        self.ctx.counts["sog_cog_samples"] += 1
        if self.ctx.keep and self.ctx.keep_sog_cog:
            self.ctx.out.sog_cog.append((t, sog, math.nan if cog_deg is None else cog_deg))

    def velocity(self, t: float, sog: float, cog_deg: float | None, sog_step: float,
                 cog_raw: str) -> list[Record]:
        """A :class:`GnssVelocity` from SOG [m/s] and COG [deg true] (one per time stamp; a SOG above
        zero without a course gives none)."""
        if t <= self.last_vel_t:
            self.ctx.counts["duplicate_velocity"] += 1
            return []
        if cog_deg is None and sog > 0.0:
            self.ctx.counts["sog_without_cog"] += 1
            return []
        c = math.radians(cog_deg or 0.0)
        sigma = velocity_sigma(sog, sog_step, math.radians(field_step(cog_raw)) if cog_raw.strip() else math.pi)
        self.last_vel_t = t
        return [GnssVelocity(t, sog * math.sin(c), sog * math.cos(c), sigma)]

    def vtg(self, msg: pynmea2.NMEASentence) -> list[Record]:
        ctx, t = self.ctx, self.clock.t
        cog = ctx.optional(num, msg, "true_track", lo=0.0, hi=360.0)
        kts = ctx.optional(self.sog_field, msg, "spd_over_grnd_kts", KNOT)
        kmh = ctx.optional(self.sog_field, msg, "spd_over_grnd_kmph", 1.0 / 3.6)
        mode = str(msg.faa_mode).strip()[:1]
        if mode == "N" or (kts is None and kmh is None):
            return ctx.skip("no speed", "no_speed")
        if t is None:
            return ctx.skip("before any time", "untimed")
        sog = kts if kts is not None else kmh
        self.speed(t, sog, cog)
        if mode in VELOCITY_BAD_MODES:
            return ctx.skip(f"mode {mode}: not a GNSS velocity")
        step = field_step(raw_field(msg, "spd_over_grnd_kts")) * KNOT if kts is not None else \
            field_step(raw_field(msg, "spd_over_grnd_kmph")) / 3.6
        recs = self.velocity(t, sog, cog, step, raw_field(msg, "true_track") if cog is not None else "")
        if not recs:
            return ctx.skip("duplicate velocity (same time stamp)" if t <= self.last_vel_t
                            else "speed without a course")
        return recs

    def vhw(self, msg: pynmea2.NMEASentence) -> list[Record]:
        ctx = self.ctx
        kts = ctx.optional(num, msg, "water_speed_knots", lo=0.0, hi=math.inf)
        kmh = ctx.optional(num, msg, "water_speed_km", lo=0.0, hi=math.inf)
        if kts is None and kmh is None:
            return ctx.skip("no speed", "no_water_speed")
        if self.clock.t is None:
            return ctx.skip("before any time", "untimed")
        if kts is not None:
            v = ctx.speed_value(kts, "water_speed_knots", KNOT)
            step = field_step(raw_field(msg, "water_speed_knots")) * KNOT
        else:
            v = ctx.speed_value(kmh, "water_speed_km", 1.0 / 3.6)
            step = field_step(raw_field(msg, "water_speed_km")) / 3.6
        return [WaterSpeed(self.clock.t, v, water_speed_sigma(v, step))]

    def rot(self, msg: pynmea2.NMEASentence) -> list[Record]:
        t = self.clock.t
        rot = num(msg, "rate_of_turn", lo=-1e5, hi=1e5)
        if rot is None or str(msg.status).strip()[:1] == "V":
            return self.ctx.skip("invalid (status V) or empty", "invalid_rot")
        if t is None:
            return self.ctx.skip("before any time", "untimed")
        if self.sog is None or t - self.sog[0] > self.sog_max_age:
            return self.ctx.skip("no recent SOG", "rot_without_sog")
        return [Odometry(t, self.sog[1], -math.radians(rot) / 60.0)]
