"""Live mode's clock and decoder: NMEA sentences in, records out, on a stream clock robust to time
outliers (docs/live.md, *Time sanity*).

:class:`StreamClock` judges each time stamp; :class:`NmeaInput` decodes each sentence
(:class:`graphnav.io.nmea.NmeaDecoder`), asks the clock about the time it carried, and undoes an
outlier in the decoder (:meth:`~graphnav.io.nmea.NmeaDecoder.snapshot` /
:meth:`~graphnav.io.nmea.NmeaDecoder.restore`). A sustained clock step is a re-sync: the sentences
of the outlier run are decoded again on the new clock (a step back starts a fresh decoder).
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable

from ..errors import LogError
from ..geodesy import LocalFrame
from ..io.nmea import NmeaDecoder, parse_sentence
from ..log import Record

log_ = logging.getLogger("graphnav.live")
TIME_TOLERANCE_S = 10.0
"""A time stamp may lie this far behind the stream clock, or this far ahead of it beyond the wall
time elapsed since the clock's last stamp arrived; farther is an outlier (:class:`StreamClock`)."""
RESYNC_STAMPS = 10
"""This many consecutive outliers with distinct, mutually consistent stamps are a clock step: accepted."""


class StreamClock:
    """The NMEA stream's clock, robust to time outliers (docs/live.md, *Time sanity*).

    The clock is the latest accepted time stamp ``t0`` and the wall time ``a0`` it arrived at
    (``time.perf_counter``). A stamp ``t`` arriving at ``a`` is consistent with it when
    ``t0 - tol <= t <= t0 + tol + max(0, a - a0)``: stream time neither goes back by more than
    ``tol`` nor runs ahead of the wall clock by more than ``tol`` (a stream replayed faster than
    real time advances by small steps, each well inside ``tol``; a link that was down for an hour
    comes back an hour later, which the wall-time term allows). A consistent stamp is accepted
    (the clock moves to it if it is later); any other is an outlier: counted, and it never moves
    the clock. ``resync`` consecutive outliers with distinct stamps, each consistent with the
    previous one by the same rule, are a genuine clock step (a receiver that found GPS time, a
    leap second, a replay restarted): the clock jumps to the last of them (``"resync"``).
    """

    def __init__(self, tol: float = TIME_TOLERANCE_S, resync: int = RESYNC_STAMPS) -> None:
        self.tol = tol
        self.resync = max(1, int(resync))
        self.t0: float | None = None
        self.a0 = 0.0
        self.run: list[tuple[float, float]] = []  # the current run of consistent outliers (distinct stamps)
        self.runs = 0  # how many runs have started (a caller's buffer of the current run restarts with it)
        self.resyncs = 0
        self.step = 0.0  # the clock's jump at the last re-sync [s]

    def _fits(self, t: float, a: float, t0: float, a0: float) -> bool:
        return t0 - self.tol <= t <= t0 + self.tol + max(0.0, a - a0)

    def fits(self, t: float, a: float) -> bool:
        """Whether ``t`` arriving at ``a`` is consistent with the clock (no clock yet: yes); no side effects."""
        return self.t0 is None or self._fits(t, a, self.t0, self.a0)

    def check(self, t: float, a: float) -> str:
        """``"ok"`` (accepted), ``"outlier"`` or ``"resync"`` (a sustained step: accepted, clock moved)."""
        if self.fits(t, a):
            if self.t0 is None or t >= self.t0:
                self.t0, self.a0 = t, a
            self.run.clear()
            return "ok"
        if self.run and self._fits(t, a, *self.run[-1]):
            if t != self.run[-1][0]:
                self.run.append((t, a))
        else:
            self.run = [(t, a)]
            self.runs += 1
        if len(self.run) < self.resync:
            return "outlier"
        assert self.t0 is not None
        self.step = t - self.t0
        self.t0, self.a0 = t, a
        self.run.clear()
        self.resyncs += 1
        return "resync"

    def shift(self, dt: float) -> None:
        """Move the clock's time base by ``dt`` (the decoder's first date: seconds of the day became POSIX)."""
        if self.t0 is not None:
            self.t0 += dt
        self.run = [(t + dt, a) for t, a in self.run]


OnRecords = Callable[[list[Record], float], None]


