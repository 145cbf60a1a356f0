"""What iSAM2 costs per keyframe as the log grows: ``ISAM2.update`` and the online estimate (the
newest keyframe's state and marginal), CPU ms averaged over tenths of the run, with the variables
re-eliminated and relinearised per update (``ISAM2Result``).

    python benchmarks/isam2_growth.py LOG [--calculate-estimate] [-O key=value ...]

``--calculate-estimate`` reads the newest state with ``ISAM2.calculateEstimate`` (the whole-tree
wildfire back-substitution, the code before issue #24's change) instead of its marginal factor.
Prints one row per tenth of the keyframes; ``--json`` one object with the rows.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from graphnav import estimators  # noqa: E402
from graphnav.graph import solver as S  # noqa: E402
from graphnav.io import load_log  # noqa: E402


def _value(v: str):  # noqa: ANN202
    try:
        return json.loads(v)
    except ValueError:
        return v


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log")
    ap.add_argument("--calculate-estimate", action="store_true", help="the newest state by calculateEstimate")
    ap.add_argument("-O", dest="options", action="append", default=[], help="isam2 option key=value")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows: list[list[float]] = []
    update, estimate = S.Solver.update, S.Solver.estimate

    def timed_update(self, graph, values, *a, **k):  # noqa: ANN001, ANN202
        if self.kind != "isam2":
            return update(self, graph, values, *a, **k)
        c = time.process_time()
        if self.keep:
            self.graph.push_back(graph)
            self.initial.insert(values)
        r = self.s.update(graph, values)
        self._fresh = set() if args.calculate_estimate else set(values.keys())
        self._marginals = {}
        self.updates += 1
        rows.append([self.updates, (time.process_time() - c) * 1e3, 0.0, r.getVariablesReeliminated(),
                     r.getVariablesRelinearized()])
        return None

    def timed_estimate(self, key, type_name="Pose2"):  # noqa: ANN001, ANN202
        c = time.process_time()
        v = estimate(self, key, type_name)
        if rows:
            rows[-1][2] += (time.process_time() - c) * 1e3
        return v

    S.Solver.update, S.Solver.estimate = timed_update, timed_estimate
    options = {k: _value(v) for k, v in (o.split("=", 1) for o in args.options)}
    log = load_log(args.log)
    c = time.process_time()
    res = estimators.run("isam2", log, **options)
    cpu = time.process_time() - c
    a = np.array(rows)
    w = max(len(a) // 10, 1)
    out = []
    for i in range(0, len(a), w):
        b = a[i:i + w]
        out.append({"from_keyframe": int(b[0, 0]), "update_ms": float(b[:, 1].mean()),
                    "estimate_ms": float(b[:, 2].mean()), "reeliminated": float(b[:, 3].mean()),
                    "relinearized": float(b[:, 4].mean())})
    summary = {"log": args.log, "calculate_estimate": args.calculate_estimate, "cpu_s": cpu,
               "keyframes": len(a), "windows": out, "info_final_ms": res.info.get("final_ms")}
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{args.log}: {len(a)} keyframes, {cpu:.1f} s CPU (estimator only)")
    print("| from keyframe | update ms | estimate ms | re-eliminated | relinearised |")
    print("|---|---|---|---|---|")
    for r in out:
        print(f"| {r['from_keyframe']} | {r['update_ms']:.2f} | {r['estimate_ms']:.2f} | {r['reeliminated']:.0f} | "
              f"{r['relinearized']:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
