"""Live mode's sink: each estimate published as NMEA (GGA, HDT, VTG, ROT; one UDP datagram) and as a
Signal K delta (:func:`graphnav.io.signalk.solution_delta`, uncertainties under meta), timed
(GNSS sentence arrival -> solution sent, over the last :data:`LATENCY_WINDOW` fixes) and appended to
a new TUM file per run (``DIR/live-YYYYmmddTHHMMSSZ.tum``, + ``.cov``, flushed line by line). A coasted
estimate (a prediction through a silent stream) is flagged in each output that can carry it: GGA quality 6,
Signal K ``navigation.gnss.methodQuality`` "Estimated (DR) mode"; the TUM file cannot, so the summary lists
the spans of coasted estimates (``coasted_spans``)."""

from __future__ import annotations

import json
import logging
import math
import socket
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GraphnavError
from ..geodesy import LocalFrame
from ..io.nmea_fields import UERE_M
from ..io.nmea_out import no_fix_sentences, solution_sentences
from ..io.outputs import ensure_dir
from ..io.tum import TrajectoryWriter
from ..log import RECORD_TYPES
from ..result import Estimate
from .transport import parse_endpoint, resolve

log_ = logging.getLogger("graphnav.live")
LATENCY_WINDOW = 100_000
MAX_SPANS = 1000  # coasted spans kept for the summary (the newest)
_KINDS = ("", *RECORD_TYPES)  # latency ring buffer: the record kind of each estimate ("": unknown)


def _by_kind(lat: np.ndarray, kinds: np.ndarray) -> dict[str, dict[str, float | int]]:
    """Latency median / p99 / max [ms] and count per record kind that produced estimates."""
    out: dict[str, dict[str, float | int]] = {}
    for code in np.unique(kinds):
        v = lat[kinds == code]
        out[_KINDS[int(code)] or "other"] = {"n": int(v.size), "median": float(np.median(v)),
                                               "p99": float(np.percentile(v, 99)), "max": float(v.max())}
    return out


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


