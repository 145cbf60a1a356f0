"""Live mode on loopback: a real sender (replay) and receiver (graphnav live) over UDP/TCP.

Every network test binds 127.0.0.1 only and is bounded in time (duration / idle-exit limits)."""

from __future__ import annotations

import json
import signal
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pynmea2
import pytest
from _harbour import harbour_trial
from _live import start_live

from graphnav.geodesy import LocalFrame
from graphnav.geometry import heading_deg_to_yaw, wrap_angle
from graphnav.io.nmea import read_nmea
from graphnav.io.nmea_out import sentence
from graphnav.online.live_runner import LiveRunner, parse_endpoint
from graphnav.online.nmea_replay import corrupt_sentence, log_sentences, replay
from graphnav.online.runner import make_online, run_online

REPO = Path(__file__).resolve().parents[2]


def _offline_estimates(log) -> int:
    """How many estimates the default live estimator makes from the log's NMEA sentences offline."""
    from graphnav.io.nmea import NmeaDecoder, parse_sentence

    est, n = make_online("fixed-lag"), 0
    dec = NmeaDecoder(LocalFrame(log.meta["origin"]["lat"], log.meta["origin"]["lon"]), keep=False)
    for _, s in log_sentences(log):
        for rec in dec.feed(parse_sentence(s)):
            n += est.add(rec) is not None
    return n + (est.flush() is not None)


