"""Live mode: NMEA 0183 in over UDP/TCP, an online estimator, the solution out as NMEA.

One single-threaded ``selectors`` loop (no locks, latency is measurable) over four parts: the
transport (:mod:`.transport`), the clock and decoder (:mod:`.stream_clock`), the scans
(:mod:`.scan_feed`) and the sink (:mod:`.sink`):

* **Sources** -- ``udp://HOST:PORT`` binds and receives datagrams (one or more sentences each);
  ``tcp://HOST:PORT`` connects to an NMEA TCP server (a multiplexer such as kplex or a
  chart plotter's server) and reconnects every second when the link drops. Every line is checked
  (checksum required) and decoded by :class:`graphnav.io.nmea.NmeaDecoder`; a bad sentence is
  counted (``bad_sentences``) and logged (the first 20, then every 1000th), never fatal.
* **NMEA 2000 and Signal K** -- ``n2k_sources`` (``udp://``/``tcp://``) carry an NMEA 2000 gateway's
  text lines (canboat, Yacht Devices RAW, Actisense N2K ASCII: :mod:`graphnav.io.n2k`);
  ``signalk_sources`` (``ws://HOST:PORT``, path default ``/signalk/v1/stream?subscribe=self``) a Signal
  K server's delta stream (:mod:`graphnav.online.marine_feed`, :mod:`graphnav.io.signalk`). Their
  records carry their own time stamps (checked by the stream clock); a bad line is counted
  (``bad_marine_lines``), never fatal.
* **Scans** -- ``scan_sources`` (``udp://HOST:PORT``) receive one scan per datagram: a JSON
  Lines ``scan`` record (docs/log-format.md: ``{"t", "type": "scan", "ranges", "angles"}`` or
  ``angle_min``/``angle_increment``; ``null``/0 = no return), ``t`` on the NMEA clock (POSIX s);
  bad packets are counted (``bad_scans``). Or ``scans_from`` (a :class:`NavLog`) replays that
  log's scans on the NMEA stream's clock: a scan is handed to the estimator when the stream's
  sentence time passes its time stamp (if the two time bases differ by more than 60 s, the log is
  shifted so that its first scan falls on the first timed sentence). The run ends when the last
  scan has been handed over.
* **Estimator** -- anything implementing :class:`graphnav.result.OnlineEstimator`
  (``add(record) -> Estimate | None``), by name from :func:`graphnav.estimators.make_online`:
  :class:`graphnav.graph.navigator.Navigator` (the navigation graph of ``graphnav run``, with the
  fixed-lag smoother, the default, or iSAM2) or :class:`graphnav.estimators.ekf_online.EkfOnline` (the
  ``ekf`` estimator). When the loop stops, the estimator's ``flush()`` (if it has one) solves what
  was waiting for a later record and that estimate is published too.
* **Output** -- every estimate is appended to a new file per run, ``DIR/live-YYYYmmddTHHMMSSZ.tum``
  (UTC start time; + ``.cov``; an earlier run's file is never touched), flushed line by line
  (:class:`graphnav.io.tum.TrajectoryWriter`), and published as GGA, HDT, VTG, ROT
  (valid checksums, one datagram per estimate) to ``publish`` (``udp://HOST:PORT``), and as one
  Signal K delta per estimate (:func:`graphnav.io.signalk.solution_delta`) to ``publish_signalk``.
  While the stream is silent (two output or record periods without a record), the estimator's
  predictions on its output grid are published too (``coast``, :meth:`LiveRunner.tick`: the
  navigator's or the EKF's motion model, covariance grown; GGA fix quality 6, *estimated*, Signal K
  ``navigation.gnss.methodQuality`` "Estimated (DR) mode"; counted in ``coasted_estimates``, their times
  in ``coasted_spans``), instead of a hole in the output.
* **Stopping** -- SIGINT/SIGTERM (or :meth:`LiveRunner.stop`, ``duration``, ``idle_exit``, the
  end of the scan replay) ends the loop; files are flushed and closed and ``summary()`` returns
  ``sentences_in``, ``bad_sentences``, ``estimates``, ``published``, ``latency_ms_median``,
  ``latency_ms_p99``, ``latency_ms_max`` (arrival of the sentence or datagram whose record produced the
  estimate -> solution sent, every record kind, over the last 100 000 estimates; per kind in
  ``latency_ms_by_kind``) and more.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import LogError
from ..log import NavLog, Record
from ..result import Estimate, OnlineEstimator
from .scan_feed import ScanFeed
from .sink import LATENCY_WINDOW, Sink, new_live_file
from .stream_clock import RESYNC_STAMPS, TIME_TOLERANCE_S, NmeaInput, StreamClock
from .transport import Endpoint, Transport, parse_endpoint, resolve

__all__ = ["LATENCY_WINDOW", "RESYNC_STAMPS", "TIME_TOLERANCE_S", "Endpoint", "LiveRunner", "StreamClock",
           "new_live_file", "parse_endpoint", "resolve"]

log_ = logging.getLogger("graphnav.live")


class Drop:
    """Record kinds left out (``KIND`` or ``KIND@SOURCE``, as ``run --drop``); ``drops(rec)`` counts them."""

    def __init__(self, kinds: list[str] | None) -> None:
        from ..io.drop import parse_kinds

        self.kinds = parse_kinds(kinds)
        self.plain = {k for k in self.kinds if "@" not in k}
        self.pairs = {tuple(k.split("@", 1)) for k in self.kinds if "@" in k}
        self.dropped = 0

    def drops(self, rec: Record) -> bool:
        if self.kinds and (rec.kind in self.plain or (rec.kind, getattr(rec, "source", "")) in self.pairs):
            self.dropped += 1
            return True
        return False


class LiveRunner:
    """The live loop (see the module docstring): ``transport`` -> ``nmea`` (clock + decoder) and
    ``scans`` -> ``estimator`` -> ``sink``. ``run()`` blocks until stopped, then returns :meth:`summary`;
    ``feed_sentence`` / ``feed_scan`` put one input through the same path without sockets."""

    def __init__(self, sources: list[str], estimator: OnlineEstimator, *, publish: str | None = None,
                 out_dir: str | Path | None = None, scans_from: NavLog | None = None,
                 origin: tuple[float, float] | None = None, require_checksum: bool = True,
                 duration: float | None = None, idle_exit: float | None = None,
                 scan_sources: list[str] | None = None,
                 restart: Callable[[], OnlineEstimator] | None = None,
                 time_tolerance: float = TIME_TOLERANCE_S, resync_stamps: int = RESYNC_STAMPS,
                 n2k_sources: list[str] | None = None, signalk_sources: list[str] | None = None,
                 publish_signalk: str | None = None, drop: list[str] | None = None) -> None:
        self.transport = Transport(sources, scan_sources, n2k=n2k_sources, signalk=signalk_sources)
        self.nmea = NmeaInput(self._records, self._step_back, origin=origin, require_checksum=require_checksum,
                              time_tolerance=time_tolerance, resync_stamps=resync_stamps)
        self.scans = ScanFeed(scans_from)
        self.sink = Sink(publish, out_dir, publish_signalk)
        self.drop = Drop(drop)
        self.marine: Any = None  # MarineInput, made at the first NMEA 2000 / Signal K line
        self.bad_marine = 0
        self.estimator = estimator
        self.restart = restart  # a fresh estimator, for a clock that steps back (a re-sync)
        self.duration, self.idle_exit = duration, idle_exit
        self._stop = threading.Event()
        self.records = 0
        self.wall_s = 0.0
        self.stop_reason = ""

    @property
    def last_estimate(self) -> Estimate | None:
        return self.sink.last

    def stop(self, *_: Any) -> None:
        self._stop.set()

    # -- one input
    def feed_sentence(self, raw: bytes, arrival: float) -> None:
        """One NMEA line that arrived at ``arrival`` (``time.perf_counter``)."""
        self.nmea.feed(raw, arrival)

    def feed_scan(self, data: bytes, arrival: float | None = None) -> None:
        """One scan datagram; a time stamp far from the stream clock is a time outlier (counted, dropped)."""
        scan = self.scans.packet(data)
        if scan is None:
            return
        if not self.nmea.clock.fits(scan.t, time.perf_counter() if arrival is None else arrival):
            self.nmea.outlier("scan", scan.t)
            return
        self.scans.hold(scan, time.perf_counter() if arrival is None else arrival)
        if self.nmea.t is not None:
            self._hand_over(self.nmea.t)

    def feed_marine(self, kind: str, raw: bytes, arrival: float) -> None:
        """One NMEA 2000 or Signal K line: its records, each stamped time checked by the stream clock
        (an outlier is counted and dropped); a bad line is counted (``bad_marine``), never fatal."""
        if self.marine is None:
            from .marine_feed import MarineInput

            self.marine = MarineInput(self.nmea.decoder.frame)
        self.marine.frame = self.marine.frame or self.nmea.decoder.frame
        try:
            recs = self.marine.feed(kind, raw)
        except LogError as err:
            self.bad_marine += 1
            if self.bad_marine <= 20 or self.bad_marine % 1000 == 0:
                log_.warning("bad %s line #%d (%s): %r", kind, self.bad_marine, err, raw[:80])
            return
        if self.nmea.decoder.frame is None and self.marine.frame is not None:
            self.nmea.decoder.frame = self.marine.frame  # the published solution's frame
        for rec in recs:
            if self.nmea.clock.check(rec.t, arrival) == "outlier":
                self.nmea.time_outliers += 1
                continue
            for scan, _ in self.scans.due_waiting(rec.t):
                self._record(scan, arrival)
            self._record(rec, arrival)

    def _records(self, recs: list[Record], arrival: float) -> None:
        """A sentence's records, after the scans the stream time reached; what they produce is timed
        from the sentence's ``arrival``."""
        if self.nmea.t is not None:
            self._hand_over(self.nmea.t, arrival)
        for rec in recs:
            self._record(rec, arrival)

    def _hand_over(self, t_stream: float, arrival: float | None = None) -> None:
        """Scans the stream's time has reached go to the estimator; the latency of what they produce
        counts from ``arrival`` (the sentence that released them) or else their own datagram's."""
        for scan, came in self.scans.due(t_stream):
            self._record(scan, came if arrival is None else arrival)
        if self.scans.done:
            self.stop_reason = "end of --scans-from replay"
            self._stop.set()

    def _step_back(self) -> None:
        """The clock stepped back: waiting scans are dropped, the sink's times start again (its estimates
        are not late, :meth:`Sink.resync`), and a fresh estimator (when ``restart`` is given) takes over,
        which would drop every record as late otherwise."""
        self.scans.waiting.clear()
        self.sink.resync()
        if self.restart is not None:
            log_.warning("clock step back: the estimator starts afresh")
            self.estimator = self.restart()

    def _record(self, rec: Record, arrival: float | None) -> None:
        if self.drop.drops(rec):
            return
        self.records += 1
        est = self.estimator.add(rec)
        for c in getattr(self.estimator, "coasted_out", ()):  # predictions through the gap before it
            self.sink.emit(c, None, self.nmea.decoder.frame)
        if est is not None:
            self.sink.emit(est, arrival, self.nmea.decoder.frame, rec.kind)

    def tick(self, now: float | None = None) -> None:
        """The output clock: while the stream is silent, the estimator's predictions due by now
        (``coast(t)``, when it has it; the stream's time extrapolated at the wall clock's rate
        since its last stamp arrived, ``now`` a ``time.perf_counter``) are published, flagged; past
        ``coast_max_s`` the output says it has no solution (``no_fix(t)``, :meth:`Sink.no_fix`)."""
        coast = getattr(self.estimator, "coast", None)
        clock = self.nmea.clock
        if not callable(coast) or clock.t0 is None:
            return
        t = clock.t0 + max(0.0, (time.perf_counter() if now is None else now) - clock.a0)
        for c in coast(t):
            self.sink.emit(c, None, self.nmea.decoder.frame)
        no_fix = getattr(self.estimator, "no_fix", None)  # past coast_max_s: said, not silent
        for tau in no_fix(t) if callable(no_fix) else ():
            self.sink.no_fix(tau)

    # -- the loop
    def run(self) -> dict[str, Any]:
        old = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, self.stop)
        try:
            self.transport.open()  # listening before the output file exists (what a caller waits for)
            self.sink.open()
            log_.info("listening on %s; publishing to %s", self.transport, self.sink.publish or "-")
            self._loop()
            flush = getattr(self.estimator, "flush", None)  # keyframes waiting for a later record
            if callable(flush):
                est = flush()
                for e in getattr(self.estimator, "replayed_out", ()):  # a warm-up ended by the end of input
                    self.sink.emit(e, None, self.nmea.decoder.frame)
                if est is not None:
                    self.sink.emit(est, None, self.nmea.decoder.frame)
        finally:
            self.transport.close()
            self.sink.close()
            for sig, h in old.items():
                signal.signal(sig, h)
        return self.summary()

    def _loop(self) -> None:
        t_start = time.monotonic()
        last_input = None
        while not self._stop.is_set():
            now = time.monotonic()
            if self.duration is not None and now - t_start >= self.duration:
                self.stop_reason = "duration"
                break
            idle = now - last_input if last_input is not None else 0.0
            if self.idle_exit is not None and idle >= self.idle_exit:
                self.stop_reason = "idle"
                break
            items = self.transport.poll(0.05)
            if items:
                last_input = time.monotonic()
            for kind, raw, arrival in items:
                if kind == "scan":
                    self.feed_scan(raw, arrival)
                elif kind == "nmea":
                    self.feed_sentence(raw, arrival)
                else:
                    self.feed_marine(kind, raw, arrival)
                if self._stop.is_set():
                    break
            self.tick()
        self.stop_reason = self.stop_reason or "signal"
        self.wall_s = time.monotonic() - t_start

    def summary(self) -> dict[str, Any]:
        nm, sink = self.nmea, self.sink.summary()
        out: dict[str, Any] = {
            "sentences_in": nm.sentences_in, "bad_sentences": nm.bad,
            "estimates": sink.pop("estimates"), "published": sink.pop("published"),
            **{k: sink.pop(k) for k in ("latency_ms_median", "latency_ms_p99", "latency_ms_max", "latency_ms_by_kind")},
            "ignored_sentences": nm.ignored, "time_outliers": nm.time_outliers, "clock_resyncs": nm.clock.resyncs,
            "records": self.records, "wall_s": self.wall_s,
            "sentences_per_s": nm.sentences_in / self.wall_s if self.wall_s > 0 else None,
            "stop_reason": self.stop_reason}
        if self.scans.replay is not None:
            out["scans_replayed"] = self.scans.replayed
        if self.marine is not None:
            out.update(self.marine.info())
            out["bad_marine_lines"] = self.bad_marine
        if self.drop.kinds:
            out["dropped"], out["dropped_records"] = self.drop.kinds, self.drop.dropped
        if self.transport.has_scans:
            out["scans_in"], out["bad_scans"] = self.scans.scans_in, self.scans.bad_scans
        if nm.decoder.frame is not None:
            out["origin"] = {"lat": nm.decoder.frame.lat0, "lon": nm.decoder.frame.lon0}
        out.update(sink)  # out, tum
        from .warmup import motion_of

        out.update(motion_of(self.estimator))  # the motion model and why (graphnav.online.warmup)
        info = getattr(self.estimator, "info", None)
        if callable(info):
            out["estimator"] = info()
        return out
