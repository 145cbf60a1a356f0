"""Live-mode figures: end-to-end latency at 10 Hz input, sustained throughput, memory over a long replay.

Runs the real CLI in separate processes on loopback: ``graphnav live`` (receiver, estimator,
publisher) and ``graphnav replay`` (sender) on the harbour scenario with 10 Hz GNSS and compass
(``graphnav simulate harbour --profile legacy --fix-hz 10 --lidar-hz 0``; GGA + RMC + ZDA + HDT + VTG + ROT per
epoch), samples the live process's RSS from /proc every second, and prints a table (plus one JSON
object with ``--json``). By default it measures fixed-lag, isam2 and ekf one after the other.

    python benchmarks/live_bench.py                      # 60 s at 1x for fixed-lag, isam2 and ekf
    python benchmarks/live_bench.py --realtime 0 --long-hours 1 --long-speed 10 --estimator fixed-lag
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from graphnav.io import save_log  # noqa: E402
from graphnav.sim.harbour import HarbourConfig, simulate_harbour  # noqa: E402

T0 = 1.7e9  # POSIX start of the simulated logs (NMEA needs dates)


def harbour_log(seconds: float, seed: int):
    """The harbour route (repeated as needed) with 10 Hz GNSS/compass/odometry and no scans."""
    return simulate_harbour(seed, HarbourConfig.legacy(fix_hz=10.0, lidar_hz=0.0, t0=T0), duration=seconds)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def session(log_path: Path, seconds: float, speed: float, estimator: str, workdir: Path) -> dict:
    port, pub = free_port(), free_port()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # a consumer of the published NMEA
    sink.bind(("127.0.0.1", pub))
    sink.settimeout(0.2)
    received = [0]
    stop = threading.Event()

    def drain():
        while not stop.is_set():
            try:
                received[0] += sink.recv(65536).count(b"\n")
            except TimeoutError:
                pass

    th = threading.Thread(target=drain, daemon=True)
    th.start()
    cmd = [sys.executable, "-m", "graphnav", "live", "--nmea", f"udp://127.0.0.1:{port}",
           "--estimator", estimator, "--publish", f"udp://127.0.0.1:{pub}",
           "--out", str(workdir / f"live-{speed:g}x"), "--idle-exit", "3", "--json"]
    live = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=REPO)
    time.sleep(3.0)  # imports
    rss: list[tuple[float, float]] = []
    t0 = time.monotonic()
    rep = subprocess.Popen([sys.executable, "-m", "graphnav", "replay", str(log_path), "--nmea-out",
                            f"udp://127.0.0.1:{port}", "--speed", str(speed), "--json"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=REPO)
    while rep.poll() is None:
        r = rss_mb(live.pid)
        if r is not None:
            rss.append((time.monotonic() - t0, r))
        time.sleep(1.0)
    sent = json.loads(rep.stdout.read())
    out = json.loads(live.communicate(timeout=120)[0])
    stop.set()
    th.join(1)
    sink.close()
    r = np.array([v for _, v in rss]) if rss else np.zeros(1)
    n = len(r)
    return {
        "log_s": sent["t1"] - sent["t0"], "speed": speed, "sent": sent["sentences_sent"],
        "sentences_in": out["sentences_in"], "bad_sentences": out["bad_sentences"],
        "estimates": out["estimates"],
        "published": out["published"], "received_by_sink": received[0],
        "latency_ms_median": out["latency_ms_median"], "latency_ms_p99": out["latency_ms_p99"],
        "latency_ms_max": out["latency_ms_max"], "latency_ms_by_kind": out.get("latency_ms_by_kind", {}),
        "wall_s": out["wall_s"],
        "sentences_per_s": sent["sentences_sent"] / sent["wall_s"],
        "rss_mb_first_10pct": float(np.median(r[: max(1, n // 10)])),
        "rss_mb_last_10pct": float(np.median(r[-max(1, n // 10):])),
        "rss_mb_max": float(r.max()), "rss_samples": n,
        "rss_mb_at_25_50_75_100pct": [float(r[min(n - 1, int(q * n))]) for q in (0.25, 0.5, 0.75, 1.0)],
        "estimator": estimator, "solve_ms_median": out.get("estimator", {}).get("step_ms_median"),
        "solve_ms_p99": out.get("estimator", {}).get("step_ms_p99"),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--realtime", type=float, default=60.0, help="seconds of 10 Hz input at 1x (latency)")
    ap.add_argument("--long-hours", type=float, default=0.0, help="hours of log for the memory/throughput run")
    ap.add_argument("--long-speed", type=float, default=10.0)
    ap.add_argument("--estimator", action="append", help="repeatable (default: fixed-lag, isam2, ekf)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = {}
    estimators = args.estimator or ["fixed-lag", "isam2", "ekf"]
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        if args.realtime > 0:
            p = work / "rt.jsonl"
            save_log(harbour_log(args.realtime, seed=1), p)
            for est in estimators:
                rows[f"{est}, 10 Hz, 1x"] = session(p, args.realtime, 1.0, est, work)
        if args.long_hours > 0:
            p = work / "long.jsonl.gz"
            save_log(harbour_log(args.long_hours * 3600, seed=2), p)
            for est in estimators:
                rows[f"{est}, 10 Hz, {args.long_speed:g}x, {args.long_hours:g} h log"] = session(
                    p, args.long_hours * 3600, args.long_speed, est, work)
    if args.json:
        print(json.dumps(rows))
        return 0
    keys = ["sent", "sentences_in", "bad_sentences", "estimates", "published", "received_by_sink",
            "latency_ms_median", "latency_ms_p99", "latency_ms_max", "solve_ms_median", "solve_ms_p99",
            "sentences_per_s", "wall_s", "rss_mb_first_10pct", "rss_mb_last_10pct", "rss_mb_max",
            "rss_mb_at_25_50_75_100pct"]
    names = list(rows)
    print("| metric | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for k in keys:
        vals = [rows[n][k] for n in names]
        fmt = [f"{v:.2f}" if isinstance(v, float) else
               (" / ".join(f"{x:.1f}" for x in v) if isinstance(v, list) else str(v)) for v in vals]
        print(f"| {k} | " + " | ".join(fmt) + " |")
    print("\nlatency by the record kind that produced the estimate (n, median / p99 / max ms):")
    for n in names:
        by = rows[n]["latency_ms_by_kind"]
        print(f"  {n}: " + "; ".join(f"{kind} n={v['n']} {v['median']:.2f} / {v['p99']:.2f} / {v['max']:.2f}"
                                     for kind, v in sorted(by.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