def free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Collector:
    """UDP receiver of the published solution."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.data: list[bytes] = []
        self.done = threading.Event()
        self.th = threading.Thread(target=self._run, daemon=True)
        self.th.start()

    def _run(self) -> None:
        while not self.done.is_set():
            try:
                self.data.append(self.sock.recv(65536))
            except TimeoutError:
                pass

    def close(self) -> list[str]:
        time.sleep(0.3)
        self.done.set()
        self.th.join(2)
        self.sock.close()
        return [ln for d in self.data for ln in d.decode("ascii").split("\r\n") if ln]


def start_runner(runner: LiveRunner) -> tuple[threading.Thread, dict]:
    out: dict = {}
    th = threading.Thread(target=lambda: out.update(runner.run()), daemon=True)
    th.start()
    for _ in range(100):
        if all(s.sock is not None for s in runner.transport.sources):
            break
        time.sleep(0.02)
    return th, out


def truth_at(log, t):
    tr = log.truth()
    i = np.clip(np.searchsorted(tr.t, np.asarray(t) - 1e-3), 0, len(tr.t) - 1)
    assert np.all(np.abs(tr.t[i] - t) < 1e-3)
    return tr.poses[i]


def test_parse_endpoint():
    assert str(parse_endpoint("udp://127.0.0.1:10110")) == "udp://127.0.0.1:10110"
    assert parse_endpoint("tcp://localhost:2000").scheme == "tcp"
    for bad in ("udp://127.0.0.1", "serial:///dev/ttyUSB0", "127.0.0.1:5"):
        with pytest.raises(ValueError):
            parse_endpoint(bad)
    with pytest.raises(ValueError):
        parse_endpoint("tcp://127.0.0.1:5", ("udp",))


def test_corrupted_sentences_are_invalid():
    rng = np.random.default_rng(0)
    log = harbour_trial(duration=1.0)
    for _, s in list(log_sentences(log))[:40]:
        bad = corrupt_sentence(s, rng)
        assert bad != s
        with pytest.raises(pynmea2.ParseError):  # ChecksumError is a ParseError
            pynmea2.parse(bad, check=True)


def test_udp_loopback_tracks_truth(tmp_path):
    """Replay at 10x with 3 % damaged sentences -> live estimates; published NMEA parses and is as
    accurate as the same online estimator run offline on the same sentences."""
    log = harbour_trial(duration=20.0, rate=10.0, seed=5)
    port = free_port()
    col = Collector()
    runner = LiveRunner([f"udp://127.0.0.1:{port}"], make_online("fixed-lag"),
                        publish=f"udp://127.0.0.1:{col.port}",
                        out_dir=tmp_path / "out", idle_exit=1.0, duration=40.0)
    th, summary = start_runner(runner)
    sent = replay(log, f"udp://127.0.0.1:{port}", speed=10.0, corrupt=0.03, seed=2)
    th.join(45)
    assert not th.is_alive()
    lines = col.close()
    assert summary["stop_reason"] == "idle"
    assert 0.95 * sent["sentences_sent"] <= summary["sentences_in"] <= sent["sentences_sent"]
    assert 0 < summary["bad_sentences"] <= sent["corrupted"]
    assert summary["estimates"] >= 38 and summary["latency_ms_median"] is not None  # a 0.5 s keyframe grid
    # every estimate but the end-of-input flush is timed from the arrival of the record that produced it
    by_kind = summary["latency_ms_by_kind"]
    assert sum(v["n"] for v in by_kind.values()) >= summary["estimates"] - 1 and "other" not in by_kind
    assert 0 < summary["latency_ms_median"] <= summary["latency_ms_p99"] <= summary["latency_ms_max"]
    # every published sentence carries a valid checksum and parses
    msgs = [pynmea2.parse(s, check=True) for s in lines]
    kinds = {m.sentence_type for m in msgs}
    assert kinds == {"GGA", "HDT", "VTG", "ROT"}
    assert summary["published"] == len(lines)
    # the published GGA/HDT track the truth
    frame = LocalFrame(log.meta["origin"]["lat"], log.meta["origin"]["lon"])  # the truth's frame
    gga = [m for m in msgs if m.sentence_type == "GGA"]
    hdt = [m for m in msgs if m.sentence_type == "HDT"]
    # after the stream ends the runner coasts (GGA quality 6, estimated: past the truth's end here)
    coasted = [int(m.gps_qual) == 6 for m in gga]
    assert sum(coasted) == summary["coasted_estimates"] and not any(coasted[:-5])
    gga = [m for m, c in zip(gga, coasted, strict=True) if not c]
    hdt = [m for m, c in zip(hdt, coasted, strict=True) if not c]
    tod = np.array([m.timestamp.hour * 3600 + m.timestamp.minute * 60 + m.timestamp.second
                    + m.timestamp.microsecond * 1e-6 for m in gga])
    t = 1.7e9 - (1.7e9 % 86400) + tod
    x, y = frame.to_local(np.array([m.latitude for m in gga]), np.array([m.longitude for m in gga]))
    ref = truth_at(log, t)
    live_err = np.hypot(x - ref[:, 0], y - ref[:, 1])
    yaw_err = wrap_angle(heading_deg_to_yaw(np.array([float(m.heading) for m in hdt])) - ref[:, 2])
    # offline: the same estimator over the same (undamaged) sentences
    f = tmp_path / "all.nmea"
    f.write_text("\n".join(s for _, s in log_sentences(log)) + "\n")
    off = run_online(read_nmea(f, origin=(frame.lat0, frame.lon0)), make_online("fixed-lag"))
    off_err = np.hypot(*(off.poses[:, :2] - truth_at(log, off.t)[:, :2]).T)
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    assert rms(live_err) <= 1.5 * rms(off_err) + 0.1, (rms(live_err), rms(off_err))
    assert rms(live_err) < 0.5 * 1.5  # well inside the GNSS noise (sigma 1.5 m)
    assert np.degrees(rms(yaw_err[5:])) < 2.0
    # every estimate is on disk
    tum = Path(summary["tum"]).read_text().splitlines()
    assert Path(summary["tum"]).parent == tmp_path / "out" and Path(summary["tum"]).name.startswith("live-")
    assert len(tum) - 1 == summary["estimates"]


def test_malformed_and_truncated_stream_does_not_stop_the_estimator():
    log = harbour_trial(duration=4.0, rate=10.0)
    sentences = [s for _, s in log_sentences(log)]
    port = free_port()
    runner = LiveRunner([f"udp://127.0.0.1:{port}"], make_online("fixed-lag"), idle_exit=0.7, duration=20.0)
    th, summary = start_runner(runner)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    junk = [b"\xff\xfe\x00garbage", b"$GPGGA,1", b"$" + b"A" * 10000, b"", b"\r\n\r\n", b"$GNGGA,,,,,,,,,*00",
            b"$HEHDT,1,T*FF", b"!AIVDM,1,1,,A,13aG?P0P00PD;88MD5MTDww@2<0L,0*30",
            (sentence("GPXYZ,1,2") + "\r\n").encode()]  # valid but unknown: ignored, not bad
    half = len(sentences) // 2
    for s in sentences[:half]:
        tx.sendto(s.encode() + b"\r\n", ("127.0.0.1", port))
    for j in junk:
        tx.sendto(j, ("127.0.0.1", port))
    for s in sentences[half:]:
        tx.sendto((s[: len(s) // 2] + "\r\n").encode(), ("127.0.0.1", port))  # truncated copy
        tx.sendto(s.encode() + b"\r\n", ("127.0.0.1", port))
    tx.close()
    th.join(25)
    assert not th.is_alive()
    assert summary["bad_sentences"] >= len(sentences) - half + 5
    # one per keyframe, before and after the junk: as many as offline on the clean sentences
    assert summary["estimates"] == _offline_estimates(log)
    assert summary["ignored_sentences"] == 1
    assert runner.last_estimate is not None and runner.last_estimate.t == pytest.approx(log.t1, abs=0.5)


def test_tcp_source_reassembles_lines_and_reconnects():
    log = harbour_trial(duration=3.0, rate=10.0)
    data = "".join(s + "\r\n" for _, s in log_sentences(log)).encode()
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", 0))
    srv.listen(2)
    srv.settimeout(10)
    port = srv.getsockname()[1]

    def serve():
        cut = len(data) // 2
        for chunk in (data[:cut], data[cut:]):  # two connections; the cut falls mid-line, so the
            conn, _ = srv.accept()  # line's two halves arrive as two bad sentences
            for i in range(0, len(chunk), 37):  # small pieces: lines span several recv() calls
                conn.sendall(chunk[i:i + 37])
                time.sleep(0.0005)
            conn.close()

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    runner = LiveRunner([f"tcp://127.0.0.1:{port}"], make_online("fixed-lag"), duration=8.0, idle_exit=1.0)
    th, summary = start_runner(runner)
    th.join(15)
    server.join(1)
    srv.close()
    n = data.count(b"\n")
    assert summary["sentences_in"] in (n, n + 1)  # the line cut by the reconnect counts as two
    assert summary["bad_sentences"] <= 2
    assert summary["estimates"] >= _offline_estimates(log) - 1


def test_scans_from_replay_ends_the_run(tmp_path):
    log = harbour_trial(duration=3.0, rate=10.0, scans=True)
    scans = log.of("scan")
    est = make_online("fixed-lag")
    port = free_port()
    runner = LiveRunner([f"udp://127.0.0.1:{port}"], est, scans_from=log, duration=20.0)
    th, summary = start_runner(runner)
    replay(log, f"udp://127.0.0.1:{port}", speed=0)
    th.join(25)
    assert summary["stop_reason"] == "end of --scans-from replay"
    assert summary["scans_replayed"] == len(scans) == est.info()["scan"]


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_cli_sigterm_exits_cleanly_with_one_json_object(tmp_path):
    log = harbour_trial(duration=2.0, rate=10.0)
    port = free_port()
    p = start_live(tmp_path / "o", "--nmea", f"udp://127.0.0.1:{port}", "--duration", "60", "--json")
    try:
        replay(log, f"udp://127.0.0.1:{port}", speed=0)
        time.sleep(1.0)
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    obj = json.loads(out)  # exactly one JSON object on stdout
    keys = ("sentences_in", "bad_sentences", "estimates", "published", "latency_ms_median", "latency_ms_p99")
    for key in keys:
        assert key in obj
    # once the stream fell silent the runner coasted (predictions, counted apart)
    assert obj["stop_reason"] == "signal"
    assert obj["estimates"] - obj["coasted_estimates"] + obj["late_estimates"] == _offline_estimates(log)
    tum = Path(obj["tum"]).read_text().splitlines()
    assert len(tum) - 1 == obj["estimates"]  # nothing lost
    saved = json.loads(Path(obj["tum"]).with_suffix(".summary.json").read_text())
    assert saved["estimates"] == obj["estimates"]


def test_udp_scan_stream_joins_the_graph():
    """Scans as JSON datagrams (replay --scans-out -> live --scans): they reach the estimator as
    scan factors; a bad scan packet is counted, never fatal."""
    log = harbour_trial(duration=5.0, rate=10.0, scans=True)
    nport, sport = free_port(), free_port()
    est = make_online("fixed-lag")
    runner = LiveRunner([f"udp://127.0.0.1:{nport}"], est, scan_sources=[f"udp://127.0.0.1:{sport}"],
                        idle_exit=1.0, duration=20.0)
    th, summary = start_runner(runner)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for junk in (b"not json", b'{"type": "gnss"}', b'{"t": 1, "type": "scan", "ranges": [1, 2]}'):
            tx.sendto(junk, ("127.0.0.1", sport))
    time.sleep(0.2)
    sent = replay(log, f"udp://127.0.0.1:{nport}", speed=10.0, scans_target=f"udp://127.0.0.1:{sport}")
    th.join(25)
    assert sent["scans_sent"] == len(log.of("scan")) == 5
    assert summary["bad_scans"] == 3 and summary["scans_in"] == 8
    info = est.info()
    assert info["scan"] == 5 and info["icp_pairs"] - info["icp_failed"] >= 3


def test_tcp_source_down_then_up_does_not_stall_udp():
    log = harbour_trial(duration=2.0, rate=10.0)
    data = "".join(s + "\r\n" for _, s in log_sentences(log)).encode()
    uport, tport = free_port(), free_port(socket.SOCK_STREAM)
    est = make_online("fixed-lag")
    runner = LiveRunner([f"udp://127.0.0.1:{uport}", f"tcp://127.0.0.1:{tport}"], est, duration=12.0,
                        idle_exit=1.5)
    th, summary = start_runner(runner)
    replay(log, f"udp://127.0.0.1:{uport}", speed=0)  # TCP is down meanwhile (refused, retried)
    time.sleep(0.5)
    assert est.info()["gnss"] == len(log.of("gnss"))  # UDP fully processed while TCP was down
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", tport))
    srv.listen(1)
    srv.settimeout(5)
    conn, _ = srv.accept()  # the runner retries every second
    conn.sendall(data)
    conn.close()
    srv.close()
    th.join(15)
    assert summary["sentences_in"] == 2 * data.count(b"\n")
    n = len(log.of("gnss"))
    info = est.info()
    assert info["gnss"] == n and info["late"] >= n  # the TCP copy repeats old times: late
