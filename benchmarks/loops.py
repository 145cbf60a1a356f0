"""Issue #15's loop-closure targets, measured: ``isam2`` with and without loops (and dead reckoning).

Per log: dead reckoning's ATE; isam2's ATE, aligned ATE and RPE1 with loops (default) and with
``-O loops=false``; loops accepted (``loop_closures``), candidates verified and rejected per stage;
runtime and keyframes, time per keyframe (total and in the loop closer). The checks of #15: median
ATE over the logs <= 1.0 m, each log's ATE <= 0.3 x dead reckoning's, RPE1 with loops <= 1.05 x
without. The logs are the converted CARMEN ones of issue #9 (never in the repository)::

    graphnav convert carmen LOG.gz --out c.jsonl.gz
    graphnav simulate degrade c.jsonl.gz --odometry-noise 0.05,0.05,0.5 --seed 0 --out carmen-NAME.jsonl.gz

Usage: ``python benchmarks/loops.py LOG... [--json] [-O key=value ...]`` (e.g.
``/work/cache/logs/carmen-*.jsonl.gz``).
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
from graphnav.evaluation.evaluate import summarize  # noqa: E402
from graphnav.io import load_log  # noqa: E402

KEYS = ("ate_rmse_m", "ate_aligned_rmse_m", "rpe_rmse_m", "runtime_s")
COUNTS = ("loop_candidates", "loop_verified", "loop_closures", "loop_rejected_match", "loop_rejected_chain",
          "loop_rejected_refine", "loop_unconfirmed", "places", "loop_ms")


def measure(path: Path, options: dict) -> dict:
    log = load_log(path)
    out: dict = {"log": path.name.split(".")[0]}
    r = estimators.run("dead-reckoning", log)
    out["dr"] = summarize("dead-reckoning", r, log, runtime_s=0.0)["ate_rmse_m"]
    for label, extra in (("loops", {}), ("no_loops", {"loops": False})):
        t0 = time.perf_counter()
        r = estimators.run("isam2", log, **{**options, **extra})
        s = summarize("isam2", r, log, runtime_s=time.perf_counter() - t0)
        out[label] = {k: s.get(k) for k in KEYS}
        out[label]["keyframes"] = r.info.get("keyframes")
        if label == "loops":
            out.update({k: r.info.get(k) for k in COUNTS})
    n = out["loops"]["keyframes"] or 1
    out["ms_per_keyframe"] = 1e3 * out["loops"]["runtime_s"] / n
    out["loop_ms_per_keyframe"] = (out.get("loop_ms") or 0.0) / n
    out["ate_ratio_dr"] = out["loops"]["ate_rmse_m"] / out["dr"]
    out["rpe1_ratio"] = out["loops"]["rpe_rmse_m"] / out["no_loops"]["rpe_rmse_m"]
    return out


def table(rows: list[dict]) -> str:
    f = lambda v, p=3: "—" if v is None else f"{v:.{p}f}"  # noqa: E731
    lines = ["| log | keyframes | DR ATE | ATE no loops | ATE loops | aligned | ATE / DR | RPE1 loops / no loops "
             "| accepted | candidates | rejected match / chain / refine / unconfirmed | runtime s | ms / keyframe "
             "| loop ms / keyframe |", "|" + "---|" * 14]
    for r in rows:
        lo, no = r["loops"], r["no_loops"]
        lines.append(f"| {r['log']} | {lo['keyframes']} | {f(r['dr'])} | {f(no['ate_rmse_m'])} | "
                     f"{f(lo['ate_rmse_m'])} | "
                     f"{f(lo['ate_aligned_rmse_m'])} | {f(r['ate_ratio_dr'], 2)} | {f(r['rpe1_ratio'], 3)} | "
                     f"{r['loop_closures']} | {r['loop_candidates']} | {r['loop_rejected_match']} / "
                     f"{r['loop_rejected_chain']} / {r['loop_rejected_refine']} / {r['loop_unconfirmed']} | "
                     f"{f(lo['runtime_s'], 1)} | {f(r['ms_per_keyframe'], 1)} | {f(r['loop_ms_per_keyframe'], 1)} |")
    ate = [r["loops"]["ate_rmse_m"] for r in rows]
    lines.append("")
    met = "met" if np.median(ate) <= 1.0 else "missed"
    lines.append(f"median ATE with loops {np.median(ate):.3f} m (target <= 1.0: {met}); "
                 f"without {np.median([r['no_loops']['ate_rmse_m'] for r in rows]):.3f} m; "
                 f"ATE <= 0.3 x DR on {sum(r['ate_ratio_dr'] <= 0.3 for r in rows)} of {len(rows)}; "
                 f"RPE1 <= 1.05 x without loops on {sum(r['rpe1_ratio'] <= 1.05 for r in rows)} of {len(rows)}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", type=Path)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("-O", dest="options", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args()
    options = {}
    for o in a.options:
        k, _, v = o.partition("=")
        try:
            options[k] = json.loads(v)
        except json.JSONDecodeError:
            options[k] = v
    rows = []
    for p in a.logs:
        rows.append(measure(p, options))
        if not a.json:
            print(json.dumps({k: v for k, v in rows[-1].items()}), file=sys.stderr, flush=True)
    if a.json:
        print(json.dumps(rows))
    else:
        print(table(rows))


if __name__ == "__main__":
    main()
