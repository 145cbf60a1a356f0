"""Live mode: NMEA 0183 in over UDP/TCP, an online estimator, the solution out as NMEA.

One single-threaded ``selectors`` loop (no locks, latency is measurable):

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
  (``add(record) -> Estimate | None``), by name from :data:`graphnav.online.runner.ONLINE_ESTIMATORS`:
  :class:`graphnav.graph.navigator.Navigator` (the navigation graph of ``graphnav run``, with the
  fixed-lag smoother, the default, or iSAM2) or :class:`graphnav.online.ekf_online.EkfOnline` (the
  ``ekf`` estimator). When the loop stops, the estimator's ``flush()`` (if it has one) solves what
  was waiting for a later record and that estimate is published too.
* **Output** -- every estimate is appended to a new file per run, ``DIR/live-YYYYmmddTHHMMSSZ.tum``
  (UTC start time; + ``.cov``; an earlier run's file is never touched), flushed line by line
  (:class:`graphnav.io.tum.TrajectoryWriter`), and published as GGA, HDT, VTG, ROT
  (valid checksums, one datagram per estimate) to ``publish`` (``udp://HOST:PORT``), and as one
  Signal K delta per estimate (:func:`graphnav.io.signalk.solution_delta`) to ``publish_signalk``.
* **Stopping** -- SIGINT/SIGTERM (or :meth:`LiveRunner.stop`, ``duration``, ``idle_exit``, the
  end of the scan replay) ends the loop; files are flushed and closed and ``summary()`` returns
  ``sentences_in``, ``bad_sentences``, ``estimates``, ``published``, ``latency_ms_median``,
  ``latency_ms_p99``, ``latency_ms_max`` (arrival of the sentence or datagram whose record produced the
  estimate -> solution sent, every record kind, over the last 100 000 estimates; per kind in
  ``latency_ms_by_kind``) and more.
"""

from __future__ import annotations

import bisect
import errno
import json
import logging
import math
import os
import selectors
import signal
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from ..errors import AddressError, GraphnavError, LogError
from ..geodesy import LocalFrame
from ..io.jsonl import parse_record
from ..io.nmea import UERE_M, NmeaDecoder, parse_sentence
from ..io.nmea_out import solution_sentences
from ..io.outputs import ensure_dir
from ..io.tum import TrajectoryWriter
from ..log import RECORD_TYPES, NavLog, Scan
from ..result import Estimate, OnlineEstimator

log_ = logging.getLogger("graphnav.live")
LATENCY_WINDOW = 100_000
_KINDS = ("", *RECORD_TYPES)  # latency ring buffer: the record kind of each estimate ("": unknown)


def _by_kind(lat: np.ndarray, kinds: np.ndarray) -> dict[str, dict[str, float | int]]:
    """Latency median / p99 / max [ms] and count per record kind that produced estimates."""
    out: dict[str, dict[str, float | int]] = {}
    for code in np.unique(kinds):
        v = lat[kinds == code]
        out[_KINDS[int(code)] or "other"] = {"n": int(v.size), "median": float(np.median(v)),
                                               "p99": float(np.percentile(v, 99)), "max": float(v.max())}
    return out
MAX_LINE = 4096  # a TCP line longer than this without a newline is garbage
MAX_MESSAGE = 1 << 20  # a Signal K delta (one websocket message) longer than this is garbage
TIME_TOLERANCE_S = 10.0
"""A time stamp may lie this far behind the stream clock, or this far ahead of it beyond the wall
time elapsed since the clock's last stamp arrived; farther is an outlier (:class:`StreamClock`)."""
RESYNC_STAMPS = 10
"""This many consecutive outliers with distinct, mutually consistent stamps are a clock step: accepted."""


@dataclass(frozen=True)
class Endpoint:
    scheme: str
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.scheme}://{self.host}:{self.port}"


