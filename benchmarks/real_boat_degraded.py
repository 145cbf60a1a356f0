"""A real boat's log scored against its own fixes: the fixes become the reference, a degraded copy of
them (2.5 m at 1 Hz, a 60 s outage, a 10 s 20 m jump: ``graphnav.sim.degrade``) replaces them, and the
boat's own heading, SOG/COG and water speed stay. Prints, per seed, the degraded fixes linearly
interpolated against the reference (what a user has without an estimator) and each estimator (``-e``,
default isam2; the graph's with each set of options): smoothed ATE (and its ratio to the fixes'), online
ATE, NEES, the fixes rejected online and switched off at the end. The reference is a receiver's fixes:
the figures are upper bounds, and a second NEES adds the reference's own rounding (:func:`rounding_sigma`)
to the covariance (a lower bound on its noise).

    python benchmarks/real_boat_degraded.py ../shared/data/marine/anemomind/psaros33-20140627-0006.nmea.gz \\
        --start 0.3 --duration 900 -O '{}' -O '{"motion": "odometry"}'

(``--lenient`` for psaros33-20140627-0004: a GPS time 59 s back.)

Figures: docs/smoother.md, "A real boat's instruments" and "Where the NEES came from".
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from graphnav import estimators  # noqa: E402
from graphnav.evaluation.metrics import ate  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import Gnss, NavLog, Truth  # noqa: E402
from graphnav.sim.degrade import DegradeConfig, Window, degrade  # noqa: E402


def reference_log(path: str, start: float, duration: float, lenient: bool = False) -> NavLog:
    """``duration`` s of the log from ``start`` (a fraction of its fixes): its fixes as truth (the heading
    interpolated from its compass), every other record kept. ``lenient``: skip bad sentences (psaros33-20140627-0004
    has an RMC/GLL time 59 s back)."""
    log = load_log(path, lenient=lenient)
    t = np.array([r.t for r in log.of("gnss")])
    t0 = float(t[int(len(t) * start)])
    sl = log.sliced(t0, t0 + duration)
    hd = sl.of("heading")
    if not hd:
        raise SystemExit(f"{path}: no heading records in the slice")
    ht, hy = np.array([h.t for h in hd]), np.unwrap(np.array([h.yaw for h in hd]))
    truth = [Truth(r.t, r.x, r.y, float(np.interp(r.t, ht, hy))) for r in sl.of("gnss")]
    return NavLog.from_unsorted([r for r in sl if not isinstance(r, Gnss)] + truth, meta=dict(sl.meta))


def rounding_sigma(xy: np.ndarray) -> np.ndarray:
    """Per axis, the 1-sigma [m] of the rounding of the reference's positions: ``step / sqrt(12)``, ``step`` the
    smallest change between consecutive positions above 1 cm (an NMEA position in thousandths of a minute:
    1.85 m north, 1.85 cos(lat) m east); unrounded positions give a few mm."""
    out = []
    for d in np.abs(np.diff(xy, axis=0)).T:
        d = d[d > 0.01]
        out.append(float(d.min()) / np.sqrt(12.0) if d.size else 0.0)
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log")
    ap.add_argument("--start", type=float, default=0.3, help="where the slice starts (fraction of the fixes)")
    ap.add_argument("--duration", type=float, default=900.0, help="[s]")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("-O", dest="options", action="append", default=None,
                    help="options of the graph estimators as JSON (repeatable)")
    ap.add_argument("-e", dest="estimators", default="isam2",
                    help="estimators, comma-separated (the -O sets apply to isam2, batch and fixed-lag)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--lenient", action="store_true", help="skip bad sentences of the log")
    a = ap.parse_args()
    base = reference_log(a.log, a.start, a.duration, a.lenient)
    ref_cov = np.diag(rounding_sigma(base.truth().poses[:, :2]) ** 2)  # the reference's own rounding
    cfg = DegradeConfig(gnss_sigma=2.5, gnss_hz=1.0, outages=(Window((0.3, 0.5), 60.0),),
                        jumps=(Window((0.6, 0.8), 10.0, 20.0),))
    rows = []
    for seed in range(a.seeds):
        dl = degrade(base, cfg, seed=seed)
        ref = dl.truth()
        fx = dl.of("gnss")
        ft, fxy = np.array([f.t for f in fx]), np.array([[f.x, f.y] for f in fx])
        m = (ref.t >= ft[0]) & (ref.t <= ft[-1])
        interp = np.c_[np.interp(ref.t[m], ft, fxy[:, 0]), np.interp(ref.t[m], ft, fxy[:, 1])]
        row = {"seed": seed, "fixes_interpolated_m": float(np.sqrt(np.mean(np.sum((interp - ref.poses[m, :2]) ** 2,
                                                                                 axis=1)))), "runs": []}
        sets = [json.loads(o) for o in (a.options or ["{}"])]
        for name, opts in [(e, o) for e in a.estimators.split(",")
                           for o in (sets if e in ("isam2", "batch", "fixed-lag") else [{}])]:
            r = estimators.run(name, dl, **opts)
            err = r.trajectory.poses[:, :2] - ref.interpolate(r.trajectory.t)[:, :2]
            cov = r.trajectory.cov[:, :2, :2]
            nees = float(np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err).mean())
            nees_ref = float(np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov + ref_cov), err).mean())
            state = r.info.get("state", r.info.get("motion"))
            row["runs"].append({"estimator": name, "options": opts, "state": state,
                                "ate_m": ate(r.trajectory, ref)["rmse"],
                                "online_ate_m": None if r.online is None else ate(r.online, ref)["rmse"],
                                "nees_mean": nees,
                                "nees_with_reference_rounding": nees_ref,
                                "gnss_rejected": r.info.get("gnss_rejected"),
                                "switched_off": r.info.get("switched_off", {}).get("switched_off")})
        rows.append(row)
    if a.json:
        print(json.dumps({"log": a.log, "start": a.start, "duration_s": a.duration,
                          "reference_rounding_sigma_m": np.sqrt(np.diag(ref_cov)).tolist(), "seeds": rows}))
        return
    for row in rows:
        parts = [f"seed {row['seed']}: fixes interpolated {row['fixes_interpolated_m']:.2f} m"]
        for run in row["runs"]:
            parts.append(f"{run['estimator']} {run['options'] or ''} ({run['state']}): {run['ate_m']:.2f} m "
                         f"({run['ate_m'] / row['fixes_interpolated_m']:.2f}x), online "
                         f"{'-' if run['online_ate_m'] is None else format(run['online_ate_m'], '.2f')}, "
                         f"NEES {run['nees_mean']:.2f} ({run['nees_with_reference_rounding']:.2f} with the "
                         f"reference's rounding), rejected {run['gnss_rejected']}")
        print(" | ".join(parts))
    print(f"reference rounding sigma (x, y): {np.sqrt(ref_cov[0, 0]):.2f}, {np.sqrt(ref_cov[1, 1]):.2f} m")


if __name__ == "__main__":
    main()
