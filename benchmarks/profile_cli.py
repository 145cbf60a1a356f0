"""cProfile one graphnav CLI command with a CPU-time timer (fair on a shared, loaded machine).

    python benchmarks/profile_cli.py OUT.prof -- run data/harbour.npz -e isam2 --json

Prints ``cpu``, ``wall`` and the peak RSS on stderr and writes the profile to OUT.prof (read it with
``python -m pstats OUT.prof`` or ``pstats.Stats(OUT).sort_stats("cumulative").print_stats(40)``).
Only this process is profiled (not compare's worker processes nor Dask workers).
"""

from __future__ import annotations

import cProfile
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from graphnav import cli  # noqa: E402


def main() -> int:
    if len(sys.argv) < 4 or sys.argv[2] != "--":
        print(__doc__, file=sys.stderr)
        return 2
    out, args = sys.argv[1], sys.argv[3:]
    prof = cProfile.Profile(time.process_time)
    c0, w0 = time.process_time(), time.perf_counter()
    prof.enable()
    try:
        rc = cli.main(args)
    finally:
        prof.disable()
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"cpu {time.process_time() - c0:.2f} s wall {time.perf_counter() - w0:.2f} s maxrss {rss:.0f} MB",
              file=sys.stderr)
        prof.dump_stats(out)
    return rc


if __name__ == "__main__":
    sys.exit(main())
