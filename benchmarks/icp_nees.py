"""NEES of the weighted-ICP increments against truth: marina, harbour, the nine CARMEN logs.

    python benchmarks/icp_nees.py [--marina DIR] [--carmen LOG ...] [--variant HDL] [--json]

One setting for all (``IcpConfig(variant=...)``, the defaults; initial guess the odometry increment
where the log has odometry, else constant velocity, as ``icp-dr``, but without the guess's
covariance, so that the pairs kept are those the matcher itself accepts: with it, a direction the
odometry knows better is taken from the odometry, which on the harbour is nearly every pair). For every
unflagged pair with a reference increment: ``NEES = xi^T cov^-1 xi``, ``xi = Log(est^-1 ref)``
(GTSAM's convention, :func:`graphnav.scan.icp_pairs.nees`); chi-square with 3 degrees of freedom
has mean 3 and a 95 % bound of 7.81.

What "truth" is here:

* marina: the RTK reference of the 160 clean pairs (the reference-only rule of
  :func:`graphnav.scan.icp_pairs.valid_reference_steps`; docs/datasets.md, the data's README). The
  reference has its own per-step noise, 0.01-0.05 m and 0.03-0.1 deg (README): printed also with
  those bounds added to each covariance;
* harbour: ``data/harbour.npz``, simulated, exact;
* CARMEN: the SLAM-corrected laser poses, which carry their own cm-level, tenth-of-a-degree error
  per step (Kümmerle et al., *On measuring the accuracy of SLAM algorithms*, Auton. Robots 27,
  2009, report relation errors of a few cm and 0.4-1.3 deg for SLAM results on these logs).

``implied ref sigma`` is the reference noise per step that would close the gap between the errors
and the covariances (per component ``max(0, mean(xi^2) - mean(cov_ii))``; translation averaged over
x and y): compare it with what is known of each reference. Medians, the fraction beyond the 95 %
bound and the counts are printed beside the means (the errors are heavy-tailed).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import se2_between  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.io.marina import read_marina  # noqa: E402
from graphnav.scan.icp_pairs import nees, reference_increments, run_pairs, valid_reference_steps  # noqa: E402
from graphnav.scan.weighted_icp import IcpConfig  # noqa: E402

CHI2_3_95 = 7.815
MARINA_REF = {"README lower (0.01 m, 0.03 deg)": (0.01, 0.03), "README upper (0.05 m, 0.1 deg)": (0.05, 0.1)}


def find(*names: str) -> Path | None:
    for base in (ROOT.parent, ROOT.parent.parent):
        p = base.joinpath(*names)
        if p.exists():
            return p
    return None


def ref_cov(sigma_m: float, sigma_deg: float) -> np.ndarray:
    return np.diag([sigma_m**2, sigma_m**2, np.radians(sigma_deg) ** 2])


def stats(name: str, log, variant: str, marina: bool = False) -> dict:  # noqa: ANN001
    pr = run_pairs(log, IcpConfig(variant=variant), init="odometry", guess_cov=False)
    ref = reference_increments(log, pr.t0, pr.t1)
    scored = valid_reference_steps(ref) if marina else np.all(np.isfinite(ref), axis=1)
    ne = nees(pr, ref, scored)
    use = np.isfinite(ne)
    xi = np.array([se2_between(r.pose, f) for r, f in zip(pr.results, ref, strict=True)])[use]
    cov = np.array([r.cov for r in pr.results])[use]
    gap = np.maximum(np.mean(xi**2, axis=0) - np.mean(np.diagonal(cov, axis1=1, axis2=2), axis=0), 0.0)
    row = {"dataset": name, "scored": int(scored.sum()), "unflagged": int(use.sum()),
           "nees_mean": float(np.mean(ne[use])), "nees_median": float(np.median(ne[use])),
           "beyond_95": float(np.mean(ne[use] > CHI2_3_95)),
           "err_t_rms_m": float(np.sqrt(np.mean(xi[:, 0] ** 2 + xi[:, 1] ** 2) / 2)),
           "sigma_t_rms_m": float(np.sqrt(np.mean(cov[:, 0, 0] + cov[:, 1, 1]) / 2)),
           "err_rot_rms_deg": float(np.degrees(np.sqrt(np.mean(xi[:, 2] ** 2)))),
           "sigma_rot_rms_deg": float(np.degrees(np.sqrt(np.mean(cov[:, 2, 2])))),
           "implied_ref_sigma_m": float(np.sqrt((gap[0] + gap[1]) / 2)),
           "implied_ref_sigma_deg": float(np.degrees(np.sqrt(gap[2])))}
    if marina:
        for label, (sm, sd) in MARINA_REF.items():
            n2 = nees(pr, ref, scored, ref_cov(sm, sd))
            row[f"nees_mean with {label}"] = float(np.nanmean(n2))
    return row


def fmt(rows: list[dict]) -> str:
    out = ["| dataset | pairs scored (unflagged) | mean NEES | median | > 95 % bound | error / 1-sigma, "
           "translation per axis (m) | rotation (deg) | implied ref. sigma (m / deg) |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['dataset']} | {r['scored']} ({r['unflagged']}) | {r['nees_mean']:.2f} | "
                   f"{r['nees_median']:.2f} | {100 * r['beyond_95']:.0f} % | {r['err_t_rms_m']:.4f} / "
                   f"{r['sigma_t_rms_m']:.4f} | {r['err_rot_rms_deg']:.3f} / {r['sigma_rot_rms_deg']:.3f} | "
                   f"{r['implied_ref_sigma_m']:.4f} / {r['implied_ref_sigma_deg']:.3f} |")
    extra = [f"- {r['dataset']}: {k} = {v:.2f}" for r in rows for k, v in r.items() if k.startswith("nees_mean with")]
    return "\n".join(out + ([""] + extra if extra else []))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--marina", type=Path, default=find("shared", "data", "icp_data_marina"))
    ap.add_argument("--harbour", type=Path, default=ROOT / "data" / "harbour.npz")
    ap.add_argument("--carmen", nargs="*", type=Path, default=None,
                    help="converted CARMEN logs (default ../cache/logs/carmen-*.jsonl.gz)")
    ap.add_argument("--variant", default="HDL")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args()
    carmen = args.carmen
    if carmen is None:
        base = find("cache", "logs")
        carmen = sorted(base.glob("carmen-*.jsonl.gz")) if base else []
    rows = []
    if args.marina and args.marina.exists():
        rows.append(stats("marina (RTK)", read_marina(args.marina), args.variant, marina=True))
    if args.harbour.exists():
        rows.append(stats("harbour (exact)", load_log(args.harbour), args.variant))
    for p in carmen:
        rows.append(stats(p.name.removesuffix(".jsonl.gz") + " (SLAM)", load_log(p), args.variant))
        print(f"{p.name}: done", file=sys.stderr)
    if carmen:
        c = [r for r in rows if r["dataset"].endswith("(SLAM)")]
        rows.append({"dataset": "CARMEN, all pairs", "scored": sum(r["scored"] for r in c),
                     "unflagged": sum(r["unflagged"] for r in c),
                     **{k: float(np.average([r[k] for r in c], weights=[r["unflagged"] for r in c]))
                        for k in ("nees_mean", "beyond_95")},
                     **{k: float(np.sqrt(np.average([r[k] ** 2 for r in c], weights=[r["unflagged"] for r in c])))
                        for k in ("err_t_rms_m", "sigma_t_rms_m", "err_rot_rms_deg", "sigma_rot_rms_deg",
                                  "implied_ref_sigma_m", "implied_ref_sigma_deg")},
                     "nees_median": float("nan")})
    if args.json:
        print(json.dumps({"variant": args.variant, "rows": rows}))
    else:
        print(fmt(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
