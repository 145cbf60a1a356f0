"""Live mode against an offline run of the same records: the motion model live mode picks without and
with the warm-up (graphnav/online/warmup.py, docs/live.md "The motion model").

    python benchmarks/live_warmup.py LOG [--start S] [--duration 900] [--solver isam2] [--json]

A real boat's log (NMEA 0183 ``.nmea[.gz]`` or an NMEA 2000 text log ``.raw[.gz]``/``.data[.gz]``) is
fed line by line through :class:`graphnav.online.live_runner.LiveRunner` (the live decoders and
clock, no sockets); only the records stamped inside ``[t0 + start, t0 + start + duration]`` reach
the estimator (the decoders see every line before, for their context). Three tracks of online
estimates (every estimate the live sink would publish, coasted ones included):

* **before**: ``make_online(solver)``, the navigator made before any record (motion auto, no IMU
  known: the Pose2 graph) -- live mode before the warm-up;
* **after**: :func:`graphnav.online.warmup.live_estimator` (the warm-up, then ``auto_motion``);
* **offline**: ``Navigator.for_log`` on exactly the records the live run handed over (what
  ``graphnav run -e SOLVER`` does with a log of them, sorted by time: motion and position walk from the
  whole slice), record by record, and the same with the position walk left at its default (``offline-default-walk``).

Reported per track: the distance of its estimates to the offline online track (interpolated at their
times; RMSE, median, max) and of the fixes to it (each fix against the track interpolated at its time;
RMSE, median), and the CPU seconds of the live run (decode + estimate).
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.estimators import make_online  # noqa: E402
from graphnav.graph.imu_chain import ImuConfig  # noqa: E402
from graphnav.graph.navigator import Navigator  # noqa: E402
from graphnav.graph.smoother_config import SmootherConfig  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import ODOMETRY_FROM_ROT, NavLog, Record  # noqa: E402
from graphnav.online.live_runner import LiveRunner  # noqa: E402
from graphnav.online.warmup import live_estimator  # noqa: E402
from graphnav.result import Estimate  # noqa: E402


class Window(LiveRunner):
    """The live loop without sockets: records outside ``[t0, t1]`` do not reach the estimator; every
    record handed over and every estimate emitted is kept."""

    def __init__(self, estimator: Any, origin: tuple[float, float], t0: float, t1: float) -> None:
        super().__init__(["udp://127.0.0.1:9"], estimator, origin=origin, require_checksum=False)
        self.t0, self.t1 = t0, t1
        self.taped: list[Record] = []
        self.out: list[Estimate] = []
        self.past = False
        emit = self.sink.emit

        def keep(est: Estimate, arrival: float | None, frame: Any, kind: str = "") -> None:
            self.out.append(est)
            emit(est, arrival, frame, kind)

        self.sink.emit = keep  # type: ignore[method-assign]

    def _record(self, rec: Record, arrival: float | None) -> None:
        if rec.t > self.t1:
            self.past = True
        if not self.t0 <= rec.t <= self.t1:
            return
        self.taped.append(rec)
        super()._record(rec, arrival)

    def play(self, lines: list[bytes], n2k: bool) -> float:
        """Every line (arrivals 1 s apart: never ahead of the stream), then the end of input; CPU seconds."""
        c0 = time.process_time()
        a0 = time.perf_counter()
        for i, line in enumerate(lines):
            if n2k:
                self.feed_marine("n2k", line, a0 + i)
            else:
                self.feed_sentence(line, a0 + i)
            if self.past:
                break
        est = self.estimator.flush()
        for e in getattr(self.estimator, "replayed_out", ()):
            self.sink.emit(e, None, None)
        if est is not None:
            self.sink.emit(est, None, None)
        return time.process_time() - c0


def track(ests: list[Estimate]) -> np.ndarray:
    a = np.array([[e.t, e.vec[0], e.vec[1]] for e in ests]).reshape(-1, 3)
    return a[np.argsort(a[:, 0], kind="stable")]


def distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b(t_a)|: each row of ``a`` against ``b`` interpolated at its time (inside ``b``'s span)."""
    a = a[(a[:, 0] >= b[0, 0]) & (a[:, 0] <= b[-1, 0])]
    return np.hypot(a[:, 1] - np.interp(a[:, 0], b[:, 0], b[:, 1]), a[:, 2] - np.interp(a[:, 0], b[:, 0], b[:, 2]))


def stats(d: np.ndarray) -> dict[str, float]:
    return {"rmse_m": float(np.sqrt(np.mean(d**2))), "median_m": float(np.median(d)), "max_m": float(np.max(d)),
            "n": int(d.size)}


