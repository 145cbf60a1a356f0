"""Issue #24's runtime targets: ``graphnav run LOG -e isam2`` end to end on harbour logs of growing
length -- CPU seconds, real-time factor, peak RSS, accuracy -- and the runtime exponent between the
shortest and the longest log.

Each log is simulated once (``graphnav simulate harbour --duration D``, default profile: 100 Hz IMU,
10 Hz LiDAR, GNSS + Doppler, compass, speed log, beacons) into ``--dir`` and reused; each run is its
own process (``python -m graphnav run LOG -e E --json``), timed by its own resource usage
(``os.wait4``: user + sys CPU and peak RSS of that process alone), so the figures hold on a loaded
machine where wall time does not. ``--code DIR`` runs another checkout (e.g. an export of an older
commit: ``git archive COMMIT | tar -x -C DIR``) on the same logs, for a before/after table. Numba
compiles its kernels on the first run of a checkout (cached afterwards): ``--warm`` (default) first
runs the shortest log once untimed.

    python benchmarks/runtime_scaling.py --durations 600 7200            # the table + exponent
    python benchmarks/runtime_scaling.py --durations 600 7200 --code /tmp/base --json

Exponent: ``log(cpu_long / cpu_short) / log(span_long / span_short)`` (1.0: linear in log length).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


def simulate(duration: float, out: Path, code: Path, seed: int) -> dict:
    """The harbour log of ``duration`` seconds (made once; its simulate summary kept beside it)."""
    meta = out.with_suffix(".json")
    if out.exists() and meta.exists():
        return json.loads(meta.read_text())
    cmd = [PYTHON, "-m", "graphnav", "simulate", "harbour", "--duration", f"{duration:g}", "--seed", str(seed),
           "--out", str(out), "--overwrite", "--json"]
    res = subprocess.run(cmd, check=True, capture_output=True, text=True, env=_env(code), cwd=_in(code))
    meta.write_text(res.stdout)
    return json.loads(res.stdout)


def _env(code: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(code)}


def _in(code: Path) -> str:
    """The directory each process runs in: ``code`` itself. ``python -m graphnav`` puts its working directory
    first on ``sys.path``, ahead of ``PYTHONPATH``: started inside another checkout it ran that one's code."""
    return str(Path(code).resolve())


def run(log: Path, estimator: str, options: list[str], code: Path) -> dict:
    """One ``graphnav run`` process: its JSON summary plus ``cpu_s``, ``wall_s`` and ``rss_mb``."""
    cmd = [PYTHON, "-m", "graphnav", "run", str(log), "-e", estimator, "--json"]
    for o in options:
        cmd += ["-O", o]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        w0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=err, env=_env(code), cwd=_in(code))
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - w0
        p.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if p.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}): {err.read().decode()[-2000:]}")
        summary = json.loads(out.read().decode())
    summary.update(cpu_s=ru.ru_utime + ru.ru_stime, wall_s=wall, rss_mb=ru.ru_maxrss / 1024)
    return summary


def exponent(a: float, b: float, sa: float, sb: float) -> float:
    return math.log(b / a) / math.log(sb / sa)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--durations", type=float, nargs="+", default=[600.0, 7200.0], help="log lengths [s]")
    ap.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "graphnav-scaling",
                    help="where the simulated logs are kept (reused)")
    ap.add_argument("--code", type=Path, default=REPO, help="the checkout to run (default: this one)")
    ap.add_argument("-e", "--estimator", default="isam2")
    ap.add_argument("-O", dest="options", action="append", default=[], help="estimator option key=value")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-warm", dest="warm", action="store_false", help="no untimed first run")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args(argv)
    args.dir, args.code = args.dir.resolve(), args.code.resolve()  # (the processes run in --code)
    args.dir.mkdir(parents=True, exist_ok=True)
    logs = []
    for d in sorted(args.durations):
        path = args.dir / f"harbour-{d:g}s-seed{args.seed}.npz"
        sim = simulate(d, path, REPO, args.seed)
        logs.append((d, path, sum(v for k, v in sim["records"].items() if k != "beacon_known")))
    if args.warm:
        run(logs[0][1], args.estimator, args.options, args.code)
    rows = []
    for d, path, n in logs:
        s = run(path, args.estimator, args.options, args.code)
        rows.append({"duration_s": d, "records": n, "keyframes": s.get("steps"), "cpu_s": s["cpu_s"],
                     "x_real_time_cpu": d / s["cpu_s"], "wall_s": s["wall_s"], "rss_mb": s["rss_mb"],
                     "ate_rmse_m": s.get("ate_rmse_m"), "online_ate_rmse_m": s.get("online_ate_rmse_m"),
                     "nees_mean": s.get("nees_mean"), "online_nees_mean": s.get("online_nees_mean"),
                     "loop_closures": s.get("loop_closures"), "step_ms_median": s.get("step_ms_median")})
        if not args.json:
            print(json.dumps(rows[-1]), file=sys.stderr)
    res: dict = {"estimator": args.estimator, "options": args.options, "code": str(args.code), "runs": rows,
                 "load": os.getloadavg()[0]}
    if len(rows) > 1:
        a, b = rows[0], rows[-1]
        res["exponent_cpu"] = exponent(a["cpu_s"], b["cpu_s"], a["duration_s"], b["duration_s"])
        res["exponent_rss"] = exponent(a["rss_mb"], b["rss_mb"], a["duration_s"], b["duration_s"])
    if args.json:
        print(json.dumps(res))
        return 0
    print("| log [s] | records | keyframes | CPU s | x real time (CPU) | wall s | peak RSS MB | ATE / online [m] "
          "| NEES / online |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['duration_s']:g} | {r['records']} | {r['keyframes']} | {r['cpu_s']:.1f} | "
              f"{r['x_real_time_cpu']:.0f}x | {r['wall_s']:.0f} | {r['rss_mb']:.0f} | "
              f"{r['ate_rmse_m']:.3f} / {r['online_ate_rmse_m']:.3f} | "
              f"{r['nees_mean']:.2f} / {r['online_nees_mean']:.2f} |")
    if "exponent_cpu" in res:
        print(f"exponent: CPU {res['exponent_cpu']:.2f}, peak RSS {res['exponent_rss']:.2f} "
              f"(load average {res['load']:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
