"""Heading and attitude from NMEA 0183.

Heading: HDT and THS (true), HDG (magnetic sensor heading + deviation + variation, east positive) and
HDM (magnetic + variation) -> :class:`~graphnav.log.Heading`, sigma
:data:`~graphnav.io.nmea_fields.HEADING_SIGMA_DEG`. The variation of an HDG/HDM that carries none: the
last RMC's, else the file's first RMC variation, else ``variation_deg`` when given; else the magnetic
heading stands for the true one, its sigma widened by ``UNKNOWN_VARIATION_SIGMA_DEG``.
Attitude: PASHR and XDR (``A``/``D`` transducers named ROLL/HEEL and PTCH/PITCH/TRIM) ->
:class:`~graphnav.log.Attitude` (NMEA pitch is bow-up positive, ours bow-down: negated)."""

from __future__ import annotations

import math

import pynmea2

from ..errors import LogError
from ..geometry import heading_deg_to_yaw
from ..log import Attitude, Heading, Record
from .nmea_clock import SentenceClock
from .nmea_fields import (
    HEADING_SIGMA_DEG,
    UNKNOWN_VARIATION_SIGMA_DEG,
    XDR_PITCH,
    XDR_ROLL,
    field_at,
    float_field,
    num,
    parse_time_of_day,
    variation_field,
)
from .nmea_state import DecodeContext, Stateful


class HeadingSentences(Stateful):
    """HDT, THS, HDG, HDM, XDR and PASHR. ``variation``: the last RMC's [deg, east positive]."""

    STATE = ("variation",)

    def __init__(self, ctx: DecodeContext, clock: SentenceClock, *, sigma_deg: dict[str, float] | None = None,
                 variation_deg: float | None = None, first_variation: float | None = None) -> None:
        self.ctx, self.clock = ctx, clock
        self.sigma_deg = {**HEADING_SIGMA_DEG, **(sigma_deg or {})}
        self.variation: float | None = None
        self.first_variation = first_variation
        self.variation_deg = variation_deg

    def heading(self, heading_deg: float, src: str, extra_sigma_deg: float = 0.0) -> list[Record]:
        if self.clock.t is None:
            return self.ctx.skip("before any time", "untimed")
        sigma = math.radians(math.hypot(self.sigma_deg[src], extra_sigma_deg))
        return [Heading(self.clock.t, float(heading_deg_to_yaw(heading_deg % 360.0)), sigma)]

    def hdt(self, msg: pynmea2.NMEASentence) -> list[Record]:
        h = num(msg, "heading", lo=0.0, hi=360.0)
        return self.ctx.skip("empty") if h is None else self.heading(h, "HDT")

    def ths(self, msg: pynmea2.NMEASentence) -> list[Record]:
        h = num(msg, "heading", lo=0.0, hi=360.0)
        if h is None or str(msg.mode).strip()[:1] == "V":
            return self.ctx.skip("invalid (mode V) or empty", "invalid_heading")
        return self.heading(h, "THS")

    def known_variation(self) -> float | None:
        """The variation for an HDG/HDM without one: the last RMC's, the file's first, the stated one."""
        for v in (self.variation, self.first_variation, self.variation_deg):
            if v is not None:
                return v
        return None

    def magnetic(self, h: float, var: float | None, src: str) -> list[Record]:
        if var is None:
            var = self.known_variation()
        if var is None:  # no variation anywhere: the magnetic heading, its sigma widened
            if self.clock.t is not None:
                self.ctx.counts["hdg_without_variation"] += 1
            return self.heading(h, src, UNKNOWN_VARIATION_SIGMA_DEG)
        return self.heading(h + var, src)

    def hdg(self, msg: pynmea2.NMEASentence) -> list[Record]:
        h = num(msg, "heading", lo=0.0, hi=360.0)
        if h is None:
            return self.ctx.skip("empty")
        dev = self.ctx.optional(variation_field, msg, "deviation", "dev_dir")
        var = self.ctx.optional(variation_field, msg, "variation", "var_dir")
        return self.magnetic(h + (dev or 0.0), var, "HDG")

    def hdm(self, msg: pynmea2.NMEASentence) -> list[Record]:
        h = num(msg, "heading", lo=0.0, hi=360.0)
        if h is None:
            return self.ctx.skip("empty")
        return self.magnetic(h, None, "HDM")

    def attitude(self, t: float | None, roll_deg: float | None, pitch_deg: float | None,
                 sigma_deg: float = math.nan) -> list[Record]:
        if roll_deg is None or pitch_deg is None:
            return self.ctx.skip("no roll and pitch", "attitude_incomplete")
        if t is None:
            return self.ctx.skip("before any time", "untimed")
        return [Attitude(t, math.radians(roll_deg), -math.radians(pitch_deg), math.radians(sigma_deg))]

    def xdr(self, msg: pynmea2.NMEASentence) -> list[Record]:
        roll = pitch = None
        data = msg.data
        for i in range(0, len(data) - 3, 4):
            typ, raw, unit, name = (str(x).strip() for x in data[i:i + 4])
            which = "roll" if name.upper() in XDR_ROLL else "pitch" if name.upper() in XDR_PITCH else None
            if which is None or typ != "A" or raw == "":
                continue
            if unit != "D":
                raise LogError(f"unit {unit[:5]!r} of an angle is not D (degrees)", field=name)
            v = self.ctx.optional(float_field, raw, name, lo=-90.0, hi=90.0)
            if which == "roll":
                roll = v
            else:
                pitch = v
        return self.attitude(self.clock.t, roll, pitch)

    def pashr(self, msg: pynmea2.NMEASentence) -> list[Record]:
        tod = parse_time_of_day(field_at(msg, 1))
        roll = num(msg, "roll", lo=-90.0, hi=90.0)
        pitch = num(msg, "pitch", lo=-90.0, hi=90.0)
        acc = [self.ctx.optional(num, msg, n, lo=0.0, hi=90.0) for n in ("roll_accuracy", "pitch_accuracy")]
        sigma = max((a for a in acc if a is not None and a > 0.0), default=math.nan)
        return self.attitude(self.clock.own_time(tod), roll, pitch, sigma)
