"""The beacon paper's Table 1 (Marchel, Naus & Specht 2019) beside ours, with wall times.

    python benchmarks/beacon_search.py [--cluster] [--no-cli] [--no-numpy] [--no-compile] [--variants]

Runs the three exhaustive EKF searches (1, 2, 4 beacons; 20,400 layouts) in this process with the
compiled kernel (``backend="auto"``: numba when importable) through the sweep runner, as
``graphnav beacons search`` does by default (``--scheduler auto`` runs these in-process), and
prints Table 1 beside the paper's and the wall / CPU times and configurations per second. Then:
the same with the numpy backend (the speed-up, and the largest score difference between the two);
the three CLI commands as subprocesses (``python -m graphnav beacons search --beacons B --json``,
whose wall includes interpreter start-up and imports); the first numba compilation in a fresh
cache (paid once: ``cache=True``); ``--cluster`` the Dask LocalCluster path (start-up timed
apart); ``--variants`` the modelling-choice study of docs/beacon-layout.md (each choice the paper
leaves open, one at a time; slower).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from graphnav.beacons.layout import (
    PAPER_TABLE1,
    Choices,
    Fairway,
    chunk_tasks,
    grid,
    resolve_backend,
    score_chunk,
    summarize_search,
)
from graphnav.evaluation.sweep import run_sweep

REPO = Path(__file__).resolve().parents[1]


def timed_score_chunk(task: dict) -> dict:
    """score_chunk plus the CPU time for it (the machine may be shared: wall != CPU)."""
    c0 = time.process_time()
    out = score_chunk(task)
    return {**out, "cpu_s": time.process_time() - c0}


def search(beacons: int, ch: Choices, chunk: int, *, backend: str = "auto", scheduler="serial",
           fw: Fairway | None = None) -> tuple[dict, NDArray, float, float]:
    """One exhaustive search through the sweep runner: (summary, scores, wall [s], CPU [s])."""
    fw = fw or Fairway()
    layouts = grid(beacons)
    t0 = time.perf_counter()
    tasks = chunk_tasks(layouts, chunk, fw, ch, extra={"backend": backend})
    res = run_sweep(timed_score_chunk, tasks, scheduler=scheduler, progress=False)
    scores = np.concatenate([np.asarray(r["scores"]) for r in res])
    wall = time.perf_counter() - t0
    return summarize_search(layouts, scores), scores, wall, sum(r["cpu_s"] for r in res)


def timing_table(rows: dict, walls: dict, cpus: dict) -> str:
    lines = [f"{'search':10s}{'configs':>9s}{'wall [s]':>10s}{'configs/s':>11s}{'CPU [s]':>10s}"
             f"{'configs/CPU-s':>15s}"]
    for b in rows:
        n = rows[b]["configs"]
        lines.append(f"{b:>2d} beacon{'s' if b > 1 else ' '}{n:9d}{walls[b]:10.2f}{n / walls[b]:11.0f}"
                     f"{cpus[b]:10.2f}{n / cpus[b]:15.0f}")
    n = sum(r["configs"] for r in rows.values())
    wall, cpu = sum(walls.values()), sum(cpus.values())
    lines.append(f"{'all':10s}{n:9d}{wall:10.2f}{n / wall:11.0f}{cpu:10.2f}{n / cpu:15.0f}")
    return "\n".join(lines)


def load() -> str:
    return "load average {:.1f} {:.1f} {:.1f}".format(*os.getloadavg())


def table(rows: dict[int, dict]) -> str:
    lines = [f"{'':34s}" + "".join(f"{'i=' + str(b) + ' ours':>13s}{'paper':>9s}" for b in rows)]

    def line(label, ours, paper):
        return f"{label:34s}" + "".join(f"{ours(b):13.2f}{paper(b):9.2f}" for b in rows)

    lines.append(line("min mean M_xy [m]", lambda b: rows[b]["best"]["mean_mxy"],
                      lambda b: PAPER_TABLE1[b]["min"]))
    lines.append(line("  its mean M_x [m]", lambda b: rows[b]["best"]["mean_mx"],
                      lambda b: PAPER_TABLE1[b]["min_mx"]))
    lines.append(line("  its mean M_y [m]", lambda b: rows[b]["best"]["mean_my"],
                      lambda b: PAPER_TABLE1[b]["min_my"]))
    lines.append(line("max mean M_xy [m]", lambda b: rows[b]["worst_mean_mxy"],
                      lambda b: PAPER_TABLE1[b]["max"]))
    lines.append(line("mean M_xy over configurations [m]", lambda b: rows[b]["mean_over_configs_mxy"],
                      lambda b: PAPER_TABLE1[b]["mean"]))
    lines.append(line("mean M_x over configurations [m]", lambda b: rows[b]["mean_over_configs_mx"],
                      lambda b: PAPER_TABLE1[b]["mean_mx"]))
    lines.append(line("mean M_y over configurations [m]", lambda b: rows[b]["mean_over_configs_my"],
                      lambda b: PAPER_TABLE1[b]["mean_my"]))
    for b in rows:
        lines.append(f"best layout i={b}: ours {rows[b]['best']['layout']}  "
                     f"paper {PAPER_TABLE1[b]['layout']}")
    return "\n".join(lines)


VARIANTS = [
    ("reference: truth-linearised, P0 cross 0, W dg/dROT", {}),
    ("linearised at the estimate (seed 0), first-sighting init", {"linearize": "estimate"}),
    ("  ... seed 1", {"linearize": "estimate", "seed": 1}),
    ("estimate, beacon mean 0,0 until updated (eq. 15)", {"linearize": "estimate", "beacon_init": "zero"}),
    ("estimate, beacon mean = true position", {"linearize": "estimate", "beacon_init": "truth"}),
    ("P0 beacon 1e12 m^2 (10^6 m as a sigma)", {"p0_beacon": 1e12}),
    ("P0 as printed (1e6 off the vessel block)", {"p0_cross": "paper"}),
    ("  ... the same, numpy backend (ill-conditioned: rounding)", {"p0_cross": "paper", "backend": "numpy"}),
    ("W second column dg/dtheta as printed", {"w_second": "theta"}),
]


def cli_search(beacons: int) -> tuple[dict, float, float]:
    """``python -m graphnav beacons search --beacons B --json`` as a subprocess: (its JSON, the
    process's wall [s], its CPU [s] incl. interpreter start-up and imports)."""
    t0 = time.perf_counter()
    r0 = os.times()
    p = subprocess.run([sys.executable, "-m", "graphnav", "beacons", "search", "--beacons", str(beacons),
                        "--json", "--no-progress"], cwd=REPO, capture_output=True, text=True, check=True)
    r1 = os.times()
    wall = time.perf_counter() - t0
    return json.loads(p.stdout), wall, (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)


_COMPILE = """
import time, numpy as np
c0, t0 = time.process_time(), time.perf_counter()
from graphnav.beacons.layout import propagate
propagate(np.array([[[650.0, 370.0]]]), backend="numba")
print(time.process_time() - c0, time.perf_counter() - t0)
"""


def first_compile() -> tuple[float, float]:
    """CPU and wall seconds of the first compiled call in a fresh numba cache (import + compile)."""
    with tempfile.TemporaryDirectory() as d:
        p = subprocess.run([sys.executable, "-c", _COMPILE], cwd=REPO, capture_output=True, text=True, check=True,
                           env={**os.environ, "NUMBA_CACHE_DIR": d})
    cpu, wall = (float(v) for v in p.stdout.split())
    return cpu, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=512)
    ap.add_argument("--cluster", action="store_true", help="also through a Dask LocalCluster")
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy-backend comparison")
    ap.add_argument("--no-cli", action="store_true", help="skip the CLI subprocess timings")
    ap.add_argument("--no-compile", action="store_true", help="skip the fresh-cache compile timing")
    ap.add_argument("--variants", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    backend = resolve_backend("auto")
    if backend == "numba":
        search(1, Choices(), args.chunk, fw=Fairway(steps=2))  # load the cached kernel (or compile it) first
    print(f"[{load()}]")
    rows, scores, walls, cpus = {}, {}, {}, {}
    for b in (1, 2, 4):
        rows[b], scores[b], walls[b], cpus[b] = search(b, Choices(), args.chunk)
    print("Table 1 (EKF-SLAM linearised on the true track, P0 eq. 14 with zero cross terms)")
    print(table(rows))
    print(f"\nIn this process, backend {backend} (kernel loaded beforehand), sweep runner in-process:")
    print(timing_table(rows, walls, cpus))
    print(f"[{load()}]")
    if not args.no_numpy and backend == "numba":
        nrows, nwalls, ncpus, diff = {}, {}, {}, 0.0
        for b in (1, 2, 4):
            nrows[b], sc, nwalls[b], ncpus[b] = search(b, Choices(), args.chunk, backend="numpy")
            diff = max(diff, float(np.max(np.abs(sc / scores[b] - 1.0))))
            assert nrows[b]["best"]["layout"] == rows[b]["best"]["layout"]
        print("\nThe same with backend numpy (same best layouts; largest relative score difference "
              f"{diff:.1e}):")
        print(timing_table(nrows, nwalls, ncpus))
        print(f"speed-up (CPU): {sum(ncpus.values()) / sum(cpus.values()):.1f}x   [{load()}]")
    if not args.no_cli:
        print("\nCLI: python -m graphnav beacons search --beacons B --json (default --scheduler auto)")
        print(f"{'search':10s}{'configs':>9s}{'wall_s':>9s}{'configs/s':>11s}{'process wall':>14s}"
              f"{'process CPU':>13s}  scheduler/backend")
        tw = tp = tc = 0.0
        for b in (1, 2, 4):
            o, wall, cpu = cli_search(b)
            assert o["best"]["layout"] == rows[b]["best"]["layout"]
            tw, tp, tc = tw + o["wall_s"], tp + wall, tc + cpu
            print(f"{b:>2d} beacon{'s' if b > 1 else ' '}{o['configs']:9d}{o['wall_s']:9.2f}{o['configs_per_s']:11.0f}"
                  f"{wall:14.2f}{cpu:13.2f}  {o['scheduler']}/{o.get('backend')}")
        print(f"{'all':10s}{20400:9d}{tw:9.2f}{20400 / tw:11.0f}{tp:14.2f}{tc:13.2f}   [{load()}]")
    if not args.no_compile and backend == "numba":
        cpu, wall = first_compile()
        print(f"\nFirst numba compilation (fresh cache; import + compile + one call, paid once per "
              f"machine: cache=True): {cpu:.1f} s CPU, {wall:.1f} s wall   [{load()}]")
    if args.cluster:
        from distributed import Client, LocalCluster

        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.WARNING)
        client = Client(cluster)
        client.run(lambda: __import__("graphnav.beacons.layout"))  # warm the workers' imports
        startup = time.perf_counter() - t0
        try:
            crows, cwalls, ccpus = {}, {}, {}
            for b in (1, 2, 4):
                crows[b], _, cwalls[b], ccpus[b] = search(b, Choices(), args.chunk, scheduler=client)
            print(f"\nDask LocalCluster, {args.workers} workers (start-up {startup:.2f} s not included; "
                  "CPU summed over the workers; the first task of each worker loads the kernel):")
            print(timing_table(crows, cwalls, ccpus))
            print(f"[{load()}]")
        finally:
            client.close()
            cluster.close()
    if args.variants:
        print("\nModelling choices, one at a time: min / max / mean-over-configurations of mean M_xy [m]")
        print(f"{'variant':58s}" + "".join(f"{'i=' + str(b):>20s}" for b in (1, 2, 4)))
        for label, kw in VARIANTS:
            cells = []
            kw = dict(kw)
            be = kw.pop("backend", "auto")
            for b in (1, 2, 4):
                s, _, _, _ = search(b, Choices(**kw), args.chunk, backend=be)
                cells.append(f"{s['best']['mean_mxy']:6.2f}/{s['worst_mean_mxy']:6.2f}/"
                             f"{s['mean_over_configs_mxy']:6.2f}")
            print(f"{label:58s}" + "".join(f"{c:>20s}" for c in cells), flush=True)
        print(f"{'paper Table 1':58s}" + "".join(
            f"{PAPER_TABLE1[b]['min']:6.2f}/{PAPER_TABLE1[b]['max']:6.2f}/{PAPER_TABLE1[b]['mean']:6.2f}"
            .rjust(20) for b in (1, 2, 4)))


if __name__ == "__main__":
    main()
