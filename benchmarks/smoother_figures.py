"""Figures for docs/smoother.md: harbour map with truth / GNSS / isam2 online + smoothed, and the
marina-degraded track with its GNSS outage and jump; error over time for both.

    python benchmarks/smoother_figures.py [--out docs/figures]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from graphnav import estimators  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.sim.harbour import harbour_polygons  # noqa: E402


def _err(traj, ref):
    p = traj.interpolate(ref.t)
    return np.hypot(p[:, 0] - ref.x, p[:, 1] - ref.y)


def figure(log, title: str, path: Path, polys=None) -> None:
    r = estimators.run("isam2", log, covariances=False)
    ref = log.truth()
    g = log.columns("gnss")
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1.3, 1]})
    for poly in polys or []:
        a.fill(poly[:, 0], poly[:, 1], color="0.75", lw=0)
    a.plot(g["x"], g["y"], ".", ms=2, color="tab:orange", label="GNSS")
    a.plot(ref.x, ref.y, "k-", lw=1.2, label="truth")
    a.plot(r.online.x, r.online.y, "-", lw=0.8, color="tab:blue", label="isam2 online")
    a.plot(r.trajectory.x, r.trajectory.y, "-", lw=0.8, color="tab:green", label="isam2 smoothed")
    for bk in log.beacons_known:
        a.plot(bk.x, bk.y, "r^", ms=7)
    a.set_aspect("equal")
    a.legend(loc="best", fontsize=8)
    a.set_title(title)
    a.set_xlabel("x east [m]")
    a.set_ylabel("y north [m]")
    b.plot(ref.t, _err(r.online, ref), color="tab:blue", lw=0.8, label="online")
    b.plot(ref.t, _err(r.trajectory, ref), color="tab:green", lw=0.8, label="smoothed")
    for ev in log.meta.get("events", []):
        if ev["kind"] in ("gnss_outage", "gnss_jump"):
            b.axvspan(ev["t0"], ev["t1"], color="tab:red" if ev["kind"] == "gnss_jump" else "0.8", alpha=0.3)
            b.text(ev["t0"], b.get_ylim()[1] * 0.95, ev["kind"].replace("gnss_", ""), fontsize=7)
    b.set_xlabel("t [s]")
    b.set_ylabel("position error [m]")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(path)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    figure(load_log(ROOT / "data" / "harbour.npz"), "harbour seed 0", args.out / "smoother_harbour.png",
           harbour_polygons())
    sys.path.insert(0, str(ROOT / "tests"))
    from conftest import find_marina

    d = find_marina()
    if d is not None:
        from graphnav.sim.marina_degraded import simulate_marina_degraded

        figure(simulate_marina_degraded(d, args.seed), f"marina-degraded seed {args.seed}",
               args.out / "smoother_marina_degraded.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
