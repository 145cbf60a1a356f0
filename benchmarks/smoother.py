"""Smoother benchmark: isam2 / batch / fixed-lag on the harbour and marina-degraded scenarios.

    python benchmarks/smoother.py                    # both scenarios, table on stdout
    python benchmarks/smoother.py --json             # one JSON object
    python benchmarks/smoother.py --tuning           # + iSAM2 relinearisation sweep (harbour slice)

Columns: ATE RMSE smoothed / online [m] (unaligned, log frame), step_ms median (solver per
keyframe), icp_ms median, runtime [s] and the real-time factor (data duration / runtime, scan
matching included), also from the process CPU time (robust to other load on the machine).
For marina-degraded it also runs the same log without the 20 m GNSS jump and reports the
relative change of the smoothed ATE.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav import estimators  # noqa: E402
from graphnav.evaluation.evaluate import summarize  # noqa: E402
from graphnav.io import load_log  # noqa: E402

ESTIMATORS = ("isam2", "batch", "fixed-lag")


def marina_dir() -> Path | None:
    sys.path.insert(0, str(ROOT / "tests"))
    from conftest import find_marina

    return find_marina()


def run_one(name: str, log, **options) -> dict:
    t0, c0 = time.perf_counter(), time.process_time()
    r = estimators.run(name, log, **options)
    rt, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = summarize(name, r, log, runtime_s=rt)
    s["realtime_factor"] = (log.t1 - log.t0) / rt
    s["cpu_s"] = cpu  # process CPU time: what the run costs without other load on the machine
    s["realtime_factor_cpu"] = (log.t1 - log.t0) / cpu
    s["step_cpu_ms_median"] = r.info.get("step_cpu_ms_median", float("nan"))
    s["compass_bias_deg"] = r.info.get("compass_bias_deg")
    s["gnss_rejected"] = r.info.get("gnss_rejected", 0) + r.info.get("gnss_dropped_after_lm", 0)
    return s


def scenarios(seed: int) -> dict:
    out = {"harbour": load_log(ROOT / "data" / "harbour.npz")}
    d = marina_dir()
    if d is not None:
        from graphnav.sim.marina_degraded import simulate_marina_degraded

        out["marina-degraded"] = simulate_marina_degraded(d, seed)
        out["marina-degraded (no jump)"] = simulate_marina_degraded(d, seed, jump_m=0.0)
    else:
        print("marina dataset not found: marina-degraded skipped (set GRAPHNAV_MARINA)", file=sys.stderr)
    return out


def tuning(log) -> list[dict]:
    rows = []
    for thr in (0.01, 0.05, 0.1):
        for skip in (1, 5):
            opts = {
                "relinearize_threshold": thr,
                "relinearize_skip": skip,
                "covariances": False,
                "use_icp": False,
            }
            s = run_one("isam2", log, **opts)
            rows.append(
                {
                    **opts,
                    "ate_rmse_m": s["ate_rmse_m"],
                    "online_ate_rmse_m": s["online_ate_rmse_m"],
                    "step_ms_median": s["step_ms_median"],
                    "runtime_s": s["runtime_s"],
                }
            )
            print(
                f"  thr={thr:<5} skip={skip}: ATE {s['ate_rmse_m']:.3f} online {s['online_ate_rmse_m']:.3f} "
                f"step {s['step_ms_median']:.2f} ms",
                file=sys.stderr,
            )
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1, help="marina-degraded seed")
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--tuning",
        action="store_true",
        help="also sweep iSAM2 relinearisation on a harbour slice (solver only, no ICP)",
    )
    ap.add_argument("-O", "--option", action="append", default=[], help="smoother option KEY=VALUE")
    ap.add_argument("--only", choices=("harbour", "marina-degraded"), help="one scenario only")
    args = ap.parse_args()
    from graphnav.commands._common import parse_options
    from graphnav.io.jsonsafe import jsonable

    opts = parse_options(args.option)
    results: dict = {}
    for scen, log in scenarios(args.seed).items():
        if args.only and not scen.startswith(args.only):
            continue
        for name in ESTIMATORS:
            s = run_one(name, log, **opts)
            results.setdefault(scen, {})[name] = s
            print(f"{scen:26s} {name:9s} done ({s['runtime_s']:.1f} s)", file=sys.stderr)
    if "marina-degraded (no jump)" in results:
        results["jump_effect"] = {
            n: (
                results["marina-degraded"][n]["ate_rmse_m"]
                / results["marina-degraded (no jump)"][n]["ate_rmse_m"]
                - 1
            )
            for n in ESTIMATORS
        }
    if args.tuning:
        results["tuning_harbour_0_300s"] = tuning(load_log(ROOT / "data" / "harbour.npz").sliced(0, 300))
    if args.json:
        print(json.dumps(jsonable(results)))
        return 0
    head = (
        f"{'scenario':26s} {'estimator':9s} {'ATE m':>7s} {'online m':>8s} {'step ms':>8s} {'icp ms':>7s} "
        f"{'runtime s':>9s} {'x RT':>6s} {'cpu s':>6s} {'x RT cpu':>8s} {'step cpu ms':>11s} "
        f"{'bias deg':>8s} {'GNSS rej':>8s}"
    )
    print(head)
    print("-" * len(head))
    for scen, per in results.items():
        if scen in ("jump_effect",) or scen.startswith("tuning"):
            continue
        for name, s in per.items():
            on = s.get("online_ate_rmse_m")
            bias = s.get("compass_bias_deg")
            print(
                f"{scen:26s} {name:9s} {s['ate_rmse_m']:7.3f} {on if on is not None else float('nan'):8.3f} "
                f"{s['step_ms_median']:8.2f} {s['icp_ms_median']:7.1f} {s['runtime_s']:9.1f} "
                f"{s['realtime_factor']:6.0f} {s['cpu_s']:6.1f} {s['realtime_factor_cpu']:8.0f} "
                f"{s['step_cpu_ms_median']:11.2f} {bias if bias is not None else float('nan'):8.2f} "
                f"{s['gnss_rejected']:8d}"
            )
    if "jump_effect" in results:
        print(
            "smoothed ATE change from the 20 m jump: "
            + ", ".join(f"{n} {100 * v:+.1f} %" for n, v in results["jump_effect"].items())
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
