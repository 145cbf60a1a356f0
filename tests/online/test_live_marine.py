"""Live NMEA 2000 and Signal K: a local websocket server replays the real aava-n2k log (a slice) as
Signal K deltas to ``graphnav live --signalk ws://...``; the solution published as Signal K deltas
is parsed back and compared with the log's own fixes. An NMEA 2000 gateway over UDP likewise."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from graphnav.errors import LogError
from graphnav.geodesy import LocalFrame
from graphnav.io.signalk import SignalKDecoder, record_delta
from graphnav.online.live_runner import LiveRunner
from graphnav.online.marine_feed import MarineInput, signalk_url
from graphnav.online.runner import make_online

tornado = pytest.importorskip("tornado", reason="the [marine] extra (tornado) is not installed")
pytest.importorskip("nmea2000", reason="the [marine] extra (nmea2000) is not installed")
REPO = Path(__file__).resolve().parents[2]
MARINE = next((p for p in (REPO.parent / "shared" / "data" / "marine",
                           REPO.parent.parent / "shared" / "data" / "marine") if p.is_dir()), None)


@pytest.fixture(scope="module")
def aava(tmp_path_factory):
    p = MARINE / "signalk" / "aava-n2k.data.gz" if MARINE else None
    if p is None or not p.is_file():
        pytest.skip("../shared/data/marine/signalk/aava-n2k.data.gz not found (real logs, not in the repository)")
    import gzip

    from graphnav.io.n2k import read_n2k

    with gzip.open(p, "rt") as fh:
        lines = [next(fh) for _ in range(1500)]  # the first ~40 s of the bus
    part = tmp_path_factory.mktemp("aava") / "head.data"
    part.write_text("".join(lines))
    return lines, read_n2k(part)


class _ReplayServer:
    """A websocket server on 127.0.0.1 (its own thread and event loop) that sends the hello and then
    every message to each client, and keeps the connection open."""

    def __init__(self, messages: list[str]) -> None:
        import tornado.httpserver
        import tornado.netutil
        import tornado.web
        import tornado.websocket

        msgs = messages

        class Replay(tornado.websocket.WebSocketHandler):
            async def open(self):
                self.write_message(json.dumps({"name": "test", "version": "2.0.0", "self": "vessels.self"}))
                for m in msgs:
                    await self.write_message(m)

        self.sockets = tornado.netutil.bind_sockets(0, "127.0.0.1")
        self.port = self.sockets[0].getsockname()[1]
        self.paths: list[str] = []
        self._app = tornado.web.Application([(r"/signalk/v1/stream", Replay)])
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self._ready.wait(5)

    def _run(self) -> None:
        import tornado.httpserver

        async def main():
            self._loop = asyncio.get_running_loop()
            self._done = asyncio.Event()
            server = tornado.httpserver.HTTPServer(self._app)
            server.add_sockets(self.sockets)
            self._ready.set()
            await self._done.wait()
            server.stop()

        asyncio.run(main())

    def close(self) -> None:
        self._loop.call_soon_threadsafe(self._done.set)
        self._thread.join(5)


def _udp_listener() -> tuple[socket.socket, int]:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    s.settimeout(0.2)
    return s, s.getsockname()[1]


def _drain(s: socket.socket, stop: threading.Event, out: list[bytes]) -> None:
    while not stop.is_set():
        try:
            out.append(s.recv(65536))
        except TimeoutError:
            continue
        except OSError:
            return


def _fix_distance(recs, log) -> float:
    g = log.of("gnss")
    t = np.array([r.t for r in g])
    est = np.array([[r.t, r.x, r.y] for r in recs if r.kind == "gnss"])
    ok = (est[:, 0] >= t[0]) & (est[:, 0] <= t[-1])
    fx = np.interp(est[ok, 0], t, [r.x for r in g])
    fy = np.interp(est[ok, 0], t, [r.y for r in g])
    return float(np.median(np.hypot(est[ok, 1] - fx, est[ok, 2] - fy)))


def test_signalk_websocket_in_signalk_deltas_out(aava):
    log = aava[1]
    o = log.meta["origin"]
    frame = LocalFrame(o["lat"], o["lon"])
    deltas = [json.dumps(d) for r in log.records if (d := record_delta(r, frame)) is not None]
    deltas.insert(5, "this is not JSON")  # a bad message is counted, never fatal
    server = _ReplayServer(deltas)
    udp, port = _udp_listener()
    got: list[bytes] = []
    stop = threading.Event()
    th = threading.Thread(target=_drain, args=(udp, stop, got), daemon=True)
    th.start()
    try:
        runner = LiveRunner([], make_online("fixed-lag"), signalk_sources=[f"ws://127.0.0.1:{server.port}"],
                            publish_signalk=f"udp://127.0.0.1:{port}", idle_exit=1.0, duration=60.0,
                            origin=(o["lat"], o["lon"]))
        summary = runner.run()
    finally:
        time.sleep(0.2)
        stop.set()
        th.join(2)
        udp.close()
        server.close()
    assert summary["signalk_in"] == len(deltas) + 1  # and the hello
    assert summary["bad_marine_lines"] == 1 and summary["stop_reason"] == "idle"
    assert summary["estimates"] > 30 and summary["published_signalk"] == summary["estimates"] == len(got)
    dec = SignalKDecoder(frame)
    back = [r for m in got for r in dec.feed(json.loads(m))]
    d = json.loads(got[-1])["updates"][0]
    paths = {v["path"] for v in d["values"]}
    assert {"navigation.position", "navigation.headingTrue", "navigation.speedOverGround",
            "navigation.courseOverGroundTrue"} <= paths
    assert {m["path"] for m in d["meta"]} == {"navigation.position", "navigation.headingTrue"}
    assert all(r.source == "graphnav" for r in back)
    assert _fix_distance(back, log) < 2.0  # the published track follows the replayed fixes


def test_n2k_gateway_over_udp(aava):
    lines, log = aava
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    runner = LiveRunner([], make_online("fixed-lag"), n2k_sources=[f"udp://127.0.0.1:{port}"], idle_exit=1.0,
                        duration=60.0, drop=["water_speed", "gnss@99"])

    def send():
        time.sleep(0.5)
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for i in range(0, len(lines), 20):
            s.sendto("".join(lines[i:i + 20]).encode(), ("127.0.0.1", port))
            time.sleep(0.002)
        s.sendto(b"garbage line\n", ("127.0.0.1", port))
        s.close()

    th = threading.Thread(target=send, daemon=True)
    th.start()
    summary = runner.run()
    th.join(2)
    assert summary["n2k_in"] == len(lines) + 1 and summary["bad_marine_lines"] == 1
    assert summary["n2k_pgns"]["129029"] > 30 and summary["estimates"] > 30
    assert summary["origin"]["lat"] == pytest.approx(59.725, abs=0.01)
    assert summary["dropped"] == ["water_speed", "gnss@99"]  # as run --drop: a kind, a kind of one source
    assert summary["dropped_records"] == log.counts()["water_speed"]


def test_marine_input_errors_and_url():
    m = MarineInput()
    with pytest.raises(LogError):
        m.feed("signalk", b"[1, 2")
    with pytest.raises(LogError):
        m.feed("n2k", b"2024-06-01T12:00:00Z,2,129025,7,255,8,zz")
    assert signalk_url("ws://h:3000") == "ws://h:3000/signalk/v1/stream?subscribe=self"
    assert signalk_url("ws://h:3000/custom?x=1") == "ws://h:3000/custom?x=1"