def offline(records: list[Record], solver: str, live_order: bool = False,
            **kw: Any) -> tuple[list[Estimate], dict[str, Any]]:
    meta = {"odometry": ODOMETRY_FROM_ROT} if any(r.kind == "odometry" for r in records) else {}
    log = NavLog.from_unsorted(records, meta=meta)  # a log is in time order; the live stream may step back
    nav = Navigator.for_log(log, SmootherConfig.from_options({"solver": solver, **kw}))
    out: list[Estimate] = []
    for r in records if live_order else log.records:
        e = nav.add(r)
        out += [*nav.coasted_out, *([e] if e is not None else [])]
    f = nav.flush()
    out += [f] if f is not None else []
    return out, {"motion": nav.cfg.motion, "nav": nav.builder.nav,
                 "position_walk": nav.builder.motion.imu.vessel_walk if nav.builder.motion.imu is not None else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log")
    ap.add_argument("--start", type=float, default=0.0, help="slice start after the log's first record [s]")
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--solver", default="isam2")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    log = load_log(args.log)
    t0 = float(log.t0) + args.start
    t1 = t0 + args.duration
    origin = (log.meta["origin"]["lat"], log.meta["origin"]["lon"])
    opener = gzip.open if args.log.endswith(".gz") else open
    with opener(args.log, "rb") as fh:
        lines = [ln.rstrip(b"\r\n") for ln in fh if ln.strip() and not ln.startswith(b"#")]
    n2k = ".nmea" not in Path(args.log).name
    runs: dict[str, Window] = {}
    cpu: dict[str, float] = {}
    for name, make in (("before", lambda: make_online(args.solver)), ("after", live_estimator(args.solver, {}))):
        w = Window(make(), origin, t0, t1)
        cpu[name] = w.play(lines, n2k)
        runs[name] = w
    taped = runs["after"].taped
    assert [(r.kind, r.t) for r in taped] == [(r.kind, r.t) for r in runs["before"].taped]
    off, off_info = offline(taped, args.solver)
    c0 = time.process_time()
    default_walk = {"vessel_position_walk": ImuConfig().integration_sigma}
    off_default, _ = offline(taped, args.solver, imu=default_walk)
    off_cpu = time.process_time() - c0
    off_live, _ = offline(taped, args.solver, live_order=True, imu=default_walk)
    fixes = np.array([[r.t, r.x, r.y] for r in taped if r.kind == "gnss"])
    ref = track(off)
    rows = {}
    for name, ests in (("before", runs["before"].out), ("after", runs["after"].out), ("offline", off),
                       ("offline-default-walk", off_default), ("offline-default-walk-live-order", off_live)):
        tr = track(ests)
        rows[name] = {"estimates": len(ests), "to_offline": stats(distances(tr, ref)),
                      "fixes_to_track": stats(distances(fixes, tr))}
        if name in cpu:
            rows[name]["cpu_s"] = cpu[name]
    rows["offline-default-walk"]["cpu_s"] = off_cpu
    summary = runs["after"].summary()
    out = {"log": args.log, "slice_s": [args.start, args.duration], "solver": args.solver,
           "records": len(taped), "fixes": len(fixes), "kinds": NavLog.from_unsorted(taped).counts(),
           "motion_after": summary.get("motion"), "motion_reason": summary.get("motion_reason"),
           "warmup": summary.get("warmup"), "position_walk_live": summary.get("position_walk_live"),
           "offline": off_info, "tracks": rows}
    if args.json:
        print(json.dumps(out, indent=1))
        return
    print(f"{args.log} [{args.start:g}, +{args.duration:g}] s, {args.solver}: {len(taped)} records, {len(fixes)} fixes")
    print(f"after: motion {out['motion_after']} ({out['motion_reason']}); warm-up {out['warmup']}")
    print(f"live position walk: {out['position_walk_live']}; offline: {off_info}")
    print("| track | estimates | to offline online RMSE / median / max [m] | fixes to track RMSE / median [m] "
          "| CPU [s] |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        a, f = r["to_offline"], r["fixes_to_track"]
        print(f"| {name} | {r['estimates']} | {a['rmse_m']:.3f} / {a['median_m']:.3f} / {a['max_m']:.3f} | "
              f"{f['rmse_m']:.3f} / {f['median_m']:.3f} | {r.get('cpu_s', math.nan):.2f} |")


if __name__ == "__main__":
    main()
