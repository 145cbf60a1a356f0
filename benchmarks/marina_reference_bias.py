"""Where the weighted ICP and the marina's RTK reference disagree: per-segment biases, and whether
de-skewing the sweep changes them (docs/weighted-icp.md, "Downstream", marina-degraded).

    python benchmarks/marina_reference_bias.py [--marina DIR] [--sweep 1.0] [--json]

HDL, constant-velocity guess, the default settings. For each pair with a clean reference step
(:func:`graphnav.scan.icp_pairs.valid_reference_steps`) the error ``xi = Log(est^-1 ref)`` (the
reference relative to the match, in the match's frame); printed as means per step over four
segments (two turns, the quay, a straight), with and without de-skewing.

De-skew: the Scanse Sweep samples while it spins (750 samples per revolution here), so a return's
time within the sweep is its sample index / 750 x ``--sweep`` seconds (the array order is the
time order). Both scans of a pair are moved to the sweep's middle by the pair's own twist (the
match divided by the time step; two iterations), ``p <- Exp(twist tau) p``, and matched again.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import gtsam
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import se2_between  # noqa: E402
from graphnav.io.marina import read_marina  # noqa: E402
from graphnav.scan.icp_pairs import nees, reference_increments, run_pairs, valid_reference_steps  # noqa: E402
from graphnav.scan.weighted_icp import IcpConfig, match_points  # noqa: E402

SEGMENTS = {"turn 1": (35, 50), "quay": (76, 98), "straight": (115, 141), "turn 2": (147, 167)}


def se2_exp_apply(xi: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``Exp(xi_i) p_i`` for twists ``xi`` (N, 3) and points ``pts`` (N, 2) (SE(2) exponential)."""
    vx, vy, th = xi.T
    small = np.abs(th) < 1e-9
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0, np.sin(ths) / ths)
    b = np.where(small, 0.0, 2.0 * np.sin(0.5 * ths) ** 2 / ths)  # (1 - cos th) / th without cancellation
    tx, ty = a * vx - b * vy, b * vx + a * vy
    c, s = np.cos(th), np.sin(th)
    return np.column_stack([c * pts[:, 0] - s * pts[:, 1] + tx, s * pts[:, 0] + c * pts[:, 1] + ty])


def deskewed(scan, twist: np.ndarray, sweep: float) -> np.ndarray:  # noqa: ANN001
    r, a = np.asarray(scan.ranges, float), np.asarray(scan.angles, float)
    idx = np.flatnonzero(np.isfinite(r) & (r > 0) & np.isfinite(a))
    tau = (idx / len(r) - 0.5) * sweep
    p = np.column_stack([r[idx] * np.cos(a[idx]), r[idx] * np.sin(a[idx])])
    return se2_exp_apply(np.outer(tau, twist), p)


def segment_rows(xi: np.ndarray, ref: np.ndarray, use: np.ndarray) -> list[dict]:
    rows = []
    for name, (a, b) in SEGMENTS.items():
        m = use.copy()
        m[:a] = False
        m[b:] = False
        rows.append({"segment": name, "pairs": f"{a}-{b - 1}", "n": int(m.sum()),
                     "along_m": float(xi[m, 0].mean()), "lateral_m": float(xi[m, 1].mean()),
                     "yaw_deg": float(np.degrees(xi[m, 2].mean())), "ref_yaw_deg": float(np.degrees(ref[m, 2].mean())),
                     "yaw_sum_deg": float(np.degrees(xi[m, 2].sum()))})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--marina", type=Path, default=None)
    ap.add_argument("--sweep", type=float, default=1.0, help="sweep period [s] for the de-skew")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    path = args.marina or next((b / "shared" / "data" / "icp_data_marina" for b in (ROOT.parent, ROOT.parent.parent)
                                if (b / "shared" / "data" / "icp_data_marina").exists()), None)
    if path is None:
        print("marina data not found (--marina DIR)", file=sys.stderr)
        return 2
    log = read_marina(path)
    cfg = IcpConfig(variant="HDL")
    pr = run_pairs(log, cfg, init="cv", guess_cov=False)
    ref = reference_increments(log, pr.t0, pr.t1)
    clean = valid_reference_steps(ref)
    ne = nees(pr, ref, clean)
    use = np.isfinite(ne)
    est = np.array([r.pose for r in pr.results])
    scans = [r for r in log if r.kind == "scan"]
    skew, cov0 = est.copy(), np.array([r.cov for r in pr.results])
    cov = cov0.copy()
    for k in range(len(est)):
        dt = pr.t1[k] - pr.t0[k]
        for _ in range(2):
            twist = np.asarray(gtsam.Pose2.Logmap(gtsam.Pose2(*skew[k]))) / dt  # the pair's own twist
            m = match_points(deskewed(scans[k + 1], twist, args.sweep), deskewed(scans[k], twist, args.sweep),
                             cfg, init=skew[k])
            skew[k], cov[k] = m.pose, m.cov
    out = {}
    for name, e, c in (("as recorded", est, cov0), (f"de-skewed ({args.sweep:g} s sweep)", skew, cov)):
        xi = np.array([se2_between(p, f) for p, f in zip(e, ref, strict=True)])
        n_ = np.einsum("ni,ni->n", xi, np.linalg.solve(c, xi[:, :, None])[:, :, 0])
        rms = np.sqrt(np.mean(xi[use] ** 2, axis=0))
        out[name] = {"rms_m_x": float(rms[0]), "rms_m_y": float(rms[1]), "rms_yaw_deg": float(np.degrees(rms[2])),
                     "nees_mean": float(np.mean(n_[use])), "segments": segment_rows(xi, ref, use)}
    if args.json:
        print(json.dumps(out))
        return 0
    for name, o in out.items():
        print(f"{name}: RMS x {o['rms_m_x']:.4f} m, y {o['rms_m_y']:.4f} m, yaw {o['rms_yaw_deg']:.3f} deg, "
              f"mean NEES {o['nees_mean']:.1f}")
        print("| segment (pairs) | along-track (m) | lateral (m) | yaw (deg) | reference yaw per step (deg) "
              "| yaw error summed (deg) |\n|---|---|---|---|---|---|")
        for r in o["segments"]:
            print(f"| {r['segment']} ({r['pairs']}) | {r['along_m']:+.3f} | {r['lateral_m']:+.3f} "
                  f"| {r['yaw_deg']:+.3f} | {r['ref_yaw_deg']:+.2f} | {r['yaw_sum_deg']:+.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
