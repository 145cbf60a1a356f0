"""CPU seconds of the parts of ``graphnav run LOG -e ESTIMATOR`` in one process (``time.process_time``, no
profiler): imports, reading the log, the estimator's start, the records' bookkeeping (the record loop without
the keyframe steps), the steps, the closing step.

    python benchmarks/run_parts.py data/harbour.npz [isam2]

Run it alternately on two checkouts (``cd A && PYTHONPATH=$PWD python .../run_parts.py LOG``) to compare a
part whose change is smaller than the spread of the whole command on a loaded machine (docs/performance.md).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

_pt = time.process_time
_t0 = _pt()
import graphnav.evaluation.evaluate  # noqa: E402, F401  (what the run command imports before reading)
import graphnav.graph.navigator  # noqa: E402, F401
from graphnav import estimators  # noqa: E402
from graphnav.io import load_log  # noqa: E402


def main() -> int:
    if len(sys.argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    name = sys.argv[2] if len(sys.argv) > 2 else "isam2"
    t1 = _pt()
    log = load_log(sys.argv[1])
    t2 = _pt()
    est = estimators.get(name)(log)
    t3 = _pt()
    steps = [0.0]
    nav = getattr(est, "nav", None)
    if nav is not None:  # the graph's keyframe steps, timed apart from the records' bookkeeping
        step = nav._step

        def timed(k: int):  # noqa: ANN202
            s = _pt()
            try:
                return step(k)
            finally:
                steps[0] += _pt() - s

        nav._step = timed
    est.feed(log.records)
    t4 = _pt()
    est.finish()
    t5 = _pt()
    print(f"imports {t1 - _t0:.2f} load {t2 - t1:.3f} start {t3 - t2:.2f} records {t4 - t3 - steps[0]:.3f} "
          f"steps {steps[0]:.2f} finish {t5 - t4:.2f} total {t5 - _t0:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
