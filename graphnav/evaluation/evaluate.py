"""Score a :class:`RunResult` against the log's truth: the JSON keys every report shares."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..log import NavLog
from ..result import RunResult
from .metrics import (
    MOVEMENT_DT_S,
    ate,
    event_windows,
    gnss_residuals,
    heading_error,
    movement_errors,
    nees_stats,
    rpe,
    rpe_over,
    window_errors,
)


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _median(a: np.ndarray) -> float:
    return float(np.median(a)) if len(a) else float("nan")


def errors_by_event(result: RunResult, log: NavLog, *, max_dt: float = 0.02) -> dict[str, dict[str, Any]]:
    """Position errors inside the log's ``meta["events"]`` windows, per event kind (gnss_outage,
    gnss_jump, gnss_multipath, ...): ``{kind: {"windows", "duration_s", "n", "rmse_m", "max_m",
    "online_n", "online_rmse_m", "online_max_m", "sog_rmse_mps", "cog_rmse_deg", "rot_rmse_degps",
    "online_sog_rmse_mps", "online_cog_rmse_deg", "online_rot_rmse_degps"}}`` (the movement parameters
    between consecutive poses inside the windows: what the LiDAR gives through a GNSS outage).
    ``n``: the estimate/truth pairs inside the
    kind's windows (:func:`~graphnav.evaluation.metrics.window_errors`, the pairs of the ATE); the
    ``online_*`` figures are the online trajectory's (the same as the others when the estimator
    has one trajectory; ``None`` without an online one). ``{}`` without truth or events."""
    if not log.has_truth:
        return {}
    ref = log.truth()
    out: dict[str, dict[str, Any]] = {}
    for kind, wins in event_windows(log.meta.get("events")).items():
        w = window_errors(result.trajectory, ref, wins, max_dt=max_dt)
        d: dict[str, Any] = {"windows": len(wins), "duration_s": float(sum(t1 - t0 for t0, t1 in wins)),
                             "n": w["n"], "rmse_m": w["rmse"], "max_m": w["max"]}
        o = window_errors(result.online, ref, wins, max_dt=max_dt) if result.online is not None else None
        d.update({"online_n": o["n"] if o else None, "online_rmse_m": o["rmse"] if o else None,
                  "online_max_m": o["max"] if o else None})
        for prefix, tr in (("", result.trajectory), ("online_", result.online)):
            m = movement_errors(tr, ref, max_dt=max_dt, windows=wins, dt=MOVEMENT_DT_S) if tr is not None else None
            for key, name in (("sog", "sog_rmse_mps"), ("cog", "cog_rmse_deg"), ("rot", "rot_rmse_degps")):
                d[prefix + name] = _finite(m[key]["rmse"]) if m is not None else None
        out[kind] = d
    return out


def gnss_scores(traj: Any, log: NavLog) -> dict[str, Any]:
    """What a log without truth can say about an estimate: its residuals to the log's GNSS fixes
    (``gnss_residual_rms_m``, ``gnss_residual_median_m``) and their normalised innovation
    (``gnss_nis_mean``: about 2 when the estimate's covariance and the fixes' sigma are honest; the
    fixes the estimator used pull it below). ``{}`` without GNSS fixes."""
    if not log.of("gnss"):
        return {}
    c = log.columns("gnss")
    r = gnss_residuals(traj, c["t"], np.column_stack([c["x"], c["y"]]), c["sigma"])
    e = r["residual_m"]
    if not e.size:
        return {}
    nis = r["nis"]
    return {"gnss_residual_rms_m": float(np.sqrt(np.mean(e ** 2))), "gnss_residual_median_m": float(np.median(e)),
            "gnss_nis_mean": float(np.mean(nis)) if nis is not None and nis.size else None,
            "gnss_fixes_scored": int(e.size)}


def summarize(name: str, result: RunResult, log: NavLog, *, runtime_s: float,
              rpe_delta: int = 10, max_dt: float = 0.02) -> dict[str, Any]:
    """The standard summary: ``estimator``, ``steps``, ``ate_*``, ``rpe_*``, timing, movement errors,
    ``heading_rmse_deg``, ``errors_by_event`` (:func:`errors_by_event`) and ``nees_mean`` (position NEES
    of the estimate's own covariance, 2 dof: about 2 when consistent; ``None`` when the estimator gives
    no covariance).

    ATE is unaligned (in the log's frame) unless the key says ``aligned``. Keys for truth-based
    figures are present only when the log has truth.
    """
    traj = result.trajectory
    out: dict[str, Any] = {
        "estimator": name,
        "steps": len(traj),
        "runtime_s": runtime_s,
        "step_ms_median": _median(result.step_ms),
        "icp_ms_median": _median(result.icp_ms),
    }
    if log.has_truth:
        ref = log.truth()
        a = ate(traj, ref, max_dt=max_dt)
        out.update({
            "ate_rmse_m": a["rmse"], "ate_mean_m": a["mean"], "ate_median_m": a["median"], "ate_max_m": a["max"],
            "ate_aligned_rmse_m": ate(traj, ref, align=True, max_dt=max_dt)["rmse"],
            "scored_poses": a["n"],
        })
        r1 = rpe(traj, ref, delta=1, all_pairs=True, max_dt=max_dt)
        rn = rpe(traj, ref, delta=rpe_delta, all_pairs=True, max_dt=max_dt)
        out.update({"rpe_rmse_m": r1["trans"]["rmse"], "rpe_rot_rmse_deg": r1["rot"]["rmse"],
                    f"rpe{rpe_delta}_rmse_m": rn["trans"]["rmse"],
                    "rpe_1s_rmse_m": _finite(rpe_over(traj, ref, MOVEMENT_DT_S, max_dt=max_dt)["trans"]["rmse"])})
        out["heading_rmse_deg"] = heading_error(traj, ref, max_dt=max_dt)["rmse"]
        mv = movement_errors(traj, ref, max_dt=max_dt, dt=MOVEMENT_DT_S)
        out.update({"sog_rmse_mps": mv["sog"]["rmse"], "cog_rmse_deg": mv["cog"]["rmse"],
                    "rot_rmse_degps": mv["rot"]["rmse"]})
        ns = nees_stats(traj, ref, max_dt=max_dt)
        out["nees_mean"] = ns["mean"] if ns else None
        out["nees_in95"] = ns["in95"] if ns else None
        if result.online is not None and result.online is not traj:
            out["online_ate_rmse_m"] = ate(result.online, ref, max_dt=max_dt)["rmse"]
            ns = nees_stats(result.online, ref, max_dt=max_dt)
            out["online_nees_mean"] = ns["mean"] if ns else None
        out["errors_by_event"] = errors_by_event(result, log, max_dt=max_dt)
    out.update(gnss_scores(traj, log))
    for k in ("anchor", "loop_closures", "loop_candidates", "switched_off", "odometry_consistency", "odometry_scale",
              "noise_scale", "covariance_noise", "coasted_estimates", "gnss_rejected", "gnss_reacquired",
              "water_current", "current_final", "log_scale_final", "log_scale_sigma", "log_scale_series",
              "water_speed_censored", "water_reaimed_online"):
        if k in result.info:
            out[k] = result.info[k]
    return out
