"""Memory and throughput of the live path without sockets, over many hours of 10 Hz NMEA.

The harbour scenario with 10 Hz GNSS/compass/odometry (the route repeated for ``--hours``;
``graphnav.sim.harbour``, no scans) is simulated up front -- its records stay in memory for the
whole run, so they are part of the first RSS sample, not of any growth -- then turned into NMEA
sentences (ZDA, GGA, RMC, HDT, VTG, ROT) one at a time, parsed and decoded exactly as
``graphnav live`` does (checksum required, :class:`graphnav.io.nmea.NmeaDecoder` with
``keep=False``) and fed to the online estimator as fast as possible. RSS is sampled every
simulated ``--every`` minutes.

With ``--log FILE.jsonl[.gz]`` the records are instead streamed from that file line by line
(constant memory: nothing but the estimator grows), e.g. a day made beforehand in its own process:

    python benchmarks/online_memory.py --hours 4
    for k in 0 1 2 3; do  # one simulation holds at most ~7 h of this in memory: 4 x 35 laps = 25 h
      t0=$(python -c "print(1.7e9 + $k * 22511)")
      graphnav simulate harbour --profile legacy --laps 35 --fix-hz 10 --lidar-hz 0 --t0 $t0 --seed $((7 + k)) \
          --out day$k.jsonl.gz
    done
    cat day0.jsonl.gz day1.jsonl.gz day2.jsonl.gz day3.jsonl.gz > day.jsonl.gz
    python benchmarks/online_memory.py --log day.jsonl.gz --every 60
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from graphnav.io.jsonl import parse_record  # noqa: E402
from graphnav.io.nmea import NmeaDecoder, parse_sentence  # noqa: E402
from graphnav.io.nmea_out import log_to_nmea  # noqa: E402
from graphnav.log import NavLog  # noqa: E402
from graphnav.online.runner import make_online  # noqa: E402
from graphnav.sim.harbour import HarbourConfig, simulate_harbour  # noqa: E402


def sensor_log(hours: float) -> NavLog:
    """``hours`` of the harbour route, 10 Hz GNSS, compass and SOG/ROT: the NMEA-carried records only."""
    log = simulate_harbour(7, HarbourConfig.legacy(fix_hz=10.0, lidar_hz=0.0, t0=1.7e9), duration=hours * 3600)
    keep = [r for r in log.records if r.kind in ("gnss", "heading", "odometry")]
    return NavLog(keep, meta={"origin": {"lat": 43.5, "lon": 16.4}})


class _Chunk:  # what log_to_nmea reads (records + meta); it walks the records twice, so a list
    def __init__(self, records: list) -> None:
        self.records = records
        self.meta = {"origin": {"lat": 43.5, "lon": 16.4}}


def _read(path: Path) -> Iterator:
    import gzip

    with (gzip.open(path, "rt") if path.suffix == ".gz" else path.open()) as fh:
        for line in fh:
            obj = json.loads(line)
            if obj.get("type") in ("gnss", "heading", "odometry"):
                yield parse_record(obj)


def streamed_sentences(path: Path, chunk: int = 10000) -> Iterator[tuple[float, str]]:
    """The records of a JSON Lines file as NMEA, read line by line and converted ``chunk`` records at a time
    (cut between two times, so each time gets one ZDA): constant memory."""
    buf: list = []
    for rec in _read(path):
        if len(buf) >= chunk and rec.t != buf[-1].t:
            yield from log_to_nmea(_Chunk(buf), with_rmc=True)
            buf = []
        buf.append(rec)
    if buf:
        yield from log_to_nmea(_Chunk(buf), with_rmc=True)


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=4.0, help="simulated hours (ignored with --log)")
    ap.add_argument("--log", type=Path, help="stream the records from this .jsonl[.gz] instead")
    ap.add_argument("--every", type=float, default=30.0, help="sample RSS every N simulated minutes")
    ap.add_argument("--estimator", default="fixed-lag")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--progress", action="store_true", help="each RSS sample to stderr as it is taken")
    args = ap.parse_args()
    w_sim = time.perf_counter()
    if args.log is not None:
        sentences = streamed_sentences(args.log)
    else:
        log = sensor_log(args.hours)
        print(f"simulated {len(log.records)} records in {time.perf_counter() - w_sim:.0f} s", file=sys.stderr)
        sentences = log_to_nmea(log, with_rmc=True)
    est = make_online(args.estimator)
    dec = NmeaDecoder(keep=False)
    rows = []
    n_sent = n_est = 0
    t_first = None
    next_sample = 0.0
    w0 = time.perf_counter()
    for t, s in sentences:
        if t_first is None:
            t_first = t
        if t - t_first >= next_sample:
            rows.append({"sim_h": (t - t_first) / 3600, "rss_mb": rss_mb(),
                         "wall_s": time.perf_counter() - w0, "sentences": n_sent, "estimates": n_est})
            if args.progress:
                print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
            next_sample += args.every * 60
        n_sent += 1
        for rec in dec.feed(parse_sentence(s, require_checksum=True)):
            if est.add(rec) is not None:
                n_est += 1
    wall = time.perf_counter() - w0
    rows.append({"sim_h": (t - t_first) / 3600, "rss_mb": rss_mb(), "wall_s": wall, "sentences": n_sent,
                 "estimates": n_est})
    summary = {"hours": (t - t_first) / 3600, "log": str(args.log) if args.log else "simulated in memory",
               "estimator": args.estimator, "sentences": n_sent, "estimates": n_est,
               "wall_s": wall,
               "sentences_per_s": n_sent / wall, "estimates_per_s": n_est / wall,
               "realtime_factor": (t - t_first) / wall, "rss": rows}
    if args.json:
        print(json.dumps(summary))
        return 0
    print("| simulated h | RSS MB | wall s | sentences | estimates |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['sim_h']:.2f} | {r['rss_mb']:.1f} | {r['wall_s']:.0f} | {r['sentences']} "
              f"| {r['estimates']} |")
    print(f"\nthroughput: {summary['sentences_per_s']:.0f} sentences/s, "
          f"{summary['estimates_per_s']:.0f} estimates/s, "
          f"{summary['realtime_factor']:.1f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