class Sink:
    """Where the estimates go: ``publish`` (``udp://HOST:PORT``, NMEA), ``publish_signalk`` (``udp://``,
    Signal K deltas) and ``out_dir`` (a new TUM file);
    ``emit(est, arrival, frame)`` sends, times and writes one (``frame``: the local frame of the NMEA
    output; ``None``: nothing published yet)."""

    def __init__(self, publish: str | None = None, out_dir: str | Path | None = None,
                 publish_signalk: str | None = None) -> None:
        self.publish = parse_endpoint(publish, ("udp",)) if publish else None
        self.publish_signalk = parse_endpoint(publish_signalk, ("udp",)) if publish_signalk else None
        self.out_dir = Path(out_dir) if out_dir else None
        self.sock: socket.socket | None = None
        self.addr: tuple[str, int] | None = None
        self.sk_sock: socket.socket | None = None
        self.sk_addr: tuple[str, int] | None = None
        self.published_signalk = 0
        self.writer: TrajectoryWriter | None = None
        self.latency_ms = np.full(LATENCY_WINDOW, np.nan)  # ring buffer: constant memory
        self.latency_kind = np.zeros(LATENCY_WINDOW, dtype=np.int8)  # index into _KINDS of each
        self.n_latency = self.estimates = self.published = 0
        self.coasted = 0  # estimates that were predictions through a silent stream (GGA quality 6)
        self.no_fix_outputs = 0  # times said to have no solution (coasting stopped at coast_max_s)
        self.late = 0  # estimates older than one already emitted (a keyframe solved after coasting past it): dropped
        self.last: Estimate | None = None
        #: [first t, last t, count] of each run of consecutive coasted estimates (the newest MAX_SPANS)
        self.spans: deque[list[float]] = deque(maxlen=MAX_SPANS)
        self.n_spans = 0
        self._in_span = False
        self.newest: float | None = None  # the newest time emitted since the clock's last re-sync
        self.hdop = 1.0  # published HDOP: from the last estimate that carried a covariance

    def open(self) -> None:
        if self.out_dir is not None:
            self.writer = new_live_file(self.out_dir)
        if self.publish is not None:
            self.addr = resolve(self.publish)
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if self.publish_signalk is not None:
            self.sk_addr = resolve(self.publish_signalk)
            self.sk_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        for s in (self.sock, self.sk_sock):
            if s is not None:
                s.close()

    def resync(self) -> None:
        """The stream's clock stepped back (a re-sync): what comes next is not late against what went before."""
        self.newest = None

    def emit(self, est: Estimate, arrival: float | None, frame: LocalFrame | None, kind: str = "") -> None:
        """Publish one estimate (NMEA), time its latency (``kind``: the record kind that produced it),
        append it to the output file. An estimate older than one already emitted (a keyframe solved once
        the stream came back, after predictions had coasted past its time) is counted in ``late`` and
        dropped: the published times and the file's only go forward, and the online output stays what
        was said at the time."""
        if self.newest is not None and est.t < self.newest:
            self.late += 1
            return
        self.newest = est.t
        self.estimates += 1
        self.coasted += est.coasted
        if est.coasted:  # the spans of coasted estimates (the TUM file cannot flag them)
            if self._in_span and self.spans:
                self.spans[-1][1:] = [est.t, self.spans[-1][2] + 1]
            else:
                self.spans.append([est.t, est.t, 1])
                self.n_spans += 1
        self._in_span = est.coasted
        self.last = est
        if self.sock is not None and frame is not None:
            if est.cov is not None and np.all(np.isfinite(est.cov[:2, :2])):  # HDOP = sigma / UERE(GPS)
                self.hdop = max(0.01, math.sqrt(max(0.0, 0.5 * (est.cov[0, 0] + est.cov[1, 1]))) / UERE_M[1])
            lines = solution_sentences(est.t, est.vec, frame, sog=est.sog, cog_yaw=est.cog, w=est.w, hdop=self.hdop,
                                       quality=6 if est.coasted else 1)  # GGA quality 6: estimated (dead reckoning)
            self._send_nmea(lines)
        if self.sk_sock is not None and frame is not None:
            from ..io.signalk import solution_delta

            delta = solution_delta(est.t, est.vec, frame, cov=est.cov, sog=est.sog, cog_yaw=est.cog, w=est.w,
                                   coasted=est.coasted)  # navigation.gnss.methodQuality "Estimated (DR) mode"
            self._send_signalk(delta)
        if arrival is not None:  # the published solution is the latency-critical path; the file comes next
            i = self.n_latency % LATENCY_WINDOW
            self.latency_ms[i] = (time.perf_counter() - arrival) * 1e3
            self.latency_kind[i] = _KINDS.index(kind) if kind in _KINDS else 0
            self.n_latency += 1
        if self.writer is not None:
            self.writer.write(est.t, est.vec, est.cov)

    def no_fix(self, t: float) -> None:
        """Say that there is no solution at ``t`` (coasting stopped at ``coast_max_s``): GGA quality 0 and
        RMC status V (NMEA), ``methodQuality`` "no GPS" (Signal K); nothing is written to the file, which
        holds estimates only."""
        if self.newest is not None and t < self.newest:
            return
        self.newest = t
        self.no_fix_outputs += 1
        self._in_span = False
        if self.sock is not None:
            self._send_nmea(no_fix_sentences(t))
        if self.sk_sock is not None:
            from ..io.signalk import no_fix_delta

            self._send_signalk(no_fix_delta(t))

    def _send_nmea(self, lines: list[str]) -> None:
        """One datagram of NMEA sentences to ``publish`` (a failed send is logged, not raised)."""
        assert self.sock is not None
        try:
            self.sock.sendto(("\r\n".join(lines) + "\r\n").encode("ascii"), self.addr)
            self.published += len(lines)
        except OSError as exc:
            log_.warning("publish to %s failed: %s", self.publish, exc)

    def _send_signalk(self, delta: dict[str, Any]) -> None:
        """One Signal K delta to ``publish_signalk`` (a failed send is logged, not raised)."""
        assert self.sk_sock is not None
        try:
            self.sk_sock.sendto(json.dumps(delta).encode("utf-8"), self.sk_addr)
            self.published_signalk += 1
        except OSError as exc:
            log_.warning("publish to %s failed: %s", self.publish_signalk, exc)

    def summary(self) -> dict[str, Any]:
        lat = self.latency_ms[: min(self.n_latency, LATENCY_WINDOW)]
        out: dict[str, Any] = {
            "estimates": self.estimates, "coasted_estimates": self.coasted,
            "coasted_spans": [[a, b, int(n)] for a, b, n in self.spans], "coasted_spans_total": self.n_spans,
            "late_estimates": self.late, "no_fix_outputs": self.no_fix_outputs,
            "published": self.published,
            "latency_ms_median": float(np.median(lat)) if lat.size else None,
            "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else None,
            "latency_ms_max": float(lat.max()) if lat.size else None,
            "latency_ms_by_kind": _by_kind(lat, self.latency_kind[: lat.size])}
        if self.publish_signalk is not None:
            out["published_signalk"] = self.published_signalk
        if self.out_dir is not None:
            out["out"] = str(self.out_dir)
            if self.writer is not None:
                out["tum"] = str(self.writer.path)
        return out
