"""Live mode: NMEA 0183 in over UDP/TCP, an online estimator, the solution out as NMEA.

One single-threaded ``selectors`` loop (no locks, latency is measurable):

* **Sources** -- ``udp://HOST:PORT`` binds and receives datagrams (one or more sentences each);
  ``tcp://HOST:PORT`` connects to an NMEA TCP server (a multiplexer such as kplex or a
  chart plotter's server) and reconnects every second when the link drops. Every line is checked
  (checksum required) and decoded by :class:`graphnav.io.nmea.NmeaDecoder`; a bad sentence is
  counted (``bad_sentences``) and logged (the first 20, then every 1000th), never fatal.
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
* **Output** -- every estimate is appended to ``DIR/live.tum`` (+ ``live.cov``), flushed
  (:class:`graphnav.io.tum.TrajectoryWriter`), and published as GGA, HDT, VTG, ROT
  (valid checksums, one datagram per estimate) to ``publish`` (``udp://HOST:PORT``).
* **Stopping** -- SIGINT/SIGTERM (or :meth:`LiveRunner.stop`, ``duration``, ``idle_exit``, the
  end of the scan replay) ends the loop; files are flushed and closed and ``summary()`` returns
  ``sentences_in``, ``bad_sentences``, ``estimates``, ``published``, ``latency_ms_median``,
  ``latency_ms_p99`` (GNSS sentence arrival -> solution sent, over the last 100 000 fixes) and more.
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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from ..errors import LogError
from ..geodesy import LocalFrame
from ..io.jsonl import parse_record
from ..io.nmea import UERE_M, NmeaDecoder, parse_sentence
from ..io.nmea_out import solution_sentences
from ..io.tum import TrajectoryWriter
from ..log import Gnss, NavLog, Scan
from ..result import Estimate, OnlineEstimator

log_ = logging.getLogger("graphnav.live")
LATENCY_WINDOW = 100_000
MAX_LINE = 4096  # a TCP line longer than this without a newline is garbage


@dataclass(frozen=True)
class Endpoint:
    scheme: str
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.scheme}://{self.host}:{self.port}"


def parse_endpoint(url: str, schemes: tuple[str, ...] = ("udp", "tcp")) -> Endpoint:
    """``udp://HOST:PORT`` / ``tcp://HOST:PORT`` -> :class:`Endpoint` (ValueError otherwise)."""
    u = urlsplit(url)
    if u.scheme not in schemes or not u.hostname or u.port is None:
        raise ValueError(f"{url!r}: expected {' or '.join(s + '://HOST:PORT' for s in schemes)}")
    return Endpoint(u.scheme, u.hostname, u.port)


class _Source:
    """One input: a bound UDP socket or a (re)connecting TCP client with a line buffer.
    ``kind`` is ``"nmea"`` (lines) or ``"scan"`` (UDP, one JSON scan record per datagram)."""

    def __init__(self, ep: Endpoint, kind: str = "nmea") -> None:
        self.ep = ep
        self.kind = kind
        self.sock: socket.socket | None = None
        self.buf = b""
        self.next_try = 0.0
        self.connecting: float | None = None  # when a non-blocking TCP connect started

    def open(self, sel: selectors.BaseSelector) -> None:
        if self.ep.scheme == "udp":
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            s.bind((self.ep.host, self.ep.port))
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
        if len(self.buf) > MAX_LINE:
            lines.append(self.buf)
            self.buf = b""
        return lines


