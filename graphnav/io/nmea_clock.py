"""The clock of an NMEA 0183 stream: UTC time of day plus the date, by the time rule of docs/nmea.md.

A time of day that drops by more than 12 h is the next day; a fix time up to
:data:`~graphnav.io.nmea_fields.ZDA_MAX_LEAD_S` behind a clock that a ZDA set is the fix's own epoch
(receivers send the ZDA of the coming second before its GGA/RMC); a ZDA only moves the clock forward;
GST and PASHR carry their own time but do not move the clock."""

from __future__ import annotations

from datetime import date

from .nmea_fields import DAY, ZDA_MAX_LEAD_S, posix_midnight
from .nmea_state import DecodeContext, Stateful


class SentenceClock(Stateful):
    """``t`` (POSIX seconds once a date is known, else seconds since midnight of the first day),
    ``day0`` (POSIX midnight of day 0 or None), ``days`` since day 0, ``last_tod``, ``clock_src``
    (``"fix"`` or ``"zda"``: what set the clock last), ``back_ok`` (the last sentence moved the clock
    back by the ZDA rule), ``fix_clock`` (a GGA, GNS or RMC time has set the clock)."""

    STATE = ("clock_src", "back_ok", "day0", "days", "last_tod", "t", "fix_clock")

    def __init__(self, ctx: DecodeContext, day0: float | None) -> None:
        self.ctx = ctx
        self.clock_src = ""
        self.back_ok = False
        self.day0 = day0
        self.days = 0
        self.last_tod: float | None = None
        self.t: float | None = None
        self.fix_clock = False

    def stamp(self, tod: float | None, kind: str = "fix") -> float | None:
        """Move the clock to the time of day ``tod`` of a ``"fix"`` (GGA/RMC) or ``"zda"`` sentence;
        a fix behind a ZDA-set clock by at most ``ZDA_MAX_LEAD_S`` sets ``back_ok`` (counted in
        ``zda_ahead``), across midnight too."""
        self.back_ok = False
        if tod is None:
            return self.t
        days, t = self.absolute(tod)
        if self.t is not None and kind == "fix" and self.clock_src == "zda":
            if t - self.t > DAY / 2:  # the ZDA crossed midnight before this fix of the old day
                days -= 1
                t -= DAY
            if 0.0 < self.t - t <= ZDA_MAX_LEAD_S:
                self.back_ok = True
                self.ctx.counts["zda_ahead"] += 1
        self.days, self.last_tod, self.t, self.clock_src = days, tod, t, kind
        return self.t

    def absolute(self, tod: float) -> tuple[int, float]:
        """(day count, time) of a time of day: the next day when it drops by more than 12 h."""
        days = self.days
        if self.last_tod is not None and tod < self.last_tod - DAY / 2:
            days += 1
        return days, (self.day0 or 0.0) + days * DAY + tod

    def own_time(self, tod: float | None) -> float | None:
        """The time of a sentence that carries a time of day but does not move the clock (GST,
        PASHR): the nearest day to the clock's; the clock's time when it has none."""
        if tod is None:
            return self.t
        t = self.absolute(tod)[1]
        if self.t is not None and t - self.t > DAY / 2:
            t -= DAY
        return t

    def set_date(self, d: date | None) -> None:
        """The date of the current time of day (RMC, ZDA): ``t`` becomes POSIX time."""
        if d is not None:
            self.day0 = posix_midnight(d) - self.days * DAY
            if self.last_tod is not None:
                self.t = self.day0 + self.days * DAY + self.last_tod
