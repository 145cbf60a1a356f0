"""Test helper: a real ``graphnav live`` process on loopback, started and waited for."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def start_live(out_dir: Path, *args: str, ready_s: float = 30.0) -> subprocess.Popen:
    """``python -m graphnav live --out OUT_DIR ARGS...`` (this checkout's code), returned once it
    listens (its ``live-*.tum`` exists) or ``ready_s`` has passed."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.Popen([sys.executable, "-m", "graphnav", "live", "--out", str(out_dir), *args],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=out_dir.parent)
    deadline = time.monotonic() + ready_s
    while not any(out_dir.glob("live-*.tum")) and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
    time.sleep(0.2)
    return p


def send_and_wait(p: subprocess.Popen, port: int, datagrams: list[str], *, pause_s: float,
                  timeout_s: float) -> tuple[str, str]:
    """Send each text datagram (CRLF-terminated) to ``127.0.0.1:port`` with ``pause_s`` between them, then
    wait for ``p`` to exit by itself (its ``--idle-exit``); killed if it has not by ``timeout_s``. Its
    stdout and stderr."""
    import socket

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for d in datagrams:
                tx.sendto((d + "\r\n").encode(), ("127.0.0.1", port))
                time.sleep(pause_s)
        return p.communicate(timeout=timeout_s)
    finally:
        if p.poll() is None:
            p.kill()


def fed_up_to_the_gap(runner, log, t_gap: float, wall: float = 100.0) -> int:  # noqa: ANN001
    """A ``LiveRunner`` fed ``log``'s records up to ``t_gap`` (no sockets), the stream's last stamp ``t_gap``
    arriving at wall time ``wall`` (so ``runner.tick(now=wall + s)`` is ``s`` seconds of silence); returns
    the estimates emitted so far."""
    for rec in log.records:
        if rec.t > t_gap:
            break
        runner._record(rec, None)
    runner.nmea.clock.t0, runner.nmea.clock.a0 = t_gap, wall
    return runner.sink.estimates
