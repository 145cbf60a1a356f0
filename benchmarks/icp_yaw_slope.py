"""Is the weighted ICP's yaw short on small steps? The match's yaw increments against the log's truth
(issue #25; docs/defaults.md, "What was fitted").

    python benchmarks/icp_yaw_slope.py LOG... [--pairs N] [--init truth|odometry] [--matcher hdl|p2l|both]
                                              [--sweep SECONDS]

Every consecutive scan pair is matched from the truth's increment (``--init odometry``: from the
odometry's, as the graph does); the match's own estimate is kept (``quality["icp_pose"]``, before a
flag replaces any of it by the guess). A pair is *good* when the match converged with the inlier
fraction the matcher asks for and its yaw error is within 5 robust sigmas (1.4826 x the median
absolute error) of the truth's. Per log:

* ``w1``: the regression slope (through the origin) of the matches' yaw increments on the truth's over
  the good pairs, and the reverse one (1 / the slope of the truth's on the matches'). Noise in the
  truth's increments pulls the first below the true scale, noise in the matches pushes the second
  above it: the two bracket the scale when the noises are independent.
* ``windows``: the same on sums of W consecutive pairs (sliding windows; a pair that is not good
  counts with the truth's increment, ``filled`` of them). A per-pose noise -- of the truth, or a scan
  whose points do not sit where its pose says -- telescopes in a sum; a yaw scale does not.
* ``scale_offset``: least squares of the error sums over non-overlapping windows of 20 pairs on the
  truth's net yaw in them and the number of good pairs: the yaw scale error [%] and a constant
  per-pair yaw offset [deg], with their standard errors (separates a scale from a drift that the
  log's net turning makes look like one).
* ``lag1``: the lag-1 autocorrelation of the per-pair yaw error (consecutive pairs share a scan:
  -0.5 for pure per-pose noise, 0 for independent per-pair errors).
* ``binned``: the mean yaw error [deg] in bins of the truth's increment and in bins of the match's
  own: a matcher that shrinks small steps shows it binned either way; noise in the truth's poses
  shows a pull toward zero binned by the truth's increment only (regression to the mean).
* ``pair_rms``: the RMS per-pair error of the matches and of the odometry against the truth
  (translation [m], yaw [deg]).

``--sweep S`` de-skews every scan first as a LiDAR sweeping its beams in index order over ``S``
seconds would need (:mod:`graphnav.scan.deskew`, beam ``i`` of ``N`` at ``i S / N``), with the truth's
twist over the scan's next pair: a sweep left in the scans turns every match clockwise by
``~ dyaw w S / pi`` when the beams are taken counter-clockwise (a SICK LMS: 180 deg in 6.7 ms).

``--matcher p2l`` runs :func:`p2l_match` instead, a textbook point-to-line ICP independent of
graphnav's kernels (cKDTree nearest neighbours, unweighted Gauss-Newton); ``both`` runs the two on
the same pairs and adds the RMS of their yaw difference and the correlation of their errors: when
two independent matchers agree with each other much better than with the truth, what separates them
from the truth is in the data (the truth, the scans' geometry), not in a matcher.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.geometry import increment, wrap_angle  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.log import odometry_samples  # noqa: E402
from graphnav.scan.deskew import twist_of  # noqa: E402
from graphnav.scan.icp_pairs import reference_increments  # noqa: E402
from graphnav.scan.weighted_icp import IcpConfig, match_points, scan_points  # noqa: E402

WINDOWS = (1, 5, 20, 100, 500)
SCALE_WINDOW = 20
OUTLIER_SIGMAS = 5.0
BIN_EDGES_DEG = (-40.0, -6.0, -2.0, -1.0, -0.3, 0.3, 1.0, 2.0, 6.0, 40.0)


# ----------------------------------------------------------------------------- an independent matcher


def p2l_match(src: NDArray[np.float64], tgt: NDArray[np.float64], init: NDArray[np.float64], *,
              gate: float = 0.3, k: int = 10, min_flat: float = 0.8, max_iter: int = 60
              ) -> tuple[NDArray[np.float64], bool]:
    """A textbook 2D point-to-line ICP: ``(dx, dy, dyaw)`` of ``src`` (N, 2) in ``tgt``'s (M, 2) frame
    from ``init``, and whether it converged. The target's lines are the PCA of each point's ``k``
    nearest neighbours (kept where the line is flat: 1 - l_min / l_max >= ``min_flat``); pairs are the
    nearest target points within ``gate`` [m]; each step is the unweighted Gauss-Newton step of
    ``sum (n . (R p + t - q))^2``."""
    tree = cKDTree(tgt)
    _, nn = tree.query(tgt, k)
    c = tgt[nn] - tgt[nn].mean(1, keepdims=True)
    lam, vec = np.linalg.eigh(np.einsum("mki,mkj->mij", c, c))
    normal = vec[:, :, 0]
    flat = 1.0 - lam[:, 0] / np.maximum(lam[:, 1], 1e-12)
    th, tx, ty = float(init[2]), float(init[0]), float(init[1])
    for _ in range(max_iter):
        co, si = np.cos(th), np.sin(th)
        p = src @ np.array([[co, si], [-si, co]]) + (tx, ty)
        d, j = tree.query(p)
        use = (d < gate) & (flat[j] >= min_flat)
        if use.sum() < 3:
            return np.array([tx, ty, th]), False
        n, q, pu = normal[j[use]], tgt[j[use]], p[use]
        r = np.einsum("ij,ij->i", n, pu - q)
        jac = np.column_stack([n, n[:, 1] * pu[:, 0] - n[:, 0] * pu[:, 1]])  # left increment about the origin
        dtx, dty, dth = -np.linalg.lstsq(jac, r, rcond=None)[0]
        cd, sd = np.cos(dth), np.sin(dth)
        th, tx, ty = th + dth, cd * tx - sd * ty + dtx, sd * tx + cd * ty + dty
        if abs(dth) < 1e-9 and np.hypot(dtx, dty) < 1e-8:
            return np.array([tx, ty, th]), True
    return np.array([tx, ty, th]), False


# ----------------------------------------------------------------------------- the statistics


def yaw_errors(est: NDArray, ref: NDArray, ok: NDArray) -> tuple[NDArray, NDArray]:
    """Per-pair yaw error (match - truth, wrapped) and the good pairs (``ok``, finite, within
    :data:`OUTLIER_SIGMAS` robust sigmas)."""
    err = np.asarray(wrap_angle(np.asarray(est, dtype=float) - np.asarray(ref, dtype=float)), dtype=float).reshape(-1)
    good = np.asarray(ok, dtype=bool) & np.isfinite(err)
    if good.any():
        sigma = 1.4826 * np.median(np.abs(err[good]))
        good &= np.abs(err) <= OUTLIER_SIGMAS * sigma
    return err, good


def _filled(est: NDArray, ref: NDArray, good: NDArray) -> tuple[NDArray, NDArray]:
    r = np.where(np.isfinite(ref), ref, 0.0)
    return np.where(good, est, r), r


def window_slopes(est: NDArray, ref: NDArray, good: NDArray, w: int) -> tuple[float, float]:
    """Forward and reverse regression slopes of the match's yaw on the truth's over sliding sums of
    ``w`` pairs (pairs that are not good take the truth's increment)."""
    y, r = _filled(est, ref, good)
    cy, cr = np.r_[0.0, np.cumsum(y)], np.r_[0.0, np.cumsum(r)]
    a, b = cy[w:] - cy[:-w], cr[w:] - cr[:-w]
    if w == 1:
        a, b = a[good], b[good]
    return float(a @ b / (b @ b)), float(a @ a / (a @ b))


def scale_offset(est: NDArray, ref: NDArray, good: NDArray, w: int = SCALE_WINDOW) -> dict[str, float]:
    """Yaw scale error and constant per-pair offset from the error sums of non-overlapping windows of
    ``w`` pairs (least squares on the truth's net yaw and the good pairs per window)."""
    y, r = _filled(est, ref, good)
    n = len(y) // w * w
    e = (y - r)[:n].reshape(-1, w).sum(1)
    x = np.column_stack([r[:n].reshape(-1, w).sum(1), good[:n].reshape(-1, w).sum(1).astype(float)])
    coef, *_ = np.linalg.lstsq(x, e, rcond=None)
    dof = max(len(e) - 2, 1)
    cov = np.sum((e - x @ coef) ** 2) / dof * np.linalg.inv(x.T @ x)
    se = np.sqrt(np.diag(cov))
    return {"scale_pct": 100 * float(coef[0]), "scale_se_pct": 100 * float(se[0]),
            "offset_deg": float(np.degrees(coef[1])), "offset_se_deg": float(np.degrees(se[1])), "windows": len(e)}


def lag1(err: NDArray, good: NDArray) -> float:
    """Lag-1 autocorrelation of the yaw error over consecutive good pairs."""
    i = np.flatnonzero(good[:-1] & good[1:])
    return float(np.corrcoef(err[i], err[i + 1])[0, 1]) if len(i) > 2 else float("nan")


def binned(est: NDArray, ref: NDArray, err: NDArray, good: NDArray, by: str) -> list[dict]:
    """Mean yaw error [deg] (and its standard error) in bins of the truth's (``by="truth"``) or the
    match's (``by="match"``) yaw increment."""
    x = np.degrees(ref if by == "truth" else est)
    out = []
    for lo, hi in zip(BIN_EDGES_DEG[:-1], BIN_EDGES_DEG[1:], strict=True):
        s = good & (x >= lo) & (x < hi)
        if s.sum() >= 5:
            e = np.degrees(err[s])
            out.append({"bin_deg": [lo, hi], "n": int(s.sum()), "mean_err_deg": float(e.mean()),
                        "se_deg": float(e.std(ddof=1) / np.sqrt(s.sum()))})
    return out


def summary(est: NDArray, ref: NDArray, ok: NDArray) -> dict:
    """The statistics of the module docstring for one matcher's (N, 3) estimates against the truth's."""
    err, good = yaw_errors(est[:, 2], ref[:, 2], ok)
    fw, rv = window_slopes(est[:, 2], ref[:, 2], good, 1)
    txy = np.hypot(est[good, 0] - ref[good, 0], est[good, 1] - ref[good, 1])
    return {"good": int(good.sum()), "w1": {"slope": fw, "reverse": rv},
            "windows": [dict(zip(("pairs", "slope", "reverse"), (w, *window_slopes(est[:, 2], ref[:, 2], good, w)),
                                 strict=True)) for w in WINDOWS[1:] if w < len(est)],
            "filled": int((~good).sum()), "scale_offset": scale_offset(est[:, 2], ref[:, 2], good),
            "lag1": lag1(err, good),
            "pair_rms": {"xy_m": float(np.sqrt(np.mean(txy ** 2))),
                         "yaw_deg": float(np.degrees(np.sqrt(np.mean(err[good] ** 2))))},
            "binned_by_truth": binned(est[:, 2], ref[:, 2], err, good, "truth"),
            "binned_by_match": binned(est[:, 2], ref[:, 2], err, good, "match")}


# ----------------------------------------------------------------------------- the study


def _twists(ref: NDArray, t0: NDArray, t1: NDArray) -> list[NDArray | None]:
    """Per scan, the truth's constant twist over its next pair (the last scan: its previous one)."""
    out: list[NDArray | None] = []
    for k in range(len(ref) + 1):
        j = k if k < len(ref) else k - 1
        ok = j >= 0 and np.all(np.isfinite(ref[j])) and t1[j] > t0[j]
        out.append(twist_of(ref[j], float(t1[j] - t0[j])) if ok else None)
    return out


def match_all(path: Path, pairs: int, init: str, matchers: list[str], sweep: float = 0.0
              ) -> tuple[dict, NDArray, NDArray]:
    """Every consecutive pair of the first ``pairs`` + 1 scans matched by each of ``matchers``:
    ``{matcher: (est (N, 3), ok (N,))}``, the truth's increments (N, 3) and the odometry's; with a
    ``sweep`` [s] the scans de-skewed first with the truth's twist."""
    log = load_log(path)
    scans = log.of("scan")[:pairs + 1]
    t0 = np.array([s.t for s in scans[:-1]])
    t1 = np.array([s.t for s in scans[1:]])
    ref = reference_increments(log, t0, t1)
    odo_samples = odometry_samples(log)
    odo = np.full_like(ref, np.nan)
    cfg = IcpConfig()
    if sweep:
        pts = [scan_points(s, cfg, sweep_s=sweep, twist=tw) for s, tw in zip(scans, _twists(ref, t0, t1), strict=True)]
    else:
        pts = [scan_points(s, cfg) for s in scans]
    out = {m: (np.full_like(ref, np.nan), np.zeros(len(t0), dtype=bool)) for m in matchers}
    for k in range(len(t0)):
        inc = increment(odo_samples, t0[k], t1[k]) if len(odo_samples) else None
        if inc is not None:
            odo[k] = inc[0]
        guess = ref[k] if init == "truth" else (inc[0] if inc is not None else np.zeros(3))
        if not np.all(np.isfinite(guess)):
            continue
        if "hdl" in out:
            r = match_points(pts[k + 1], pts[k], cfg, init=guess)
            q = r.quality
            out["hdl"][0][k] = q.get("icp_pose", r.pose)
            out["hdl"][1][k] = bool(q.get("converged")) and q.get("inlier_fraction", 0.0) >= cfg.min_inlier_fraction
        if "p2l" in out:
            out["p2l"][0][k], out["p2l"][1][k] = p2l_match(pts[k + 1], pts[k], guess)
    return out, ref, odo


def study(path: Path, pairs: int, init: str, matcher: str, sweep: float = 0.0) -> dict:
    matchers = ["hdl", "p2l"] if matcher == "both" else [matcher]
    res, ref, odo = match_all(path, pairs, init, matchers, sweep)
    dt = np.isfinite(ref[:, 2])
    out: dict = {"log": path.name, "pairs": len(ref), "init": init, "sweep_s": sweep,
                 "truth_turn_deg": {"net": float(np.degrees(ref[dt, 2].sum())),
                                    "abs": float(np.degrees(np.abs(ref[dt, 2]).sum()))}}
    for m, (est, ok) in res.items():
        out[m] = summary(est, ref, ok)
    if np.isfinite(odo).any():
        eo = odo - ref
        f = np.all(np.isfinite(eo), axis=1)
        eyaw = np.asarray(wrap_angle(eo[f, 2]), dtype=float)
        out["odometry_pair_rms"] = {"xy_m": float(np.sqrt(np.mean(eo[f, 0] ** 2 + eo[f, 1] ** 2))),
                                    "yaw_deg": float(np.degrees(np.sqrt(np.mean(eyaw ** 2))))}
    if matcher == "both":
        (a, oka), (b, okb) = res["hdl"], res["p2l"]
        ea, ga = yaw_errors(a[:, 2], ref[:, 2], oka)
        eb, gb = yaw_errors(b[:, 2], ref[:, 2], okb)
        g = ga & gb
        d = np.asarray(wrap_angle(a[g, 2] - b[g, 2]), dtype=float)
        out["hdl_vs_p2l"] = {"pairs": int(g.sum()), "yaw_diff_rms_deg": float(np.degrees(np.sqrt(np.mean(d ** 2)))),
                             "error_correlation": float(np.corrcoef(ea[g], eb[g])[0, 1])}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", type=Path, nargs="+")
    ap.add_argument("--pairs", type=int, default=100_000)
    ap.add_argument("--init", choices=("truth", "odometry"), default="truth")
    ap.add_argument("--matcher", choices=("hdl", "p2l", "both"), default="both")
    ap.add_argument("--sweep", type=float, default=0.0, help="de-skew the scans for this sweep [s] first")
    args = ap.parse_args()
    for p in args.logs:
        print(json.dumps(study(p, args.pairs, args.init, args.matcher, args.sweep)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
