"""A 6-axis IMU on a heeled, rolling hull: data/harbour.npz with its IMU records made 6-axis
(:func:`graphnav.sim.heel.heeled`: gravity included, a constant heel plus wave roll and pitch, beacon
bearings in the hull's plane) and isam2 on it, per heel: smoothed / online ATE, NEES, and the roll and
pitch error of the closing estimate (mean over the keyframes, against the simulated hull).

    python benchmarks/heeled_imu.py [--heels 0 5 10 20] [--waves 5] [--attitude-hz 0] [--json]

Figures: docs/smoother.md, "A 6-axis IMU on a heeled hull".
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import factors as F  # noqa: E402
from graphnav.evaluation.metrics import ate, nees_stats  # noqa: E402
from graphnav.graph.navigator import Navigator  # noqa: E402
from graphnav.io.dispatch import load_log  # noqa: E402
from graphnav.sim.heel import heeled, roll_pitch_at  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--log", default=str(Path(__file__).resolve().parents[1] / "data" / "harbour.npz"))
    ap.add_argument("--heels", type=float, nargs="+", default=[0.0, 5.0, 10.0, 20.0], help="[deg]")
    ap.add_argument("--waves", type=float, default=5.0, help="wave roll amplitude [deg] (pitch half of it)")
    ap.add_argument("--attitude-hz", type=float, default=0.0, help="AHRS roll/pitch records (0: none)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    base = load_log(a.log)
    rows = []
    for h in a.heels:
        log = heeled(base, math.radians(h), math.radians(a.waves), seed=0, attitude_hz=a.attitude_hz)
        nav = Navigator.for_log(log)
        for r in log:
            nav.add(r)
        nav.flush()
        res = nav.result()
        t = np.array(nav.builder.kf_t)
        roll, pitch = roll_pitch_at(log, t)
        est = [nav._final.atPose3(F.X(k)).rotation() for k in range(len(t))]
        d_roll = np.degrees([e.roll() - r for e, r in zip(est, roll, strict=True)])
        d_pitch = np.degrees([e.pitch() - p for e, p in zip(est, pitch, strict=True)])
        truth = log.truth()
        rows.append({"heel_deg": h, "waves_deg": a.waves, "attitude_hz": a.attitude_hz,
                     "ate_rmse_m": ate(res.trajectory, truth)["rmse"],
                     "online_ate_rmse_m": ate(res.online, truth)["rmse"],
                     "nees_mean": nees_stats(res.trajectory, truth)["mean"],
                     "online_nees_mean": nees_stats(res.online, truth)["mean"],
                     "roll_error_mean_deg": float(np.mean(d_roll)), "pitch_error_mean_deg": float(np.mean(d_pitch))})
        if not a.json:
            r = rows[-1]
            print(f"heel {h:4.1f} deg: ATE {r['ate_rmse_m']:.3f} / {r['online_ate_rmse_m']:.3f} m, NEES "
                  f"{r['nees_mean']:.2f} / {r['online_nees_mean']:.2f}, roll error "
                  f"{r['roll_error_mean_deg']:+.2f} deg, pitch {r['pitch_error_mean_deg']:+.2f} deg", flush=True)
    if a.json:
        print(json.dumps({"log": a.log, "runs": rows}))


if __name__ == "__main__":
    main()