def parse_endpoint(url: str, schemes: tuple[str, ...] = ("udp", "tcp")) -> Endpoint:
    """``udp://HOST:PORT`` / ``tcp://HOST:PORT`` -> :class:`Endpoint` (:class:`AddressError`, a
    ValueError naming the address, otherwise)."""
    expected = f"expected {' or '.join(s + '://HOST:PORT' for s in schemes)}"
    u = urlsplit(url)
    try:
        port = u.port
    except ValueError:  # e.g. "Port out of range 0-65535"
        raise AddressError(url, f"port out of range 0-65535 ({expected})") from None
    if u.scheme not in schemes or not u.hostname or port is None:
        raise AddressError(url, expected)
    return Endpoint(u.scheme, u.hostname, port)


def resolve(ep: Endpoint) -> tuple[str, int]:
    """The IPv4 socket address of ``ep`` (:class:`AddressError` naming it if the host does not resolve)."""
    try:
        info = socket.getaddrinfo(ep.host, ep.port, socket.AF_INET,
                                  socket.SOCK_DGRAM if ep.scheme == "udp" else socket.SOCK_STREAM)
    except OSError as exc:  # socket.gaierror
        raise AddressError(str(ep), f"cannot resolve host {ep.host!r}: {exc.strerror or exc}") from None
    return info[0][4][:2]


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


class _Source:
    """One input: a bound UDP socket or a (re)connecting TCP client with a line buffer, or a
    websocket client (``ws://``: :class:`graphnav.online.marine_feed.WebSocketLines`, its messages as
    lines). ``kind`` is ``"nmea"`` (lines), ``"n2k"`` (NMEA 2000 gateway lines), ``"signalk"`` (delta
    JSON, one a line) or ``"scan"`` (UDP, one JSON scan record per datagram)."""

    def __init__(self, ep: Endpoint, kind: str = "nmea", url: str = "") -> None:
        self.ep = ep
        self.kind = kind
        self.url = url
        self.feed = None  # the websocket client of a ws:// source
        self.sock: socket.socket | None = None
        self.buf = b""
        self.next_try = 0.0
        self.connecting: float | None = None  # when a non-blocking TCP connect started

    def open(self, sel: selectors.BaseSelector) -> None:
        if self.ep.scheme in ("ws", "wss"):
            if time.monotonic() < self.next_try:
                return
            self.next_try = time.monotonic() + 1.0
            from .marine_feed import WebSocketLines

            self.feed = WebSocketLines(self.url)
            self.sock, self.buf = self.feed.sock, b""
            sel.register(self.sock, selectors.EVENT_READ, self)
            return
        if self.ep.scheme == "udp":
            addr = resolve(self.ep)
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            try:
                s.bind(addr)
            except OSError as exc:  # in use, not an address of this machine, privileged port...
                s.close()
                raise AddressError(str(self.ep), f"cannot listen: {exc.strerror or exc}") from None
        else:
            if time.monotonic() < self.next_try:
                return
            self.next_try = time.monotonic() + 1.0
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setblocking(False)  # a non-blocking connect: a dead server never stalls the loop
            try:
                err = s.connect_ex((self.ep.host, self.ep.port))
            except OSError as exc:  # e.g. the host name does not resolve
                err, msg = -1, str(exc)
            else:
                msg = os.strerror(err)
            if err not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
                s.close()
                log_.debug("tcp %s: %s (retrying)", self.ep, msg)
                return
            self.sock, self.buf = s, b""
            self.connecting = time.monotonic() if err else None
            sel.register(s, selectors.EVENT_WRITE if err else selectors.EVENT_READ, self)
            if not err:
                log_.info("connected to %s", self.ep)
            return
        s.setblocking(False)
        self.sock = s
        self.buf = b""
        sel.register(s, selectors.EVENT_READ, self)

    def connect_timed_out(self, sel: selectors.BaseSelector, limit: float = 3.0) -> None:
        if self.connecting is not None and time.monotonic() - self.connecting > limit:
            log_.debug("tcp %s: connect timed out (retrying)", self.ep)
            self.close(sel)

    def close(self, sel: selectors.BaseSelector) -> None:
        self.connecting = None
        if self.sock is not None:
            sel.unregister(self.sock)
            self.sock.close()
            self.sock = None
        if self.feed is not None:
            self.feed.close()
            self.feed = None

    def read(self, sel: selectors.BaseSelector) -> list[bytes]:
        assert self.sock is not None
        if self.connecting is not None:  # the non-blocking connect finished (or failed)
            err = self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err:
                log_.debug("tcp %s: %s (retrying)", self.ep, os.strerror(err))
                self.close(sel)
            else:
                self.connecting = None
                sel.modify(self.sock, selectors.EVENT_READ, self)
                log_.info("connected to %s", self.ep)
            return []
        if self.ep.scheme == "udp":  # drain what is queued (up to 256 datagrams), in arrival order
            out: list[bytes] = []
            for _ in range(256):
                try:
                    data, _ = self.sock.recvfrom(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError as exc:
                    log_.warning("%s: %s", self.ep, exc)
                    break
                out.extend([data] if self.kind == "scan" else data.splitlines())
            return out
        try:
            data = self.sock.recv(65536)
        except BlockingIOError:
            return []
        except OSError as exc:
            log_.warning("%s: %s", self.ep, exc)
            data = b""
        if not data:  # TCP peer closed: reconnect later
            log_.warning("%s closed; reconnecting", self.ep)
            self.close(sel)
            lines, self.buf = ([self.buf] if self.buf else []), b""
            return lines
        lines = (self.buf + data).split(b"\n")
        self.buf = lines.pop()
        if len(self.buf) > (MAX_LINE if self.kind == "nmea" else MAX_MESSAGE):  # a whole N2K ISO message: 5.4 kB
            lines.append(self.buf)
            self.buf = b""
        return lines


def new_live_file(out_dir: Path, now: float | None = None) -> TrajectoryWriter:
    """A writer on a new file ``out_dir/live-YYYYmmddTHHMMSSZ[-N].tum`` (UTC; ``-N`` when that second's
    name is taken): a live run appends to its own file and never replaces an earlier run's."""
    ensure_dir(out_dir)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(now))
    for n in range(1000):
        path = out_dir / f"live-{stamp}{f'-{n}' if n else ''}.tum"
        if path.with_suffix(".cov").exists():
            continue
        try:
            return TrajectoryWriter(path, exclusive=True)
        except FileExistsError:
            continue
    raise GraphnavError("no free live-*.tum file name for this second", where=str(out_dir))


