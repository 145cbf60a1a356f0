"""The live EKF through silent gaps: how many estimates it coasts and whether their stated covariance
holds the error (docs/live.md, *Coasting*).

    python benchmarks/ekf_coast.py LOG [--start S] [--duration D] [--json]      # a real NMEA 0183 log
    python benchmarks/ekf_coast.py --synthetic [--gap A,B] [--json]             # simulated, with truth

The log's sentences go through :class:`graphnav.online.live_runner.LiveRunner` (the live decoder, stream
clock and sink, no sockets) with ``make_online("ekf")`` as ``graphnav live -e ekf`` makes it. Each line
arrives at the wall time of its own stream time (a 1x replay: a first pass of the decoder gives every
line's stream time), and the runner's clock ticks every 50 ms of that wall time in between, as its loop
does: silent stretches of the log are coasted through exactly as live. ``--synthetic``: ``graphnav
simulate harbour --profile legacy`` (1 Hz fixes, 10 Hz compass and SOG/ROT), every record inside ``--gap``
removed, replayed as NMEA (GGA, RMC, HDT, VTG, ROT).

Reported: the coasted estimates and spans; against the truth (synthetic), each coasted estimate's error and
NEES (2 dof: mean 2 when the covariance is right), binned by the time since the span began; against the
fixes that come back (real log), the first fix after each span against the last coasted estimate carried
to the fix's time at its own SOG/COG: the distance and the NIS with the fix's sigma added (2 dof).
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.estimators import make_online  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import ODOMETRY_FROM_ROT, NavLog, Record  # noqa: E402
from graphnav.online.live_runner import LiveRunner  # noqa: E402
from graphnav.online.nmea_replay import log_sentences  # noqa: E402
from graphnav.online.stream_clock import NmeaInput  # noqa: E402
from graphnav.result import Estimate  # noqa: E402

TICK_S = 0.05  # LiveRunner's loop polls every 50 ms


class Tape(LiveRunner):
    """The live loop without sockets; every record handed over and every estimate emitted is kept."""

    def __init__(self, estimator: Any, origin: tuple[float, float] | None) -> None:
        super().__init__(["udp://127.0.0.1:9"], estimator, origin=origin, require_checksum=False)
        self.taped: list[Record] = []
        self.out: list[Estimate] = []
        emit = self.sink.emit

        def keep(est: Estimate, arrival: float | None, frame: Any, kind: str = "") -> None:
            n = self.sink.estimates
            emit(est, arrival, frame, kind)
            if self.sink.estimates > n:  # (a late one is not emitted)
                self.out.append(est)

        self.sink.emit = keep  # type: ignore[method-assign]

    def _record(self, rec: Record, arrival: float | None) -> None:
        self.taped.append(rec)
        super()._record(rec, arrival)


def stream_times(lines: list[bytes], origin: tuple[float, float] | None) -> list[float | None]:
    """Each line's stream time (the decoder's clock after it), from a first pass that accepts every stamp."""
    nm = NmeaInput(lambda recs, a: None, lambda: None, origin=origin, require_checksum=False)
    out = []
    for i, ln in enumerate(lines):
        nm.feed(ln, 1e6 * i)  # arrivals far apart: no stamp is an outlier
        out.append(nm.t)
    return out


def play(lines: list[bytes], times: list[float | None], origin: tuple[float, float] | None,
         t0: float, t1: float) -> tuple[Tape, float]:
    """The lines stamped in ``[t0, t1]`` at 1x, the clock ticking every :data:`TICK_S` between; CPU seconds."""
    run = Tape(make_online("ekf", meta={"odometry": ODOMETRY_FROM_ROT}), origin)
    c0 = time.process_time()
    base = 1000.0  # the wall clock of the stream's first line
    first = next(t for t in times if t is not None and t >= t0)
    now = None
    for ln, t in zip(lines, times, strict=True):
        if t is None or t < t0:
            continue
        if t > t1:
            break
        a = base + (t - first)
        if now is not None:
            while now + TICK_S < a:
                now += TICK_S
                run.tick(now)
        run.feed_sentence(ln, a)
        now = a if now is None else max(now, a)
    return run, time.process_time() - c0


def spans(c: np.ndarray) -> list[tuple[int, int]]:
    """[i, j] index ranges of consecutive coasted estimates."""
    out, i = [], None
    for k, v in enumerate(c):
        if v and i is None:
            i = k
        if not v and i is not None:
            out.append((i, k - 1))
            i = None
    if i is not None:
        out.append((i, len(c) - 1))
    return out


def nees(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    return np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err)


def against_truth(ests: list[Estimate], log: NavLog) -> dict[str, Any]:
    c = np.array([e.coasted for e in ests])
    tr = log.truth()
    rows = []
    for i, j in spans(c):
        for k in range(i, j + 1):
            e = ests[k]
            ref = tr.interpolate(np.array([e.t]))[0]
            err = e.vec[:2] - ref[:2]
            rows.append((e.t - ests[i].t, math.hypot(*err), float(nees(err[None], e.cov[None, :2, :2])[0]),
                         math.sqrt(0.5 * (e.cov[0, 0] + e.cov[1, 1]))))
    a = np.array(rows).reshape(-1, 4)
    bins = {}
    for lo, hi in ((0, 10), (10, 30), (30, 60), (60, 1e9)):
        m = (a[:, 0] >= lo) & (a[:, 0] < hi)
        if m.any():
            bins[f"{lo}-{hi if hi < 1e9 else 'end'} s"] = {
                "n": int(m.sum()), "error_rmse_m": float(np.sqrt(np.mean(a[m, 1] ** 2))),
                "stated_sigma_rms_m": float(np.sqrt(np.mean(a[m, 3] ** 2))), "nees_mean": float(np.mean(a[m, 2])),
                "inside_99pct": float(np.mean(a[m, 2] < 9.21))}
    return {"coasted": int(c.sum()), "spans": len(spans(c)), "nees_mean": float(np.mean(a[:, 2])) if len(a) else None,
            "inside_99pct": float(np.mean(a[:, 2] < 9.21)) if len(a) else None, "by_time_coasted": bins}


def against_fixes(ests: list[Estimate], fixes: list[Record]) -> dict[str, Any]:
    """The first fix after each coasted span against the span's last estimate carried to its time."""
    c = np.array([e.coasted for e in ests])
    ft = np.array([f.t for f in fixes])
    rows = []
    for i, j in spans(c):
        e = ests[j]
        k = int(np.searchsorted(ft, e.t, side="right"))
        if k == len(ft):
            continue
        f = fixes[k]
        dt = f.t - e.t
        p = e.vec[:2].copy()
        if e.sog is not None and e.cog is not None:
            p += e.sog * dt * np.array([math.cos(e.cog), math.sin(e.cog)])
        err = np.array([f.x, f.y]) - p
        cov = e.cov[:2, :2] + np.eye(2) * f.sigma ** 2
        rows.append({"t": e.t, "span_s": e.t - ests[i].t + (ests[i].t - ests[i - 1].t if i else 0.0),
                     "n": j - i + 1, "error_m": float(math.hypot(*err)),
                     "stated_sigma_m": float(math.sqrt(0.5 * np.trace(e.cov[:2, :2]))), "fix_sigma_m": f.sigma,
                     "nis": float(nees(err[None], cov[None])[0])})
    nis = np.array([r["nis"] for r in rows])
    return {"coasted": int(c.sum()), "spans": len(spans(c)), "scored_spans": len(rows),
            "nis_mean": float(nis.mean()) if nis.size else None,
            "nis_median": float(np.median(nis)) if nis.size else None,
            "inside_99pct": float(np.mean(nis < 9.21)) if nis.size else None, "spans_detail": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", nargs="?")
    ap.add_argument("--synthetic", action="store_true")
    ap.add_argument("--gap", default="100,160", help="--synthetic: the silent gap [s after the start]")
    ap.add_argument("--start", type=float, default=0.0, help="slice start after the log's first record [s]")
    ap.add_argument("--duration", type=float, default=1e9)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    truth_log = None
    if args.synthetic:
        a, b = (float(v) for v in args.gap.split(","))
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "h.jsonl"
            subprocess.run([sys.executable, "-m", "graphnav", "simulate", "harbour", "--profile", "legacy",
                            "--duration", "300", "--fix-hz", "1", "--lidar-hz", "0", "--t0", "1.7e9", "--out",
                            str(path)], check=True, cwd=ROOT, capture_output=True)
            truth_log = load_log(path)
        t00 = truth_log.t0
        truth_log = truth_log.without(lambda r: r.kind != "truth" and t00 + a < r.t < t00 + b)
        origin = (truth_log.meta["origin"]["lat"], truth_log.meta["origin"]["lon"])
        timed = list(log_sentences(truth_log, origin=origin))
        lines = [s.encode() for _, s in timed]
        times: list[float | None] = [t for t, _ in timed]
        t0, t1 = truth_log.t0, truth_log.t1
    else:
        log = load_log(args.log)
        origin = (log.meta["origin"]["lat"], log.meta["origin"]["lon"])
        opener = gzip.open if args.log.endswith(".gz") else open
        with opener(args.log, "rb") as fh:
            lines = [ln.rstrip(b"\r\n") for ln in fh if ln.strip() and not ln.startswith(b"#")]
        times = stream_times(lines, origin)
        t0 = float(log.t0) + args.start
        t1 = t0 + args.duration
    run, cpu = play(lines, times, origin, t0, t1)
    s = run.summary()
    out: dict[str, Any] = {"log": "synthetic harbour (legacy), gap " + args.gap if args.synthetic else args.log,
                           "slice_s": [args.start, args.duration], "motion": s["estimator"].get("motion"),
                           "estimates": s["estimates"], "coasted_estimates": s["coasted_estimates"],
                           "coasted_spans_total": s["coasted_spans_total"],
                           "coast_period_s": s["estimator"].get("coast_period_s"), "cpu_s": cpu}
    if truth_log is not None:
        out["against_truth"] = against_truth(run.out, truth_log)
    fixes = [r for r in run.taped if r.kind == "gnss"]
    out["against_returning_fixes"] = against_fixes(run.out, fixes)
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for k, v in out.items():
            print(f"{k:26s} {v}")


if __name__ == "__main__":
    main()
