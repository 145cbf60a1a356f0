"""The beacon paper's Table 1 (Marchel, Naus & Specht 2019) beside ours, with wall times.

    python benchmarks/beacon_search.py [--workers 2] [--chunk 512] [--variants]

Runs the three exhaustive EKF searches (1, 2, 4 beacons; 20,400 layouts) through the Dask sweep
runner on one LocalCluster (its start-up is timed separately), then prints Table 1 beside the
paper's. ``--variants`` adds the modelling-choice study of docs/beacon-layout.md (each choice
the paper leaves open, one at a time; slower).
"""

from __future__ import annotations

import argparse
import logging
import os
import time

import numpy as np

from graphnav.beacon_layout import (
    PAPER_TABLE1,
    Choices,
    Fairway,
    chunk_tasks,
    grid,
    score_chunk,
    summarize_search,
)
from graphnav.sweep import run_sweep


def timed_score_chunk(task: dict) -> dict:
    """score_chunk plus the worker's CPU time for it (the machine may be shared: wall != CPU)."""
    c0 = time.process_time()
    out = score_chunk(task)
    return {**out, "cpu_s": time.process_time() - c0}


def search(client, beacons: int, ch: Choices, chunk: int,
           fw: Fairway | None = None) -> tuple[dict, float, float]:
    fw = fw or Fairway()
    layouts = grid(beacons)
    t0 = time.perf_counter()
    res = run_sweep(timed_score_chunk, chunk_tasks(layouts, chunk, fw, ch), scheduler=client, progress=False)
    wall = time.perf_counter() - t0
    scores = np.concatenate([np.asarray(r["scores"]) for r in res])
    return summarize_search(layouts, scores), wall, sum(r["cpu_s"] for r in res)


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
    ("W second column dg/dtheta as printed", {"w_second": "theta"}),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=512)
    ap.add_argument("--variants", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                           dashboard_address=":0", silence_logs=logging.WARNING)
    client = Client(cluster)
    client.run(lambda: __import__("graphnav.beacon_layout"))  # warm the workers' imports
    startup = time.perf_counter() - t0
    try:
        rows, walls, cpus = {}, {}, {}
        for b in (1, 2, 4):
            rows[b], walls[b], cpus[b] = search(client, b, Choices(), args.chunk)
        total = sum(walls.values())
        print("Table 1 (EKF-SLAM linearised on the true track, P0 eq. 14 with zero cross terms)")
        print(table(rows))
        print()
        print(f"{'search':10s}{'configs':>9s}{'wall [s]':>10s}{'configs/s':>11s}{'CPU [s]':>10s}"
              f"{'configs/CPU-s':>15s}")
        for b in rows:
            n = rows[b]["configs"]
            print(f"{b:>2d} beacon{'s' if b > 1 else ' '}{n:9d}{walls[b]:10.2f}{n / walls[b]:11.0f}"
                  f"{cpus[b]:10.2f}{n / cpus[b]:15.0f}")
        n = sum(r["configs"] for r in rows.values())
        cpu = sum(cpus.values())
        print(f"{'all':10s}{n:9d}{total:10.2f}{n / total:11.0f}{cpu:10.2f}{n / cpu:15.0f}")
        print(f"({args.workers} workers; cluster start-up {startup:.2f} s not included; "
              "CPU = sum over workers. "
              f"On {args.workers} idle cores the wall time would be about CPU / {args.workers} = "
              f"{cpu / args.workers:.1f} s. Load average now: {os.getloadavg()[0]:.1f})")
        if args.variants:
            print("\nModelling choices, one at a time: min / max / mean-over-configurations of mean M_xy [m]")
            print(f"{'variant':58s}" + "".join(f"{'i=' + str(b):>20s}" for b in (1, 2, 4)))
            for label, kw in VARIANTS:
                cells = []
                for b in (1, 2, 4):
                    s, _, _ = search(client, b, Choices(**kw), args.chunk)
                    cells.append(f"{s['best']['mean_mxy']:6.2f}/{s['worst_mean_mxy']:6.2f}/"
                                 f"{s['mean_over_configs_mxy']:6.2f}")
                print(f"{label:58s}" + "".join(f"{c:>20s}" for c in cells), flush=True)
            print(f"{'paper Table 1':58s}" + "".join(
                f"{PAPER_TABLE1[b]['min']:6.2f}/{PAPER_TABLE1[b]['max']:6.2f}/{PAPER_TABLE1[b]['mean']:6.2f}"
                .rjust(20) for b in (1, 2, 4)))
    finally:
        client.close()
        cluster.close()


if __name__ == "__main__":
    main()
