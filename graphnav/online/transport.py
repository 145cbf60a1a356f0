"""Live mode's transport: the NMEA 0183, NMEA 2000 gateway (UDP/TCP), Signal K (websocket) and scan
(UDP) sources behind one ``selectors`` poll.

``udp://HOST:PORT`` binds and receives datagrams (one or more lines each; a scan source: one JSON
scan record per datagram); ``tcp://HOST:PORT`` connects to a TCP server (a multiplexer such as kplex
or a chart plotter's server) and reconnects every second when the link drops; ``ws://HOST:PORT``
reads a Signal K server's delta stream (:class:`graphnav.online.marine_feed.WebSocketLines`).
"""

from __future__ import annotations

import errno
import logging
import os
import selectors
import socket
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

from ..errors import AddressError

log_ = logging.getLogger("graphnav.live")
MAX_LINE = 4096  # a TCP line longer than this without a newline is garbage
MAX_MESSAGE = 1 << 20  # a Signal K delta (one websocket message) longer than this is garbage


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


class Source:
    """One input: a bound UDP socket or a (re)connecting TCP client with a line buffer, or a
    websocket client (``ws://``: :class:`graphnav.online.marine_feed.WebSocketLines`, its messages as
    lines). ``kind`` is ``"nmea"`` (lines), ``"n2k"`` (NMEA 2000 gateway lines), ``"signalk"`` (delta
    JSON, one a line) or ``"scan"`` (UDP, one JSON scan record per datagram)."""

    def __init__(self, ep: Endpoint, kind: str = "nmea", url: str = "") -> None:
        self.ep = ep
        self.kind = kind
        self.url = url
        self.feed: Any = None  # the websocket client of a ws:// source
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


class Transport:
    """Every input socket behind one selector: ``poll(timeout)`` returns the lines (NMEA) and
    datagrams (scans) that arrived, each ``(kind, data, arrival)`` (``arrival``: ``time.perf_counter``
    when its socket was read), and reopens sources whose TCP link dropped."""

    def __init__(self, nmea: list[str], scans: list[str] | None = None, *, n2k: list[str] | None = None,
                 signalk: list[str] | None = None) -> None:
        self.sources = [Source(parse_endpoint(s)) for s in nmea]
        self.sources += [Source(parse_endpoint(s), "n2k") for s in n2k or []]
        if signalk:
            from .marine_feed import signalk_url

            self.sources += [Source(parse_endpoint(s, ("ws", "wss")), "signalk", signalk_url(s)) for s in signalk]
        if not self.sources:
            raise ValueError("at least one --nmea, --n2k or --signalk source is needed")
        self.sources += [Source(parse_endpoint(s, ("udp",)), "scan") for s in scans or []]
        self.sel: selectors.BaseSelector | None = None

    @property
    def has_scans(self) -> bool:
        return any(s.kind == "scan" for s in self.sources)

    def open(self) -> None:
        self.sel = selectors.DefaultSelector()
        for src in self.sources:
            src.open(self.sel)

    def poll(self, timeout: float = 0.05) -> list[tuple[str, bytes, float]]:
        assert self.sel is not None
        for src in self.sources:
            if src.sock is None:
                src.open(self.sel)
            else:
                src.connect_timed_out(self.sel)
        out: list[tuple[str, bytes, float]] = []
        for key, _ in self.sel.select(timeout=timeout):
            src = key.data
            arrival = time.perf_counter()
            out += [(src.kind, raw, arrival) for raw in src.read(self.sel)]
        return out

    def close(self) -> None:
        if self.sel is not None:
            for src in self.sources:
                src.close(self.sel)
            self.sel.close()
            self.sel = None

    def __str__(self) -> str:
        return ", ".join(str(s.ep) for s in self.sources)
