"""CPU seconds of each figure of a compare report (drawing + PNG encoding, one process, no workers).

    python benchmarks/figure_cpu.py COMP.pkl [--out DIR] [--only sog_cog,nees]
    python benchmarks/figure_cpu.py --build data/harbour.npz COMP.pkl    # the pickle, once (~1-2 min)

``COMP.pkl`` is a pickled :class:`graphnav.evaluation.comparison.Comparison` (``--build`` runs
``compare(load_log(LOG), workers=2)`` and pickles it), so the estimators run once and the figures can be
timed with any checkout's plotting code (each checkout's copy of this script times that checkout).
``--out`` writes the PNGs, to compare two checkouts' figures by eye or pixel by pixel. On a shared
machine, alternate the checkouts and compare medians.
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pickle", nargs="+", help="COMP.pkl, or with --build: LOG COMP.pkl")
    ap.add_argument("--build", action="store_true", help="run the comparison on LOG and pickle it")
    ap.add_argument("--out", type=Path, help="write each figure's PNG here")
    ap.add_argument("--only", default="", help="comma-separated figure names (file names without .png)")
    a = ap.parse_args(argv)
    if a.build:
        from graphnav.evaluation.comparison import compare
        from graphnav.io import load_log

        log, dest = a.pickle
        comp = compare(load_log(log), workers=2, log_name=Path(log).stem)
        Path(dest).write_bytes(pickle.dumps(comp))
        return 0
    from graphnav.evaluation.report.figures import figure_jobs, png_bytes

    comp = pickle.loads(Path(a.pickle[0]).read_bytes())
    only = {s for s in a.only.split(",") if s}
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
    total = 0.0
    for fn, args, kw, fname, _ in figure_jobs(comp):
        name = fname.removesuffix(".png")
        if only and name not in only:
            continue
        t0 = time.process_time()
        fig = fn(*args, **kw)
        png = None if fig is None else png_bytes(fig)
        dt = time.process_time() - t0
        total += dt
        if png is not None and a.out:
            (a.out / fname).write_bytes(png)
        print(f"{name:20s} {dt:6.2f}", flush=True)
    print(f"{'total':20s} {total:6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
