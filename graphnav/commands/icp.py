"""``graphnav icp LOG --variant {K,H,HM,HD,HDL}``: match every consecutive scan pair and score
the step length and rotation increment against the reference (the weighted-ICP paper's test)."""

from __future__ import annotations

import argparse
import csv
import logging
from pathlib import Path

import numpy as np

from ..errors import GraphnavError
from ..io import load_log
from ..io.outputs import OutDir, atomic_open, atomic_path
from ..scan.icp_pairs import nees, reference_increments, run_pairs, score_pairs, valid_reference_steps
from ..scan.motion_guess import INITS
from ..scan.movement import movement_from_increments
from ..scan.weighted_icp import VARIANTS, IcpConfig
from ._common import add_json_flag, add_log_args, add_overwrite_flag, emit, log_options, plain_options, progress_bar

log_ = logging.getLogger("graphnav.icp")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("icp", help="weighted ICP over consecutive scan pairs, scored against the reference",
                       description=__doc__)
    add_log_args(p)
    p.add_argument("--variant", choices=VARIANTS, default="HD", help="weighting variant (default HD)")
    p.add_argument("--init", choices=INITS, default="zero",
                   help="initial guess: constant velocity (last good match; odometry after a flagged one), "
                        "the odometry increment, or identity (default)")
    p.add_argument("--score", choices=("clean", "all"), default="clean",
                   help="pairs scored: 'clean' the reference-only glitch rule (steady speed; meant for the "
                        "marina's RTK reference, docs/datasets.md), 'all' every pair with truth (default clean)")
    p.add_argument("--out", type=Path, help="directory for pairs.csv and the Figs. 12-15 style plots")
    add_overwrite_flag(p)
    p.add_argument("--option", "-O", action="append", metavar="KEY=VALUE",
                   help="IcpConfig field, e.g. -O sigma_alpha=0.005 -O matching=delaunay; repeatable")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.out:
        return _icp(args, None)
    out = OutDir(args.out, command="icp", overwrite=args.overwrite)
    with out.discarded_on_error():  # a failed icp leaves nothing in --out
        return _icp(args, out)


def _icp(args: argparse.Namespace, out: OutDir | None) -> int:
    log = load_log(args.log, lenient=args.lenient, **log_options(args))
    options = plain_options(args)
    cfg = IcpConfig(variant=args.variant, **options)
    if len(log.of("scan")) < 2:
        raise GraphnavError(f"needs at least two scans, has {len(log.of('scan'))}", where=str(args.log))
    log_.info("matching %d scan pairs with %s (init %s)", len(log.of("scan")) - 1, args.variant, args.init)
    with progress_bar(args, total=len(log.of("scan")) - 1, desc=f"{args.variant} ICP", unit="pair") as bar:
        pr = run_pairs(log, cfg, init=args.init, on_match=lambda k, res: bar.update(1))
    ref = reference_increments(log, pr.t0, pr.t1)
    scored = valid_reference_steps(ref) if args.score == "clean" else np.all(np.isfinite(ref), axis=1)
    summary, per = score_pairs(pr, ref, scored)
    ne = nees(pr, ref, scored)
    summary["nees_mean"] = float(np.nanmean(ne)) if np.isfinite(ne).any() else float("nan")
    summary["nees_median"] = float(np.nanmedian(ne)) if np.isfinite(ne).any() else float("nan")
    summary["options"] = options
    if out is not None:
        write_pairs_csv(out.file("pairs.csv"), pr, ref, scored, per, ne)
        summary["plots"] = write_plots(out, args.variant, per)
        summary["out"] = str(args.out)
    human = "\n".join(f"{k:26s} {v}" for k, v in summary.items())
    emit(args, summary, human)
    return 0


def write_pairs_csv(path: Path, pr, ref, scored, per, ne) -> None:  # noqa: ANN001
    est = pr.poses
    dt = pr.t1 - pr.t0
    mv = movement_from_increments(est, dt)
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["pair", "t0", "t1", "dx", "dy", "dyaw", "ref_dx", "ref_dy", "ref_dyaw", "sog", "rot",
                    "step_err_m", "dtheta_err_deg", "scored", "ok", "nees", "sigma_x", "sigma_y", "sigma_yaw",
                    "points_used", "inlier_fraction", "residual", "condition_number", "iterations", "ms"])
        for k, r in enumerate(pr.results):
            q = r.quality
            w.writerow([k, pr.t0[k], pr.t1[k], *est[k], *ref[k], mv["sog"][k], mv["rot"][k],
                        per["step_err_m"][k], per["dtheta_err_deg"][k], int(per["scored"][k]),
                        int(r.ok), ne[k],
                        *np.sqrt(np.diag(r.cov)), q.get("points_used"), q.get("inlier_fraction"),
                        q.get("residual"), q.get("condition_number"), q.get("iterations"), pr.ms[k]])


def write_plots(out: Path | OutDir, variant: str, per: dict) -> list[str]:
    """The paper's Figs. 12-15: SOG / dCOG difference series and their histograms."""
    from matplotlib.figure import Figure  # (no pyplot: the matplotlib backend is left as it is)

    s = per["scored"]
    k = np.flatnonzero(s)
    files = []
    for key, label, unit, fig_series, fig_hist in (
        ("step_err_m", "SOG_ICP - SOG_R", "m/s", "fig12_sog_diff.png", "fig13_sog_hist.png"),
        ("dtheta_err_deg", "dCOG_ICP - dCOG_R", "deg", "fig14_dcog_diff.png", "fig15_dcog_hist.png"),
    ):
        e = per[key][s]
        fig = Figure(figsize=(8, 3))
        ax = fig.add_subplot()
        ax.plot(k, e, ".-", lw=0.8, label=f"{variant}_ICP")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel("scan pair")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.legend()
        fig.tight_layout()
        with atomic_path(out / fig_series) as tmp:
            fig.savefig(tmp, dpi=120)
        fig = Figure(figsize=(5, 3))
        ax = fig.add_subplot()
        ax.hist(e, bins=30)
        ax.set_xlabel(f"{label} [{unit}]")
        ax.set_ylabel("count")
        fig.tight_layout()
        with atomic_path(out / fig_hist) as tmp:
            fig.savefig(tmp, dpi=120)
        files += [fig_series, fig_hist]
    return files
