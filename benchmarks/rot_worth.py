"""What a rate of turn is worth to the vessel model: the Furuno NMEA 2000 logs (a satellite compass's heading
at 10 Hz and rate of turn, 127251) with the heading thinned to one record every 1 s or 5 s, with and without
the ROT (``imu.vessel_rot``, the EKF's ``vessel_rot``).

    python benchmarks/rot_worth.py [--json] [--data ../shared/data/marine] [-e isam2|ekf] [--every 1,5]

Each run is scored by its yaw [deg] (RMS, 95th percentile, max) against the full-heading track of the same
estimator without the ROT (at that track's times) and against the heading records it was not given (the
satellite compass's 10 Hz heading, 0.5 deg; every record for the full-heading runs), and by the track's median
distance to the log's own fixes [m] (benchmarks/marine_n2k.py's ``median_distance``). The graph's compass
bias estimate [deg] is listed: the track's yaw is the heading less it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from marine_n2k import median_distance  # noqa: E402

from graphnav import estimators  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import NavLog  # noqa: E402


def thin_headings(log: NavLog, every: float) -> NavLog:
    """``log`` with one heading record kept every ``every`` seconds (the first at or after each step)."""
    out, next_t = [], -math.inf
    for r in log.records:
        if r.kind == "heading":
            if r.t < next_t:
                continue
            next_t = r.t + every - 1e-6
        out.append(r)
    return NavLog(out, meta=log.meta, beacons_known=log.beacons_known)


def track(log: NavLog, name: str, rot: bool) -> tuple[np.ndarray, float | None]:
    """``t, x, y, yaw`` of ``name``'s track (``rot``: with the ROT) and its compass bias estimate [deg]."""
    opts = {"imu": {"vessel_rot": rot}} if name == "isam2" else {"vessel_rot": rot}
    res = estimators.run(name, log, **opts)
    tr = res.trajectory
    return np.c_[tr.t, tr.poses[:, :3]], res.info.get("compass_bias_deg")


def yaw_diff(a: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    """[deg] ``a``'s yaw against ``ref``'s (``t`` first, ``yaw`` last column) at ``ref``'s times inside ``a``."""
    ref = ref[(ref[:, 0] >= a[0, 0]) & (ref[:, 0] <= a[-1, 0])]
    ya = np.interp(ref[:, 0], a[:, 0], np.unwrap(a[:, 3]))
    d = np.degrees(np.abs(np.remainder(ya - ref[:, -1] + math.pi, 2 * math.pi) - math.pi))
    return {"rms": float(np.sqrt(np.mean(d**2))), "p95": float(np.percentile(d, 95)), "max": float(d.max())}


def scores(tr: np.ndarray, bias: float | None, ref: np.ndarray, headings: np.ndarray, fixes: np.ndarray) -> dict:
    return {"yaw_vs_full_deg": yaw_diff(tr, ref), "yaw_vs_headings_deg": yaw_diff(tr, headings),
            "compass_bias_deg": bias, "to_fixes_m": median_distance(tr[:, :3], fixes)}


def study(path: Path, name: str, everies: list[float]) -> dict:
    log = load_log(path)
    fixes = np.array([[r.t, r.x, r.y] for r in log.of("gnss")]).reshape(-1, 3)
    heads = np.array([[r.t, r.yaw] for r in log.of("heading")])
    ref, bias = track(log, name, rot=False)
    out: dict = {"headings": len(log.of("heading")), "rot_records": len(log.of("odometry"))}
    out["full_no_rot"] = scores(ref, bias, ref, heads, fixes)
    out["full_rot"] = scores(*track(log, name, rot=True), ref, heads, fixes)
    for every in everies:
        thin = thin_headings(log, every)
        kept = {r.t for r in thin.of("heading")}
        held_out = heads[[t not in kept for t in heads[:, 0]]]
        for rot in (False, True):
            out[f"heading_every_{every:g}s_{'rot' if rot else 'no_rot'}"] = scores(*track(thin, name, rot), ref,
                                                                                 held_out, fixes)
    return out


def main() -> None:
    default = ROOT.parent / "shared" / "data" / "marine"
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(default))
    ap.add_argument("--json", action="store_true")
    ap.add_argument("-e", dest="estimator", default="isam2", help="isam2 (default) or ekf")
    ap.add_argument("--every", default="1,5", help="heading thinning steps [s], comma-separated")
    a = ap.parse_args()
    everies = [float(x) for x in a.every.split(",")]
    logs = sorted(Path(a.data).glob("canboat/*.raw.gz"))
    res = {}
    for p in logs:
        log = load_log(p)
        if not log.of("gnss") or not log.of("odometry"):
            continue
        res[p.name] = study(p, a.estimator, everies)
        if not a.json:
            print(p.name)
            for k, v in res[p.name].items():
                if isinstance(v, dict):
                    y, h, b = v["yaw_vs_full_deg"], v["yaw_vs_headings_deg"], v["compass_bias_deg"]
                    print(f"  {k:26s} yaw vs full rms {y['rms']:.3f} max {y['max']:.3f}, vs headings rms "
                          f"{h['rms']:.3f} p95 {h['p95']:.3f} max {h['max']:.3f} deg, compass bias "
                          f"{'-' if b is None else f'{b:.2f}'} deg, to fixes {v['to_fixes_m']:.3f} m")
    if a.json:
        print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
