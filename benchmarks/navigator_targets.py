"""Issue #12's graph targets, measured: dead reckoning, ``isam2`` and ``batch`` on converted real logs.

For every log: dead-reckoning ATE and RPE1; isam2 smoothed ATE, SE(2)-aligned ATE, online ATE, RPE1,
step median and the time of its closing LM step (``converge_ms``); batch ATE; and the checks
``isam2 <= DR``, ``RPE1 <= 0.8 DR``, ``|isam2 - batch| <= 2 % (or 0.02 m)``. Means per group of
logs at the end. The logs are the converted ones of issue #12 (never in the repository)::

    graphnav convert carmen LOG.gz --out c.jsonl.gz
    graphnav simulate degrade c.jsonl.gz --odometry-noise 0.05,0.05,0.5 --seed 0 --out carmen-NAME.jsonl.gz
    graphnav convert mrclam DIR --robot N --out mrclam6-rN.jsonl.gz

Usage: ``python benchmarks/navigator_targets.py LOG... [--json] [-O key=value ...]``
(e.g. ``/work/cache/logs/carmen-*.jsonl.gz data/harbour.npz``).
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


def measure(path: Path, options: dict, batch: bool = True) -> dict:
    log = load_log(path)
    out: dict = {"log": path.name.split(".")[0]}
    for name in ("dead-reckoning", "isam2", "batch") if batch else ("dead-reckoning", "isam2"):
        if estimators.get(name).unmet(log):
            continue
        t0 = time.perf_counter()
        r = estimators.run(name, log, **({} if name == "dead-reckoning" else options))
        s = summarize(name, r, log, runtime_s=time.perf_counter() - t0)
        out[name] = {k: s.get(k) for k in ("ate_rmse_m", "ate_aligned_rmse_m", "online_ate_rmse_m", "rpe_rmse_m",
                                            "step_ms_median", "runtime_s")}
        out[name]["converge_ms"] = r.info.get("converge_ms")
        for key in ("switched_off", "odometry_consistency", "loop_closures"):
            if key in r.info:
                out[name][key] = r.info[key]
    dr, isam, batch = out.get("dead-reckoning"), out.get("isam2"), out.get("batch")
    if isam and batch:
        diff = abs(isam["ate_rmse_m"] - batch["ate_rmse_m"])
        out["isam2_vs_batch"] = diff / batch["ate_rmse_m"]
        out["isam2_equals_batch"] = diff <= max(0.02 * batch["ate_rmse_m"], 0.02)
    if isam and dr:
        out["ate_ratio"] = isam["ate_rmse_m"] / dr["ate_rmse_m"]
        out["rpe1_ratio"] = isam["rpe_rmse_m"] / dr["rpe_rmse_m"]
    return out


def table(rows: list[dict]) -> str:
    f = lambda v, p=3: "—" if v is None else f"{v:.{p}f}"  # noqa: E731
    head = ("| log | DR ATE | isam2 ATE | aligned | online | ATE / DR | RPE1 / DR | batch ATE | isam2 vs batch "
            "| step ms | converge ms |\n|---|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        dr, i, b = r.get("dead-reckoning", {}), r.get("isam2", {}), r.get("batch", {})
        lines.append(f"| {r['log']} | {f(dr.get('ate_rmse_m'))} | {f(i.get('ate_rmse_m'))} | "
                     f"{f(i.get('ate_aligned_rmse_m'))} | {f(i.get('online_ate_rmse_m'))} | "
                     f"{f(r.get('ate_ratio'), 2)} | {f(r.get('rpe1_ratio'), 2)} | {f(b.get('ate_rmse_m'))} | "
                     f"{f(100 * r['isam2_vs_batch'], 1) + ' %' if 'isam2_vs_batch' in r else '—'} | "
                     f"{f(i.get('step_ms_median'), 2)} | {f(i.get('converge_ms'), 0)} |")
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(r["log"].split("-")[0], []).append(r)
    def mean(rs: list[dict], est: str, key: str) -> float | None:
        v = [r[est][key] for r in rs if est in r and r[est].get(key) is not None]
        return float(np.mean(v)) if v else None

    for g, rs in groups.items():
        lines.append(f"| **mean {g}** ({len(rs)}) | {f(mean(rs, 'dead-reckoning', 'ate_rmse_m'))} | "
                     f"{f(mean(rs, 'isam2', 'ate_rmse_m'))} | {f(mean(rs, 'isam2', 'ate_aligned_rmse_m'))} | "
                     f"{f(mean(rs, 'isam2', 'online_ate_rmse_m'))} | | | {f(mean(rs, 'batch', 'ate_rmse_m'))} | | "
                     f"{f(mean(rs, 'isam2', 'step_ms_median'), 2)} | |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", type=Path)
    ap.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-batch", action="store_true", help="dead reckoning and isam2 only")
    args = ap.parse_args(argv)
    from graphnav.commands._common import parse_options

    options = parse_options(args.option)
    rows = []
    for p in args.logs:
        rows.append(measure(p, options, batch=not args.no_batch))
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)  # progress: one JSON line per log
    if args.json:
        print(json.dumps({"options": options, "rows": rows}))
    else:
        print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
