"""Live mode's scans: LiDAR scans from UDP datagrams, or replayed from a log, handed over on the NMEA
stream's clock.

A datagram is one JSON Lines ``scan`` record (docs/log-format.md: ``{"t", "type": "scan", "ranges",
"angles"}`` or ``angle_min``/``angle_increment``; ``null``/0 = no return), ``t`` on the NMEA clock
(POSIX s); bad packets are counted (``bad_scans``). A scan waits until the stream's time reaches it,
so a scan that overtakes the sentences of earlier epochs (another socket) does not make them late.
A replayed log's scans are handed over when the stream's time passes them (if the two time bases
differ by more than 60 s, the log is shifted so that its first scan falls on the first timed
sentence); ``done`` when the last has been.
"""

from __future__ import annotations

import bisect
import json
import logging
from dataclasses import replace

from ..errors import LogError
from ..io.jsonl import parse_record
from ..log import NavLog, Scan

log_ = logging.getLogger("graphnav.live")
MAX_WAITING = 100  # network scans held for the stream clock at most (the oldest is dropped, counted bad)


class ScanFeed:
    """``packet(data)``: one datagram -> a scan (or a bad one, counted); ``hold(scan, arrival)``: it waits;
    ``due(t)``: the scans the stream time ``t`` has reached, each with its datagram's arrival (``None``:
    replayed), in time order (waiting ones first, then the replay's)."""

    def __init__(self, replay: NavLog | None = None) -> None:
        self.waiting: list[tuple[Scan, float]] = []
        self.scans_in = self.bad_scans = 0
        self.replay = [r for r in replay.records if isinstance(r, Scan)] if replay is not None else None
        self.replayed = 0
        self.shift: float | None = None

    @property
    def done(self) -> bool:
        """Every scan of the replay has been handed over."""
        return self.replay is not None and self.replayed >= len(self.replay)

    def packet(self, data: bytes) -> Scan | None:
        """Parse one datagram (``None`` and counted when it is not a scan record)."""
        self.scans_in += 1
        try:
            try:
                obj = json.loads(data)
            except (ValueError, RecursionError):
                raise LogError("scan datagram is not JSON", field="scan") from None
            if not isinstance(obj, dict) or obj.get("type") != "scan":
                raise LogError("scan datagram must be a JSON object with type 'scan'", field="type")
            return parse_record(obj)
        except LogError as err:
            self.bad_scans += 1
            if self.bad_scans <= 20 or self.bad_scans % 1000 == 0:
                log_.warning("bad scan packet #%d (%s)", self.bad_scans, err)
            return None

    def hold(self, scan: Scan, arrival: float) -> None:
        """Keep a network scan (that arrived at ``arrival``) until the stream's time reaches it."""
        if len(self.waiting) >= MAX_WAITING:
            self.waiting.pop(0)
            self.bad_scans += 1
        bisect.insort(self.waiting, (scan, arrival), key=lambda sa: sa[0].t)

    def due_waiting(self, t_stream: float) -> list[tuple[Scan, float]]:
        """The network scans the stream time ``t_stream`` has reached, with their arrival."""
        out = []
        while self.waiting and self.waiting[0][0].t <= t_stream + 1e-6:
            out.append(self.waiting.pop(0))
        return out

    def due(self, t_stream: float) -> list[tuple[Scan, float | None]]:
        out: list[tuple[Scan, float | None]] = list(self.due_waiting(t_stream))
        if self.replay is None:
            return out
        if self.shift is None and self.replay:
            d = t_stream - self.replay[0].t
            self.shift = d if abs(d) > 60.0 else 0.0
        while self.replayed < len(self.replay) and self.replay[self.replayed].t + self.shift <= t_stream:
            sc = self.replay[self.replayed]
            self.replayed += 1
            out.append((replace(sc, t=sc.t + self.shift) if self.shift else sc, None))
        return out