class LiveRunner:
    """The live loop (see the module docstring). ``run()`` blocks until stopped, then returns
    :meth:`summary`."""

    writer: TrajectoryWriter | None = None
    sk_sock: socket.socket | None = None  # --publish-signalk's socket while running

    def __init__(self, sources: list[str], estimator: OnlineEstimator, *, publish: str | None = None,
                 out_dir: str | Path | None = None, scans_from: NavLog | None = None,
                 origin: tuple[float, float] | None = None, require_checksum: bool = True,
                 duration: float | None = None, idle_exit: float | None = None,
                 scan_sources: list[str] | None = None,
                 restart: Callable[[], OnlineEstimator] | None = None,
                 time_tolerance: float = TIME_TOLERANCE_S, resync_stamps: int = RESYNC_STAMPS,
                 n2k_sources: list[str] | None = None, signalk_sources: list[str] | None = None,
                 publish_signalk: str | None = None, drop: list[str] | None = None) -> None:
        self.sources = [_Source(parse_endpoint(s)) for s in sources]
        self.sources += [_Source(parse_endpoint(s), "n2k") for s in n2k_sources or []]
        if signalk_sources:
            from .marine_feed import signalk_url

            self.sources += [_Source(parse_endpoint(s, ("ws", "wss")), "signalk", signalk_url(s))
                             for s in signalk_sources]
        if not self.sources:
            raise ValueError("at least one --nmea, --n2k or --signalk source is needed")
        from ..io.drop import parse_kinds

        self.drop = parse_kinds(drop)  # record kinds (KIND or KIND@SOURCE) left out, as run --drop
        self._drop_kinds = {k for k in self.drop if "@" not in k}
        self._drop_pairs = {tuple(k.split("@", 1)) for k in self.drop if "@" in k}
        self.dropped = 0
        self.marine = None  # MarineInput, made when an n2k/signalk source is given
        self.bad_marine = 0
        self.sources += [_Source(parse_endpoint(s, ("udp",)), "scan") for s in scan_sources or []]
        self.scans_in = 0
        self.scan_wait: list[tuple[Scan, float]] = []  # network scans (and their arrival) waiting for the NMEA clock
        self.bad_scans = 0
        self.estimator = estimator
        self.restart = restart  # a fresh estimator, for a clock that steps back (a re-sync)
        self.clock = StreamClock(time_tolerance, resync_stamps)
        self.time_outliers = 0
        self.warned_outlier = False
        self.run_buf: deque[tuple[bytes, float, bool]] = deque(maxlen=64 * max(1, resync_stamps))
        self.publish = parse_endpoint(publish, ("udp",)) if publish else None
        self.publish_signalk = parse_endpoint(publish_signalk, ("udp",)) if publish_signalk else None
        self.published_signalk = 0
        self.out_dir = Path(out_dir) if out_dir else None
        self.scans = [r for r in scans_from.records if isinstance(r, Scan)] if scans_from else None
        self.scan_i = 0
        self.scan_shift: float | None = None
        frame = LocalFrame(float(origin[0]), float(origin[1])) if origin else None
        self.decoder = NmeaDecoder(frame, keep=False)
        self.require_checksum = require_checksum
        self.duration = duration
        self.idle_exit = idle_exit
        self._stop = threading.Event()
        self.sentences_in = 0
        self.bad = 0
        self.ignored = 0
        self.estimates = 0
        self.published = 0
        self.records = 0
        self.latency_ms = np.full(LATENCY_WINDOW, np.nan)  # ring buffer: constant memory
        self.latency_kind = np.zeros(LATENCY_WINDOW, dtype=np.int8)  # index into _KINDS of each
        self.n_latency = 0
        self.wall_s = 0.0
        self.stop_reason = ""
        self.last_estimate: Estimate | None = None
        self.hdop = 1.0  # published HDOP: from the last estimate that carried a covariance

    def stop(self, *_: Any) -> None:
        self._stop.set()

    # -- per sentence
    def _sentence(self, raw: bytes, arrival: float) -> None:
        s = raw.strip()
        if not s:
            return
        self.sentences_in += 1
        self._process(s, arrival)

    def _process(self, s: bytes, arrival: float, refeed: bool = False) -> None:
        """Decode one sentence; its time stamp (if it moved the decoder's clock) must pass the
        stream clock (:class:`StreamClock`): an outlier is undone in the decoder and dropped."""
        dec = self.decoder
        state = {k: v for k, v in vars(dec).items() if k != "out"}  # to undo an outlier's effect
        t_before, day0_before = dec.t, getattr(dec, "day0", None)
        try:
            try:
                line = s.decode("ascii")
            except UnicodeDecodeError:
                raise LogError("non-ASCII bytes", field="sentence") from None
            recs = dec.feed(parse_sentence(line, require_checksum=self.require_checksum))
        except LogError as err:
            if self._timed(t_before, day0_before, arrival, s, refeed) != "ok":
                vars(dec).update(state)  # a rejected sentence leaves no time behind either
            if err.field == "sentence" and err.message.startswith("unknown sentence type"):
                self.ignored += 1  # well-formed but of a type pynmea2 does not know (e.g. proprietary)
                return
            self.bad += 1
            if self.bad <= 20 or self.bad % 1000 == 0:
                log_.warning("bad sentence #%d (%s): %r", self.bad, err, s[:80])
            return
        verdict = self._timed(t_before, day0_before, arrival, s, refeed)
        if verdict == "outlier":
            vars(dec).update(state)  # as if it never came: the decoder's clock and last fix stay
            return
        if verdict == "resync":  # decoded again below, in order, with the run before it
            vars(dec).update(state)
            self._resync()
            return
        if self.clock.run:  # an untimed sentence inside a run of outliers: replayed if the run re-syncs
            self.run_buf.append((s, arrival, False))
        if self.scan_wait and self.decoder.t is not None:
            self._release_waiting(self.decoder.t, arrival)
        if self.scans is not None and self.decoder.t is not None:
            self._release_scans(self.decoder.t, arrival)
        for rec in recs:
            self._record(rec, arrival)

    def _timed(self, t_before: float | None, day0_before: float | None, arrival: float, s: bytes,
               refeed: bool) -> str:
        """The stream clock's verdict on the time the decoder took from sentence ``s`` ("ok" when
        it carried none)."""
        dec = self.decoder
        t = dec.t
        if t is None or t == t_before:
            return "ok"
        if day0_before is None and getattr(dec, "day0", None) is not None and t_before is not None:
            self.clock.shift(dec.day0)  # the first date: seconds of the day became POSIX time
        runs = self.clock.runs
        verdict = self.clock.check(t, arrival)
        if self.clock.runs != runs:  # a new run of outliers: the previous one's sentences stay dropped
            self.run_buf.clear()
        if verdict == "ok":
            self.run_buf.clear()
        elif verdict == "outlier":
            if refeed:
                return "outlier"
            self.time_outliers += 1
            self.run_buf.append((s, arrival, True))
            if not self.warned_outlier:
                self.warned_outlier = True
                assert self.clock.t0 is not None
                log_.warning("time outlier: a sentence stamped %.3f is %+.1f s from the stream clock (%.3f): "
                             "dropped; such sentences are counted in time_outliers (warned once; %d consistent "
                             "stamps in a row are accepted as a clock step): %r", t, t - self.clock.t0,
                             self.clock.t0, self.clock.resync, s[:80])
        else:
            self.run_buf.append((s, arrival, True))
        return verdict

    def _resync(self) -> None:
        """A clock step: the sentences of the outlier run are decoded again on the new clock. A step
        back also starts a fresh decoder (its last fix is in the future now) and, when ``restart``
        is given, a fresh estimator (which would drop every record as late otherwise)."""
        buf = list(self.run_buf)
        self.run_buf.clear()
        self.time_outliers -= sum(1 for _, _, timed in buf if timed) - 1  # those are re-fed, not dropped
        step = self.clock.step
        back = step < 0
        log_.warning("clock step: the stream's time moved by %+.1f s and stayed there for %d time stamps: "
                     "accepted (re-sync #%d)%s", step, self.clock.resync, self.clock.resyncs,
                     "; the estimator starts afresh" if back and self.restart is not None else "")
        if back:
            old = self.decoder
            base = getattr(old, "day0", None)
            if base is not None:
                base += getattr(old, "days", 0) * 86400.0
            self.decoder = NmeaDecoder(old.frame, day0=base, keep=False)
            self.scan_wait.clear()
            if self.restart is not None:
                self.estimator = self.restart()
        for raw, a, _ in buf:
            self._process(raw, a, refeed=True)

    def _scan_packet(self, data: bytes, arrival: float | None = None) -> None:
        """One UDP scan datagram: a JSON Lines ``scan`` record (docs/log-format.md), t on the NMEA
        clock; a time stamp far from the stream clock is a time outlier (counted, dropped)."""
        self.scans_in += 1
        try:
            try:
                obj = json.loads(data)
            except (ValueError, RecursionError):
                raise LogError("scan datagram is not JSON", field="scan") from None
            if not isinstance(obj, dict) or obj.get("type") != "scan":
                raise LogError("scan datagram must be a JSON object with type 'scan'", field="type")
            rec = parse_record(obj)
        except LogError as err:
            self.bad_scans += 1
            if self.bad_scans <= 20 or self.bad_scans % 1000 == 0:
                log_.warning("bad scan packet #%d (%s)", self.bad_scans, err)
            return
        if not self.clock.fits(rec.t, time.perf_counter() if arrival is None else arrival):
            self.time_outliers += 1
            if not self.warned_outlier:
                self.warned_outlier = True
                log_.warning("time outlier: a scan stamped %.3f is %+.1f s from the stream clock: dropped "
                             "(counted in time_outliers; warned once)", rec.t, rec.t - (self.clock.t0 or 0.0))
            return
        # held until the NMEA stream's time reaches it, so a scan that overtakes the sentences of
        # earlier epochs (another socket) does not make them late
        if len(self.scan_wait) >= 100:
            self.scan_wait.pop(0)
            self.bad_scans += 1
        bisect.insort(self.scan_wait, (rec, time.perf_counter() if arrival is None else arrival),
                      key=lambda ra: ra[0].t)
        if self.decoder.t is not None:
            self._release_waiting(self.decoder.t)

    def _release_waiting(self, t_stream: float, arrival: float | None = None) -> None:
        """Scans the stream's time has reached go to the estimator; the latency of what they produce
        counts from ``arrival`` (the sentence that released them) or else their own datagram's."""
        while self.scan_wait and self.scan_wait[0][0].t <= t_stream + 1e-6:
            rec, came = self.scan_wait.pop(0)
            self._record(rec, came if arrival is None else arrival)

    def _release_scans(self, t_stream: float, arrival: float | None = None) -> None:
        assert self.scans is not None
        if self.scan_shift is None and self.scans:
            d = t_stream - self.scans[0].t
            self.scan_shift = d if abs(d) > 60.0 else 0.0
        while self.scan_i < len(self.scans) and self.scans[self.scan_i].t + self.scan_shift <= t_stream:
            sc = self.scans[self.scan_i]
            self.scan_i += 1
            self._record(replace(sc, t=sc.t + self.scan_shift) if self.scan_shift else sc, arrival)
        if self.scan_i >= len(self.scans):
            self.stop_reason = "end of --scans-from replay"
            self._stop.set()

    def _marine_line(self, kind: str, raw: bytes, arrival: float) -> None:
        """One NMEA 2000 or Signal K line: its records, each stamped time checked by the stream
        clock (an outlier is counted and dropped); a bad line is counted (``bad_marine``), never fatal."""
        if self.marine is None:
            from .marine_feed import MarineInput

            self.marine = MarineInput(self.decoder.frame)
        self.marine.frame = self.marine.frame or self.decoder.frame
        try:
            recs = self.marine.feed(kind, raw)
        except LogError as err:
            self.bad_marine += 1
            if self.bad_marine <= 20 or self.bad_marine % 1000 == 0:
                log_.warning("bad %s line #%d (%s): %r", kind, self.bad_marine, err, raw[:80])
            return
        if self.decoder.frame is None and self.marine.frame is not None:
            self.decoder.frame = self.marine.frame  # the published solution's frame
        for rec in recs:
            if self.clock.check(rec.t, arrival) == "outlier":
                self.time_outliers += 1
                continue
            if self.scan_wait:
                self._release_waiting(rec.t, arrival)
            self._record(rec, arrival)

    def _record(self, rec, arrival: float | None) -> None:
        if self.drop and (rec.kind in self._drop_kinds or (rec.kind, getattr(rec, "source", "")) in self._drop_pairs):
            self.dropped += 1
            return
        self.records += 1
        est = self.estimator.add(rec)
        if est is not None:
            self._emit(est, arrival, getattr(rec, "kind", ""))

    def _emit(self, est: Estimate, arrival: float | None, kind: str = "") -> None:
        """Publish one estimate (NMEA), time its latency, append it to the output file."""
        self.estimates += 1
        self.last_estimate = est
        if self.pub_sock is not None and self.decoder.frame is not None:
            if est.cov is not None and np.all(np.isfinite(est.cov[:2, :2])):  # HDOP = sigma / UERE(GPS)
                self.hdop = max(0.01, math.sqrt(max(0.0, 0.5 * (est.cov[0, 0] + est.cov[1, 1]))) / UERE_M[1])
            lines = solution_sentences(est.t, est.vec, self.decoder.frame, sog=est.sog, cog_yaw=est.cog,
                                       w=est.w, hdop=self.hdop)
            try:
                self.pub_sock.sendto(("\r\n".join(lines) + "\r\n").encode("ascii"), self.pub_addr)
                self.published += len(lines)
            except OSError as exc:
                log_.warning("publish to %s failed: %s", self.publish, exc)
        if self.sk_sock is not None and self.decoder.frame is not None:
            from ..io.signalk import solution_delta

            delta = solution_delta(est.t, est.vec, self.decoder.frame, cov=est.cov, sog=est.sog, cog_yaw=est.cog,
                                   w=est.w)
            try:
                self.sk_sock.sendto(json.dumps(delta).encode("utf-8"), self.sk_addr)
                self.published_signalk += 1
            except OSError as exc:
                log_.warning("publish to %s failed: %s", self.publish_signalk, exc)
        if arrival is not None:  # the published solution is the latency-critical path; the file comes next
            i = self.n_latency % LATENCY_WINDOW
            self.latency_ms[i] = (time.perf_counter() - arrival) * 1e3
            self.latency_kind[i] = _KINDS.index(kind) if kind in _KINDS else 0
            self.n_latency += 1
        if self.writer is not None:
            self.writer.write(est.t, est.vec, est.cov)

    # -- the loop
    def run(self) -> dict[str, Any]:
        sel = selectors.DefaultSelector()
        self.writer = None
        self.pub_sock = None
        self.sk_sock = None
        old = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, self.stop)
        try:
            if self.out_dir is not None:
                self.writer = new_live_file(self.out_dir)
            if self.publish is not None:
                self.pub_addr = resolve(self.publish)
                self.pub_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if self.publish_signalk is not None:
                self.sk_addr = resolve(self.publish_signalk)
                self.sk_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            for src in self.sources:
                src.open(sel)
            log_.info("listening on %s; publishing to %s", ", ".join(str(s.ep) for s in self.sources),
                      self.publish or "-")
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
                for src in self.sources:
                    if src.sock is None:
                        src.open(sel)
                    else:
                        src.connect_timed_out(sel)
                for key, _ in sel.select(timeout=0.05):
                    src = key.data
                    arrival = time.perf_counter()
                    lines = src.read(sel)
                    if lines:
                        last_input = time.monotonic()
                    for raw in lines:
                        if src.kind == "scan":
                            self._scan_packet(raw, arrival)
                        elif src.kind != "nmea":
                            self._marine_line(src.kind, raw, arrival)
                        else:
                            self._sentence(raw, arrival)
                        if self._stop.is_set():
                            break
            if not self.stop_reason:
                self.stop_reason = "signal"
            flush = getattr(self.estimator, "flush", None)  # keyframes waiting for a later record
            if callable(flush):
                est = flush()
                if est is not None:
                    self._emit(est, None)
            self.wall_s = time.monotonic() - t_start
        finally:
            for src in self.sources:
                src.close(sel)
            sel.close()
            if self.writer is not None:
                self.writer.close()
            if self.pub_sock is not None:
                self.pub_sock.close()
            if self.sk_sock is not None:
                self.sk_sock.close()
            for sig, h in old.items():
                signal.signal(sig, h)
        return self.summary()

    def summary(self) -> dict[str, Any]:
        lat = self.latency_ms[: min(self.n_latency, LATENCY_WINDOW)]
        out: dict[str, Any] = {
            "sentences_in": self.sentences_in,
            "bad_sentences": self.bad,
            "estimates": self.estimates,
            "published": self.published,
            "latency_ms_median": float(np.median(lat)) if lat.size else None,
            "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else None,
            "latency_ms_max": float(lat.max()) if lat.size else None,
            "latency_ms_by_kind": _by_kind(lat, self.latency_kind[: lat.size]),
            "ignored_sentences": self.ignored,
            "time_outliers": self.time_outliers,
            "clock_resyncs": self.clock.resyncs,
            "records": self.records,
            "wall_s": self.wall_s,
            "sentences_per_s": self.sentences_in / self.wall_s if self.wall_s > 0 else None,
            "stop_reason": self.stop_reason,
        }
        if self.scans is not None:
            out["scans_replayed"] = self.scan_i
        if self.marine is not None:
            out.update(self.marine.info())
            out["bad_marine_lines"] = self.bad_marine
        if self.publish_signalk is not None:
            out["published_signalk"] = self.published_signalk
        if self.drop:
            out["dropped"], out["dropped_records"] = self.drop, self.dropped
        if any(s.kind == "scan" for s in self.sources):
            out["scans_in"], out["bad_scans"] = self.scans_in, self.bad_scans
        if self.decoder.frame is not None:
            f = self.decoder.frame
            out["origin"] = {"lat": f.lat0, "lon": f.lon0}
        if self.out_dir is not None:
            out["out"] = str(self.out_dir)
            if self.writer is not None:
                out["tum"] = str(self.writer.path)
        info = getattr(self.estimator, "info", None)
        if callable(info):
            out["estimator"] = info()
        return out
