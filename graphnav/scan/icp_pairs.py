"""Consecutive scan pairs of a log: match them, and score the increments against the reference.

Pair ``k`` is (scan ``k`` -> scan ``k+1``): source = scan ``k+1``, target = scan ``k``. Which pairs
are scored is decided from the reference alone (:func:`valid_reference_steps`), never from an
estimate; docs/datasets.md explains the rule on the marina data.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import se2_between, wrap_angle
from ..log import NavLog, odometry_samples
from .motion_guess import MotionGuess
from .weighted_icp import IcpConfig, MatchResult, match_points, scan_points


@dataclass
class PairRun:
    """Matches of all consecutive scan pairs of a log (arrays indexed by pair ``k``)."""

    t0: NDArray[np.float64]  # time of scan k (target)
    t1: NDArray[np.float64]  # time of scan k+1 (source)
    results: list[MatchResult]
    ms: NDArray[np.float64]  # wall time of each match [ms]
    config: IcpConfig
    init: str
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def poses(self) -> NDArray[np.float64]:
        return np.array([r.pose for r in self.results]).reshape(-1, 3)

    @property
    def ok(self) -> NDArray[np.bool_]:
        return np.array([r.ok for r in self.results], dtype=bool)


def run_pairs(log: NavLog, config: IcpConfig | None = None, init: str = "cv",
              on_match: Any = None, guess_cov: bool = True) -> PairRun:
    """Match every consecutive scan pair of ``log``.

    ``init`` (:class:`~graphnav.scan.motion_guess.MotionGuess`): ``"cv"`` constant velocity from the
    last good match (after a flagged one: the odometry increment when the log has odometry);
    ``"odometry"`` the odometry increment; ``"zero"`` identity. With ``guess_cov`` an odometry guess
    comes with its covariance (``match_points(init_cov=...)``: a match beyond it is flagged).
    ``on_match(k, result)`` is called after each match (online use).
    """
    guesser = MotionGuess(init, odometry_samples(log))
    cfg = config or IcpConfig()
    scans = log.of("scan")
    pts = [scan_points(s, cfg) for s in scans]
    results: list[MatchResult] = []
    ms = []
    for k in range(len(scans) - 1):
        guess = guesser.guess(scans[k].t, scans[k + 1].t)
        t = time.perf_counter()
        res = match_points(pts[k + 1], pts[k], cfg, init=guess, init_cov=guesser.cov if guess_cov else None)
        ms.append((time.perf_counter() - t) * 1e3)
        results.append(res)
        guesser.update(res, scans[k].t, scans[k + 1].t)
        if on_match is not None:
            on_match(k, res)
    t0 = np.array([s.t for s in scans[:-1]])
    t1 = np.array([s.t for s in scans[1:]])
    return PairRun(t0, t1, results, np.array(ms), cfg, init)


def reference_increments(log: NavLog, t0: NDArray, t1: NDArray, max_dt: float = 1e-6) -> NDArray[np.float64]:
    """Reference relative pose (N, 3) of each pair from the log's truth (NaN rows where a scan
    has no truth record at its time)."""
    truth = log.of("truth")
    tt = np.array([r.t for r in truth])
    poses = np.array([[r.x, r.y, r.yaw] for r in truth]).reshape(-1, 3)
    out = np.full((len(t0), 3), np.nan)
    if len(tt) == 0:
        return out
    for k, (a, b) in enumerate(zip(t0, t1, strict=True)):
        i, j = np.searchsorted(tt, a), np.searchsorted(tt, b)
        i = min(i, len(tt) - 1)
        j = min(j, len(tt) - 1)
        if abs(tt[i] - a) <= max_dt and abs(tt[j] - b) <= max_dt:
            out[k] = se2_between(poses[i], poses[j])
    return out


def valid_reference_steps(
    steps: NDArray[np.float64],
    *,
    window: int = 5,
    max_step_dev: float = 0.15,
    max_step_dev_global: float = 0.2,
    max_yaw_spike: float = np.radians(1.0),
    min_run: int = 3,
) -> NDArray[np.bool_]:
    """Which reference increments (N, 3) are trustworthy, from the reference alone.

    A step is a glitch when its length differs from the median of its ``window`` neighbours on
    each side by more than ``max_step_dev``, or from the median of the whole record by more than
    ``max_step_dev_global`` (the vessel sails at a steady speed), or when its yaw increment is an
    isolated spike: it differs from BOTH adjacent increments by more than ``max_yaw_spike`` in the
    same sense (the start or end of a turn changes the increment on one side only). Valid steps
    must also lie in a run of at least ``min_run`` consecutive valid steps (this drops the ragged
    end of a record whose reference stops). NaN rows are invalid.
    """
    steps = np.asarray(steps, dtype=float)
    n = len(steps)
    length = np.hypot(steps[:, 0], steps[:, 1])
    dyaw = np.asarray(wrap_angle(steps[:, 2]), dtype=float).reshape(-1)
    finite = np.all(np.isfinite(steps), axis=1)
    ok = finite.copy()
    gmed = np.nanmedian(np.where(finite, length, np.nan)) if finite.any() else np.nan
    for k in np.flatnonzero(finite):
        lo, hi = max(0, k - window), min(n, k + window + 1)
        nb = [j for j in range(lo, hi) if j != k and finite[j]]
        if not nb:
            ok[k] = False
            continue
        local = abs(length[k] - np.median(length[nb]))
        if local > max_step_dev or abs(length[k] - gmed) > max_step_dev_global:
            ok[k] = False
            continue
        adj = [dyaw[k] - dyaw[j] for j in (k - 1, k + 1) if 0 <= j < n and finite[j]]
        if len(adj) == 2 and min(abs(a) for a in adj) > max_yaw_spike and adj[0] * adj[1] > 0:
            ok[k] = False
    # runs of consecutive valid steps
    out = ok.copy()
    k = 0
    while k < n:
        if ok[k]:
            j = k
            while j < n and ok[j]:
                j += 1
            if j - k < min_run:
                out[k:j] = False
            k = j
        else:
            k += 1
    return out


def _stats(e: NDArray) -> tuple[float, float, float, float]:
    if len(e) == 0:
        return (float("nan"),) * 4
    i = int(np.argmax(np.abs(e)))
    std = float(e.std(ddof=1)) if len(e) > 1 else 0.0
    return float(e.mean()), std, float(e[i]), float(np.sqrt(np.mean(e**2)))


def score_pairs(run: PairRun, ref: NDArray, scored: NDArray) -> tuple[dict[str, Any], dict[str, NDArray]]:
    """Step-length and rotation-increment errors on the scored pairs (the issue's JSON keys)."""
    est = run.poses
    step_err = np.hypot(est[:, 0], est[:, 1]) - np.hypot(ref[:, 0], ref[:, 1])
    dth_err = np.degrees(np.asarray(wrap_angle(est[:, 2] - ref[:, 2]), dtype=float).reshape(-1))
    s = scored & np.isfinite(step_err)
    sm, ss, sx, sr = _stats(step_err[s])
    dm, ds, dx, dr = _stats(dth_err[s])
    summary = {
        "variant": run.config.variant,
        "init": run.init,
        "pairs": len(run.results),
        "pairs_scored": int(s.sum()),
        "pairs_ok": int(run.ok.sum()),
        "pairs_degenerate": int(sum(bool(r.quality.get("degenerate")) for r in run.results)),
        "step_err_mean_m": sm,
        "step_err_std_m": ss,
        "step_err_max_abs_m": abs(sx) if np.isfinite(sx) else sx,
        "step_err_max_signed_m": sx,
        "step_err_rmse_m": sr,
        "dtheta_err_mean_deg": dm,
        "dtheta_err_std_deg": ds,
        "dtheta_err_max_abs_deg": abs(dx) if np.isfinite(dx) else dx,
        "dtheta_err_max_signed_deg": dx,
        "dtheta_err_rmse_deg": dr,
        "ms_per_pair_median": float(np.median(run.ms)) if len(run.ms) else float("nan"),
    }
    return summary, {"step_err_m": step_err, "dtheta_err_deg": dth_err, "scored": s}


def nees(run: PairRun, ref: NDArray, scored: NDArray, ref_cov: NDArray | None = None) -> NDArray[np.float64]:
    """Normalised squared error of each scored, unflagged pair's increment under its covariance, with
    the error taken in GTSAM's convention (``xi = Log(est^-1 ref)``, first order). ``ref_cov`` (3, 3):
    the reference increments' own covariance, added to each match's (a reference that is not exact)."""
    out = np.full(len(run.results), np.nan)
    extra = np.zeros((3, 3)) if ref_cov is None else np.asarray(ref_cov, dtype=float)
    for k in np.flatnonzero(scored):
        r = run.results[k]
        if not r.ok or not np.all(np.isfinite(ref[k])):
            continue
        xi = se2_between(r.pose, ref[k])
        try:
            out[k] = float(xi @ np.linalg.solve(r.cov + extra, xi))
        except np.linalg.LinAlgError:
            pass
    return out