class LiveRunner:
    """The live loop (see the module docstring). ``run()`` blocks until stopped, then returns
    :meth:`summary`."""

    def __init__(self, sources: list[str], estimator: OnlineEstimator, *, publish: str | None = None,
                 out_dir: str | Path | None = None, scans_from: NavLog | None = None,
                 origin: tuple[float, float] | None = None, require_checksum: bool = True,
                 duration: float | None = None, idle_exit: float | None = None,
                 scan_sources: list[str] | None = None) -> None:
        self.sources = [_Source(parse_endpoint(s)) for s in sources]
        if not self.sources:
            raise ValueError("at least one --nmea source is needed")
        self.sources += [_Source(parse_endpoint(s, ("udp",)), "scan") for s in scan_sources or []]
        self.scans_in = 0
        self.scan_wait: list[Scan] = []  # network scans waiting for the NMEA clock
        self.bad_scans = 0
        self.estimator = estimator
        self.publish = parse_endpoint(publish, ("udp",)) if publish else None
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
        try:
            try:
                line = s.decode("ascii")
            except UnicodeDecodeError:
                raise LogError("non-ASCII bytes", field="sentence") from None
            recs = self.decoder.feed(parse_sentence(line, require_checksum=self.require_checksum))
        except LogError as err:
            if err.field == "sentence" and err.message.startswith("unknown sentence type"):
                self.ignored += 1  # well-formed but of a type pynmea2 does not know (e.g. proprietary)
                return
            self.bad += 1
            if self.bad <= 20 or self.bad % 1000 == 0:
                log_.warning("bad sentence #%d (%s): %r", self.bad, err, s[:80])
            return
        if self.scan_wait and self.decoder.t is not None:
            self._release_waiting(self.decoder.t)
        if self.scans is not None and self.decoder.t is not None:
            self._release_scans(self.decoder.t)
        for rec in recs:
            self._record(rec, arrival if isinstance(rec, Gnss) else None)

    def _scan_packet(self, data: bytes) -> None:
        """One UDP scan datagram: a JSON Lines ``scan`` record (docs/log-format.md), t on the NMEA clock."""
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
        # held until the NMEA stream's time reaches it, so a scan that overtakes the sentences of
        # earlier epochs (another socket) does not make them late
        if len(self.scan_wait) >= 100:
            self.scan_wait.pop(0)
            self.bad_scans += 1
        bisect.insort(self.scan_wait, rec, key=lambda r: r.t)
        if self.decoder.t is not None:
            self._release_waiting(self.decoder.t)

    def _release_waiting(self, t_stream: float) -> None:
        while self.scan_wait and self.scan_wait[0].t <= t_stream + 1e-6:
            self._record(self.scan_wait.pop(0), None)

    def _release_scans(self, t_stream: float) -> None:
        assert self.scans is not None
        if self.scan_shift is None and self.scans:
            d = t_stream - self.scans[0].t
            self.scan_shift = d if abs(d) > 60.0 else 0.0
        while self.scan_i < len(self.scans) and self.scans[self.scan_i].t + self.scan_shift <= t_stream:
            sc = self.scans[self.scan_i]
            self.scan_i += 1
            self._record(replace(sc, t=sc.t + self.scan_shift) if self.scan_shift else sc, None)
        if self.scan_i >= len(self.scans):
            self.stop_reason = "end of --scans-from replay"
            self._stop.set()

    def _record(self, rec, arrival: float | None) -> None:
        self.records += 1
        est = self.estimator.add(rec)
        if est is not None:
            self._emit(est, arrival)

    def _emit(self, est: Estimate, arrival: float | None) -> None:
        """Publish one estimate (NMEA), time its latency, append it to the output file."""
        self.estimates += 1
        self.last_estimate = est
        if self.pub_sock is not None and self.decoder.frame is not None:
            if est.cov is not None and np.all(np.isfinite(est.cov[:2, :2])):  # HDOP = sigma / UERE(GPS)
                self.hdop = max(0.01, math.sqrt(max(0.0, 0.5 * (est.cov[0, 0] + est.cov[1, 1]))) / UERE_M[1])
            lines = solution_sentences(est.t, est.vec, self.decoder.frame, sog=est.sog, cog_yaw=est.cog,
                                       w=est.w, hdop=self.hdop)
            try:
                self.pub_sock.sendto(("\r\n".join(lines) + "\r\n").encode("ascii"),
                                     (self.publish.host, self.publish.port))
                self.published += len(lines)
            except OSError as exc:
                log_.warning("publish to %s failed: %s", self.publish, exc)
        if arrival is not None:  # the published solution is the latency-critical path; the file comes next
            self.latency_ms[self.n_latency % LATENCY_WINDOW] = (time.perf_counter() - arrival) * 1e3
            self.n_latency += 1
        if self.writer is not None:
            self.writer.write(est.t, est.vec, est.cov)

    # -- the loop
    def run(self) -> dict[str, Any]:
        sel = selectors.DefaultSelector()
        self.writer = None
        self.pub_sock = None
        old = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, self.stop)
        try:
            if self.out_dir is not None:
                self.out_dir.mkdir(parents=True, exist_ok=True)
                self.writer = TrajectoryWriter(self.out_dir / "live.tum")
            if self.publish is not None:
                self.pub_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            for src in self.sources:
                src.open(sel)
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
                            self._scan_packet(raw)
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
            "ignored_sentences": self.ignored,
            "records": self.records,
            "wall_s": self.wall_s,
            "sentences_per_s": self.sentences_in / self.wall_s if self.wall_s > 0 else None,
            "stop_reason": self.stop_reason,
        }
        if self.scans is not None:
            out["scans_replayed"] = self.scan_i
        if any(s.kind == "scan" for s in self.sources):
            out["scans_in"], out["bad_scans"] = self.scans_in, self.bad_scans
        if self.decoder.frame is not None:
            f = self.decoder.frame
            out["origin"] = {"lat": f.lat0, "lon": f.lon0}
        if self.out_dir is not None:
            out["out"] = str(self.out_dir)
        info = getattr(self.estimator, "info", None)
        if callable(info):
            out["estimator"] = info()
        return out