class NmeaInput:
    """Sentences -> records on the stream clock. ``feed(raw, arrival)`` decodes one sentence and,
    when it is accepted, calls ``on_records(records, arrival)`` (after the decoder's time moved:
    ``t`` is the stream time); ``on_step_back()`` is called when a re-sync moved the clock back
    (a fresh decoder was started: the caller starts a fresh estimator). Counts: ``sentences_in``,
    ``bad`` (undecodable), ``ignored`` (types pynmea2 does not know), ``time_outliers``."""

    def __init__(self, on_records: OnRecords, on_step_back: Callable[[], None], *,
                 origin: tuple[float, float] | None = None, require_checksum: bool = True,
                 time_tolerance: float = TIME_TOLERANCE_S, resync_stamps: int = RESYNC_STAMPS) -> None:
        frame = LocalFrame(float(origin[0]), float(origin[1])) if origin else None
        self.decoder = NmeaDecoder(frame, keep=False)
        self.clock = StreamClock(time_tolerance, resync_stamps)
        self.require_checksum = require_checksum
        self.on_records, self.on_step_back = on_records, on_step_back
        self.run_buf: deque[tuple[bytes, float, bool]] = deque(maxlen=64 * max(1, resync_stamps))
        self.sentences_in = self.bad = self.ignored = self.time_outliers = 0
        self.warned_outlier = False

    @property
    def t(self) -> float | None:
        """The stream time (the decoder's clock)."""
        return self.decoder.t

    def outlier(self, what: str, t: float, s: bytes = b"") -> None:
        """Count a time outlier (a sentence or a scan) and warn about the first."""
        self.time_outliers += 1
        if not self.warned_outlier:
            self.warned_outlier = True
            t0 = self.clock.t0 or 0.0
            log_.warning("time outlier: a %s stamped %.3f is %+.1f s from the stream clock (%.3f): dropped; "
                         "counted in time_outliers (warned once; %d consistent stamps in a row are accepted as "
                         "a clock step)%s", what, t, t - t0, t0, self.clock.resync, f": {s[:80]!r}" if s else "")

    def feed(self, raw: bytes, arrival: float) -> None:
        s = raw.strip()
        if s:
            self.sentences_in += 1
            self._process(s, arrival)

    def _process(self, s: bytes, arrival: float, refeed: bool = False) -> None:
        """Decode one sentence; its time stamp (if it moved the decoder's clock) must pass the
        stream clock: an outlier is undone in the decoder and dropped."""
        dec = self.decoder
        state = dec.snapshot()  # to undo an outlier's effect
        t_before, day0_before = dec.t, dec.day0
        try:
            try:
                line = s.decode("ascii")
            except UnicodeDecodeError:
                raise LogError("non-ASCII bytes", field="sentence") from None
            recs = dec.feed(parse_sentence(line, require_checksum=self.require_checksum))
        except LogError as err:
            if self._timed(t_before, day0_before, arrival, s, refeed) != "ok":
                dec.restore(state)  # a rejected sentence leaves no time behind either
            if err.field == "sentence" and err.message.startswith("unknown sentence type"):
                self.ignored += 1  # well-formed but of a type pynmea2 does not know (e.g. proprietary)
                return
            self.bad += 1
            if self.bad <= 20 or self.bad % 1000 == 0:
                log_.warning("bad sentence #%d (%s): %r", self.bad, err, s[:80])
            return
        verdict = self._timed(t_before, day0_before, arrival, s, refeed)
        if verdict != "ok":
            dec.restore(state)  # an outlier: as if it never came (the decoder's clock and last fix stay)
            if verdict == "resync":  # decoded again, in order, with the run before it
                self._resync()
            return
        if self.clock.run:  # an untimed sentence inside a run of outliers: replayed if the run re-syncs
            self.run_buf.append((s, arrival, False))
        self.on_records(recs, arrival)

    def _timed(self, t_before: float | None, day0_before: float | None, arrival: float, s: bytes,
               refeed: bool) -> str:
        """The stream clock's verdict on the time the decoder took from sentence ``s`` ("ok" when
        it carried none)."""
        dec = self.decoder
        t = dec.t
        if t is None or t == t_before:
            return "ok"
        if day0_before is None and dec.day0 is not None and t_before is not None:
            self.clock.shift(dec.day0)  # the first date: seconds of the day became POSIX time
        runs = self.clock.runs
        verdict = self.clock.check(t, arrival)
        if self.clock.runs != runs or verdict == "ok":  # a new run of outliers: the previous one's stay dropped
            self.run_buf.clear()
        if verdict == "outlier" and refeed:
            return verdict
        if verdict != "ok":
            self.run_buf.append((s, arrival, True))
        if verdict == "outlier":
            self.outlier("sentence", t, s)
        return verdict

    def _resync(self) -> None:
        """A clock step: the sentences of the outlier run are decoded again on the new clock. A step
        back also starts a fresh decoder (its last fix is in the future now) and tells the caller."""
        buf = list(self.run_buf)
        self.run_buf.clear()
        self.time_outliers -= sum(1 for _, _, timed in buf if timed) - 1  # those are re-fed, not dropped
        step = self.clock.step
        log_.warning("clock step: the stream's time moved by %+.1f s and stayed there for %d time stamps: "
                     "accepted (re-sync #%d)", step, self.clock.resync, self.clock.resyncs)
        if step < 0:
            old = self.decoder
            base = old.day0
            if base is not None:
                base += old.clock.days * 86400.0
            self.decoder = NmeaDecoder(old.frame, day0=base, keep=False)
            self.on_step_back()
        for raw, a, _ in buf:
            self._process(raw, a, refeed=True)
