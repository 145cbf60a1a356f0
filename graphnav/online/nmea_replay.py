"""Turn a log into NMEA 0183 traffic: timed sentences sent over UDP at ``speed`` x real time.

gnss/heading/odometry records become ZDA + GGA + RMC + HDT + VTG + ROT
(:func:`graphnav.io.nmea_out.log_to_nmea`); a log with only reference poses (e.g. the marina
dataset) is sent as the reference trajectory (:func:`graphnav.io.nmea_out.trajectory_to_nmea`).
``corrupt`` damages that fraction of sentences (flipped character, truncation or garbage) to
exercise a receiver's checksum handling.
"""

from __future__ import annotations

import heapq
import json
import socket
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from ..io.jsonl import record_to_obj
from ..io.nmea_out import frame_of, log_to_nmea, trajectory_to_nmea
from ..log import NavLog, Scan
from .transport import parse_endpoint


def log_sentences(log: NavLog, origin: tuple[float, float] | None = None) -> Iterator[tuple[float, str]]:
    """The timed sentences of a log (sensor records if it has any, else its truth trajectory)."""
    if any(r.kind in ("gnss", "heading", "odometry") for r in log.records):
        return log_to_nmea(log, origin=origin, with_rmc=True)
    truth = log.truth()
    if len(truth.t) == 0:
        raise ValueError("the log has no gnss, heading, odometry or truth records to send")
    return trajectory_to_nmea(truth.t, truth.poses, frame_of(log, origin))


def corrupt_sentence(s: str, rng: np.random.Generator) -> str:
    """A damaged copy of ``s``: one changed character, a truncation, or random printable garbage."""
    k = int(rng.integers(3))
    if k == 0:
        i = int(rng.integers(1, len(s)))
        c = chr(int(rng.integers(33, 127)))
        return s[:i] + (c if c != s[i] else "#") + s[i + 1:]
    if k == 1:
        return s[: int(rng.integers(1, len(s)))]
    return "".join(chr(int(c)) for c in rng.integers(32, 127, int(rng.integers(1, 60))))


def scan_packet(scan: Scan, decimals: int = 3) -> bytes:
    """One scan as a UDP datagram: its JSON Lines record (ranges rounded to mm, no return = null)."""
    obj = record_to_obj(scan)
    obj["ranges"] = [None if r is None else round(r, decimals) for r in obj["ranges"]]
    obj["angles"] = [None if a is None else round(a, 6) for a in obj["angles"]]
    return json.dumps(obj, separators=(",", ":")).encode("ascii")


def replay(log: NavLog, target: str, *, speed: float = 1.0, origin: tuple[float, float] | None = None,
           corrupt: float = 0.0, seed: int = 0, stop: threading.Event | None = None,
           scans_target: str | None = None) -> dict[str, Any]:
    """Send the log's sentences to ``udp://HOST:PORT`` paced at ``speed`` x real time (``speed <= 0``:
    as fast as possible); with ``scans_target`` also its scans, one JSON datagram each, in time order.
    Returns counts and the wall time."""
    ep = parse_endpoint(target, ("udp",))
    sep = parse_endpoint(scans_target, ("udp",)) if scans_target else None
    rng = np.random.default_rng(seed)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent = damaged = scans_sent = 0
    t_first = t_last = None
    start = time.monotonic()
    try:
        stream = log_sentences(log, origin)
        if sep is not None:
            scans = ((r.t, r) for r in log.records if isinstance(r, Scan))
            stream = heapq.merge(stream, scans, key=lambda item: item[0])
        for t, s in stream:
            if stop is not None and stop.is_set():
                break
            if t_first is None:
                t_first = t
            t_last = t
            if speed > 0:
                due = start + (t - t_first) / speed
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            if isinstance(s, Scan):
                sock.sendto(scan_packet(s), (sep.host, sep.port))
                scans_sent += 1
                continue
            if corrupt > 0 and rng.random() < corrupt:
                s = corrupt_sentence(s, rng)
                damaged += 1
            sock.sendto((s + "\r\n").encode("ascii"), (ep.host, ep.port))
            sent += 1
    finally:
        sock.close()
    return {"sentences_sent": sent, "corrupted": damaged, "scans_sent": scans_sent, "t0": t_first,
            "t1": t_last,
            "wall_s": time.monotonic() - start, "target": str(ep), "speed": speed}
