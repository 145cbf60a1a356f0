"""Live NMEA 2000 and Signal K input for the live loop (:mod:`graphnav.online.live_runner`).

* :class:`MarineInput` decodes lines of an NMEA 2000 gateway (any text format of
  :mod:`graphnav.io.n2k`: canboat, Yacht Devices RAW, Actisense N2K ASCII) and Signal K deltas
  (:mod:`graphnav.io.signalk`) into records on one local frame, counting what it read and rejected.
* :class:`WebSocketLines` is a Signal K server's websocket stream as lines on a local socket: a
  client (tornado, the ``[marine]`` extra) runs in a daemon thread, writes each text message as one
  line to a socket pair whose other end the single-threaded ``selectors`` loop reads like a TCP
  source; it reconnects every second when the server is down or the link drops. A full socket pair
  blocks the thread (back-pressure: memory stays bounded).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections import Counter
from typing import Any
from urllib.parse import urlsplit, urlunsplit

from ..errors import LogError, require
from ..geodesy import LocalFrame
from ..log import Record

log_ = logging.getLogger("graphnav.live")

#: The Signal K stream path used when a ``ws://HOST:PORT`` URL gives none (the own vessel's deltas).
SIGNALK_STREAM = "/signalk/v1/stream?subscribe=self"
#: Largest websocket message taken [bytes] (a server batches a few hundred values at most).
MAX_MESSAGE = 1 << 20


def signalk_url(url: str) -> str:
    """``ws://HOST:PORT`` -> ``ws://HOST:PORT/signalk/v1/stream?subscribe=self`` (a given path is kept)."""
    u = urlsplit(url)
    if u.path in ("", "/"):
        path, _, query = SIGNALK_STREAM.partition("?")
        return urlunsplit((u.scheme, u.netloc, path, u.query or query, ""))
    return url


class MarineInput:
    """Lines in, records out: ``feed(kind, line)`` with ``kind`` ``"n2k"`` or ``"signalk"``
    (a :class:`LogError` for a bad line). ``frame`` is shared with the NMEA 0183 decoder by the caller."""

    def __init__(self, frame: LocalFrame | None = None) -> None:
        self.frame = frame
        self._n2k = None
        self._sk = None
        self.counts: Counter = Counter()

    def feed(self, kind: str, raw: bytes) -> list[Record]:
        s = raw.strip()
        if not s:
            return []
        self.counts[f"{kind}_in"] += 1
        try:
            text = s.decode("utf-8")
        except UnicodeDecodeError:
            raise LogError("not UTF-8", field="line") from None
        if kind == "n2k":
            if self._n2k is None:
                from ..io.n2k import N2kDecoder

                self._n2k = N2kDecoder(self.frame)
            from ..io.n2k import parse_line

            dec = self._n2k
            dec.frame = dec.frame or self.frame
            fr = parse_line(text)
            recs = dec.feed(fr) if fr is not None else []
        else:
            import json

            if self._sk is None:
                from ..io.signalk import SignalKDecoder

                self._sk = SignalKDecoder(self.frame)
            dec = self._sk
            dec.frame = dec.frame or self.frame
            try:
                obj = json.loads(text)
            except (ValueError, RecursionError):
                raise LogError("not a JSON object", field="delta") from None
            recs = dec.feed(obj)
        if self.frame is None and dec.frame is not None:
            self.frame = dec.frame
        return recs

    def info(self) -> dict[str, Any]:
        out = dict(self.counts)
        if self._n2k is not None:
            out["n2k_pgns"] = {k[4:]: n for k, n in sorted(self._n2k.counts.items()) if k.startswith("pgn:")}
        return out


class WebSocketLines:
    """A websocket client in a daemon thread; its text messages as ``\\n``-terminated lines on
    :attr:`sock` (non-blocking, for a selector). :meth:`close` stops it."""

    def __init__(self, url: str, *, reconnect_s: float = 1.0, connect_timeout: float = 3.0) -> None:
        require("tornado", "a Signal K websocket source")
        self.url = url
        self.reconnect_s = reconnect_s
        self.connect_timeout = connect_timeout
        self.sock, self._w = socket.socketpair()
        self.sock.setblocking(False)
        self._stop = threading.Event()
        self.connected = threading.Event()
        self.messages = 0
        self.connects = 0
        self._thread = threading.Thread(target=self._run, name="signalk-ws", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except Exception as exc:  # noqa: BLE001 - the thread must end quietly; the loop sees EOF
            log_.debug("websocket %s: %s", self.url, exc)
        finally:
            try:
                self._w.close()
            except OSError:
                pass

    def _line(self, msg: str | bytes | None, closed: asyncio.Event) -> None:
        if msg is None:
            closed.set()
            return
        if isinstance(msg, bytes):
            msg = msg.decode("utf-8", "replace")
        self.messages += 1
        try:
            self._w.sendall(msg.replace("\r", " ").replace("\n", " ").encode("utf-8") + b"\n")
        except OSError:  # the loop closed its end
            self._stop.set()
            closed.set()

    async def _main(self) -> None:
        from tornado.websocket import websocket_connect

        while not self._stop.is_set():
            closed = asyncio.Event()
            try:
                conn = await asyncio.wait_for(
                    websocket_connect(self.url, on_message_callback=lambda m, c=closed: self._line(m, c),
                                      max_message_size=MAX_MESSAGE), self.connect_timeout)
            except Exception as exc:  # noqa: BLE001 - refused, unreachable, not a websocket: retry
                log_.debug("websocket %s: %s (retrying)", self.url, exc)
                await asyncio.sleep(self.reconnect_s)
                continue
            self.connects += 1
            self.connected.set()
            log_.info("connected to %s", self.url)
            while not self._stop.is_set() and not closed.is_set():
                await asyncio.sleep(0.05)
            conn.close()
            if not self._stop.is_set():
                log_.warning("%s closed; reconnecting", self.url)
                await asyncio.sleep(self.reconnect_s)

    def close(self) -> None:
        self._stop.set()
        try:
            self.sock.close()
        except OSError:
            pass
        self._thread.join(timeout=2.0)
