"""The sensors a USV really carries (issue 21): the one graph on the harbour without an odometer.

Prints one table (or with ``--json`` one object) of the issue's targets:

* the robot-style harbour (``--profile legacy``: data/harbour.npz before issue 21, 1 Hz IMU) with
  odometry and beacons dropped, with and without the LiDAR (the LiDAR must pay for itself: at least
  2x better with it);
* the default harbour of ``graphnav simulate harbour`` (seed 0: 100 Hz IMU, GNSS position +
  Doppler velocity, compass with a deviation, 10 Hz 2D LiDAR, a speed log through a tidal
  current, charted beacons, no odometer): isam2 smoothed / online ATE, NEES, SOG and ROT RMSE,
  the largest online error inside the GNSS outage, the water current's RMS error against the
  simulator's, and the real-time factor of the run (wall clock; it depends on the machine's load);
  and on the same log the baselines: icp-dr and scan-to-map (LiDAR + IMU, no GNSS) against the IMU's
  dead reckoning, and every filter's ATE and NEES.

    python benchmarks/usv_sensors.py [--json] [--seed 0] [--duration S] [--skip-old] [--skip-baselines]

Figures: docs/smoother.md, "The USV's sensors in one graph".
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from graphnav import estimators  # noqa: E402
from graphnav.evaluation.evaluate import summarize  # noqa: E402
from graphnav.log import NavLog  # noqa: E402


def _run(name: str, log: NavLog, **options) -> tuple[dict, object]:
    c0 = time.perf_counter()
    res = estimators.run(name, log, **options)
    wall = time.perf_counter() - c0
    s = summarize(name, res, log, runtime_s=wall)
    span = (log.t1 or 0.0) - (log.t0 or 0.0)
    s["real_time_factor"] = span / wall if wall > 0 else None
    return s, res


def _row(s: dict) -> dict:
    keys = ("ate_rmse_m", "online_ate_rmse_m", "nees_mean", "online_nees_mean", "sog_rmse_mps", "rot_rmse_degps",
            "heading_rmse_deg", "real_time_factor")
    return {k: (round(s[k], 4) if isinstance(s.get(k), float) else s.get(k)) for k in keys}


def current_error(info: dict, meta: dict) -> float | None:
    """RMS of |estimated - true| water current [m/s] over the estimate's series."""
    from graphnav.sim.water_current import current_from_meta

    wc = info.get("water_current")
    if not wc or "current" not in meta:
        return None
    ser = np.array(wc["series"], dtype=float)
    true = np.asarray(current_from_meta(meta, ser[:, 0]))[:, :2]
    return float(np.sqrt(np.mean(np.sum((ser[:, 1:3] - true) ** 2, axis=1))))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=None, help="[s] of the new harbour (default: all)")
    ap.add_argument("--skip-old", action="store_true", help="skip the legacy harbour's ablation")
    ap.add_argument("--skip-baselines", action="store_true", help="skip the baselines on the new harbour")
    args = ap.parse_args()
    out: dict = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    if not args.skip_old:
        from graphnav.sim.harbour import HarbourConfig, simulate_harbour

        old = simulate_harbour(0, HarbourConfig.legacy())
        usv = old.without(lambda r: r.kind in ("odometry", "beacon"))
        s_lidar, _ = _run("isam2", usv)
        s_nolidar, _ = _run("isam2", usv.without(lambda r: r.kind == "scan"))
        out["embedded_no_odometry_no_beacons"] = {"isam2": _row(s_lidar), "isam2 without scans": _row(s_nolidar),
                                                  "lidar_gain": s_nolidar["ate_rmse_m"] / s_lidar["ate_rmse_m"]}
    from graphnav.sim.harbour import simulate_harbour

    new = simulate_harbour(args.seed, duration=args.duration)
    s, res = _run("isam2", new)
    row = _row(s)
    ev = s.get("errors_by_event") or {}
    row["outage_online_max_m"] = (ev.get("gnss_outage") or {}).get("online_max_m")
    row["current_rmse_mps"] = current_error(res.info, new.meta)
    out["new_harbour_isam2"] = row
    if not args.skip_baselines:
        base = {}
        for name in ("dead-reckoning", "icp-dr", "scan-to-map", "ekf", "ukf", "ukf-bias", "fuzzy-ukf",
                     "fuzzy-ukf-bias"):
            b, _ = _run(name, new)
            base[name] = _row(b)
        dr = base["dead-reckoning"]["ate_rmse_m"]
        for name in ("icp-dr", "scan-to-map"):
            base[name]["x_imu_dead_reckoning"] = round(base[name]["ate_rmse_m"] / dr, 4)
        out["new_harbour_baselines"] = base
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"# USV sensors in one graph ({out['date']}; python benchmarks/usv_sensors.py)")
    for section, rows in out.items():
        if section == "date":
            continue
        print(f"\n## {section}")
        if isinstance(rows, dict) and all(isinstance(v, dict) for v in rows.values()):
            for name, r in rows.items():
                print(f"{name:24s} " + "  ".join(f"{k}={v}" for k, v in r.items()))
        else:
            print("  ".join(f"{k}={v if not isinstance(v, float) or math.isnan(v) else round(v, 4)}"
                            for k, v in rows.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
