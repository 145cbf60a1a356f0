"""Plain sentences a reader can act on: per estimator what it used, what it is and why its figure looks
as it does (over-confident, degenerate, equal to another's track, skipped); the hold-out ranking;
the gaps and jumps found in the data."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..comparison import Comparison, Entry
from ..datacheck import LOG_WINDOW_S

#: a mean NEES (2 dof) outside this band gets a sentence saying what it means
NEES_BAND = (0.3, 5.0)
#: an odometry whose aligned ATE is below this share of its ATE: its error is the start pose (a sentence)
START_SHARE = 0.2
#: a share of degenerate or flagged registrations above this gets a sentence
DEGENERATE_SHARE = 0.5


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) \
        and math.isfinite(float(v)) else None


def _share(info: dict[str, Any], key: str, total: str) -> float | None:
    n, tot = _num(info.get(key)), _num(info.get(total))
    return n / tot if n is not None and tot else None


def _degenerate(e: Entry) -> str | None:
    """What share of its scan registrations an estimator could not trust, as a phrase; ``None`` below
    :data:`DEGENERATE_SHARE`."""
    info = e.result.info if e.result is not None else {}
    for key, total, what in (("degenerate_registrations", "registrations", "registrations were degenerate"),
                             ("failed_registrations", "registrations", "registrations were rejected"),
                             ("icp_failed", "icp_pairs", "weighted-ICP matches were flagged"),
                             ("failed_matches", "matches", "weighted-ICP matches were flagged")):
        s = _share(info, key, total)
        if s is not None and s > DEGENERATE_SHARE:
            return f"{100 * s:.0f} % of its {what}"
    return None


def _start_heading_error(e: Entry, comp: Comparison) -> float | None:
    """How far [deg] the estimate's first heading is from the truth's at that time (None without)."""
    tr = e.result.trajectory if e.result is not None else None
    truth = comp.log.truth() if comp.log.has_truth else None
    if tr is None or truth is None or not len(tr.t) or not truth.t[0] <= tr.t[0] <= truth.t[-1]:
        return None
    d = float(tr.poses[0][2] - truth.interpolate([tr.t[0]])[0][2])
    return abs(math.degrees(math.atan2(math.sin(d), math.cos(d))))


def verdict(e: Entry, comp: Comparison, same: dict[str, tuple[str, float]]) -> str:
    """One estimator in plain words: what it is, what it used, and why its figures look as they do."""
    head = f"**{e.name}** ({e.kind or '?'}): {e.description or 'no description'}."
    if e.skipped is not None and e.error is None:
        return f"{head} Not run: {e.skipped}."
    if e.error is not None:
        return f"{head} Failed: `{e.error}`."
    s = e.summary or {}
    used = s.get("inputs")
    out = [head, f"Used: {', '.join(used) if used else 'none of the log records'}." if used is not None else ""]
    deg = _degenerate(e)
    if e.name in same:
        other, d = same[e.name]
        init = (e.result.info if e.result is not None else {}).get("init")
        if deg:
            why = f"{deg}, so at every step it kept its guess, which is **{other}**'s motion"
        elif isinstance(init, str) and init in ("odometry", "imu"):
            why = (f"it starts every scan match from its {init} guess and fuses the match with that guess, whose "
                   f"covariance is far smaller, so the guess wins and its track is the {init} integration (for the "
                   "scans alone: -O guess_cov=false, where the estimator has it)")
        else:
            why = "it received the same information through the same motion model"
        within = "exactly" if d == 0 else f"within {d:.1g} m"
        out.append(f"Its track equals **{other}**'s {within} at every common time: {why}.")
    elif deg:
        out.append(f"{deg[0].upper() + deg[1:]}: along the weak directions it kept its motion guess, so its "
                   "track is mostly that guess.")
    ate, dr = _num(s.get("ate_rmse_m")), _dead_reckoning_ate(comp)
    aligned = _num(s.get("ate_aligned_rmse_m"))
    if e.kind == "odometry" and ate is not None and aligned is not None and aligned < START_SHARE * ate:
        anchor = (e.result.info if e.result is not None else {}).get("anchor") or "its start pose"
        off = _start_heading_error(e, comp)
        out.append(f"Its shape is right (aligned ATE {aligned:.3g} m against {ate:.3g} m): the error is its start "
                   f"pose's ({anchor.replace('_', ' ')}), mostly the heading"
                   + (f" ({off:.2f} deg off the truth's at its first pose)" if off is not None else "")
                   + ", which odometry never corrects.")
    resets = _num((e.result.info if e.result is not None else {}).get("gnss_resets"))
    sog = _num(s.get("sog_rmse_mps"))
    if resets and sog is not None:
        out.append(f"It is put back on every GNSS fix ({resets:.0f} resets): each reset is a jump in its track, "
                   f"which its SOG ({sog:.2f} m/s RMSE), COG and ROT figures carry.")
    if ate is not None and dr is not None and ate > dr[1] and used is not None and "gnss" in used:
        out.append(f"Worse than **{dr[0]}** ({dr[1]:.3g} m) although it uses GNSS.")
    nees = _num(s.get("nees_mean"))
    no_bias = e.kind == "filter" and "imu" in (used or []) and "bias" not in (e.description or "").lower()
    if nees is not None and comp.log.has_truth:
        if nees > NEES_BAND[1]:
            out.append(f"Over-confident: its position NEES is {nees:.1f} (2 when consistent), its covariance "
                       "is smaller than its errors; do not trust its ±σ bounds"
                       + (" (it models no IMU biases, so an uncalibrated bias drifts it between GNSS fixes "
                          "faster than its process noise allows)." if no_bias else "."))
        elif nees < NEES_BAND[0]:
            out.append(f"Pessimistic: its position NEES is {nees:.2f} (2 when consistent), its covariance is "
                       "larger than its errors.")
        else:
            out.append(f"Consistent: NEES {nees:.2f} (2 expected).")
    if not comp.log.has_truth:
        res = _num(s.get("gnss_residual_rms_m"))
        if res is not None:
            uses_gnss = used is None or "gnss" in used
            out.append(f"No truth: its residual to the GNSS fixes is {res:.2f} m RMS"
                       + (" (it used them, so this shows fit, not accuracy)." if uses_gnss else "."))
    ho = s.get("holdout") or {}
    if _num(ho.get("rmse_m")) is not None:
        out.append(f"Hold-out: {ho['rmse_m']:.2f} m RMS at the end of {ho['scored']} GNSS-free windows.")
        nis = _num(ho.get("nis_mean"))
        if nis is not None and nis > NEES_BAND[1]:
            out.append(f"Its covariance is over-confident in the windows (NIS {nis:.1f}, 2 expected).")
    elif e.kind == "odometry" and not any(k in (used or []) for k in ("gnss", "beacon", "scan", "cloud", "truth")):
        out.append("It has no absolute position after the start: its error grows without bound.")
    return " ".join(p for p in out if p)


def _dead_reckoning_ate(comp: Comparison) -> tuple[str, float] | None:
    """The odometry-only dead reckoning's name and ATE RMSE in this comparison, if it ran."""
    for e in comp.ran:
        v = _num((e.summary or {}).get("ate_rmse_m"))
        if e.name == "dead-reckoning" and v is not None:
            return e.name, v
    return None


def verdicts(comp: Comparison) -> list[str]:
    same = comp.same_tracks()
    return [verdict(e, comp, same) for e in comp.entries]


def holdout_table(comp: Comparison) -> tuple[str, list[str], list[list[str]]] | None:
    """The hold-out ranking (text, header, rows), ``None`` without a hold-out."""
    h = comp.holdout
    if h is None:
        return None
    d = h.describe()
    sigma = f"{d['fix_sigma_m']:.2f} m" if d["fix_sigma_m"] is not None else "–"
    text = (f"Every {h.spec.every_s:g} s the last {h.spec.length_s:g} s of GNSS ({d['withheld']['gnss']} fixes, "
            f"{d['withheld']['gnss_velocity']} velocities) were withheld from every estimator; "
            f"{d['scored_windows']} of {len(h.windows)} windows held a fix to score against"
            + (" (the others fell in gaps of the log)" if d["scored_windows"] < len(h.windows) else "")
            + (f"; {d['silent_windows']} of them held no other record (only GNSS was logged then): there an "
               f"estimator has only its motion model (a smoother's track read between its poses around the window, "
               f"a coasting navigator's online predictions, else the last estimate before: the distance sailed), "
               f"which says little of the sensors (`rmse_informative_m` in the JSON leaves them out)"
               if d.get("silent_windows") else "")
            + f". *end error*: the estimate against the window's last withheld fix (the farthest "
            f"from GNSS); *all*: the mean over every withheld fix; *NIS*: the withheld fixes' normalised "
            f"residual against the estimate's covariance plus the fix's (2 when honest); *online*: the estimate "
            f"available at the time (a smoother's smoothed track also uses the fixes after the window). The fixes' own "
            f"sigma (median, per axis): {sigma}: an error near it is as good as the fixes can tell.")
    head = ["rank", "estimator", "end error RMSE [m]", "end error max [m]", "all mean [m]", "NIS mean",
            "online end RMSE [m]"]
    rows = []
    order = comp.holdout_ranking()
    by = {e.name: e for e in comp.ran}
    for i, n in enumerate(order + [e.name for e in comp.ran if e.name not in order], 1):
        s = (by[n].summary or {}).get("holdout") or {}

        def f(k: str, fmt: str = "{:.2f}", s: dict = s) -> str:
            v = _num(s.get(k))
            return fmt.format(v) if v is not None else "–"

        rows.append([str(i) if n in order else "–", n, f("rmse_m"), f("max_m"), f("mean_m"), f("nis_mean"),
                     f("online_rmse_m")])
    return text, head, rows


def data_lines(comp: Comparison) -> list[str]:
    """The gaps in time and the GNSS jumps of the log as read (before any hold-out)."""
    out = []
    gaps = comp.checks.get("gaps") or {}
    for kind in ("gnss", "all"):
        g = gaps.get(kind)
        if g and g["count"]:
            listed = ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in g["longest"][:5])
            out.append(f"{'GNSS' if kind == 'gnss' else 'All records'}: {g['count']} gaps longer than "
                       f"{g['threshold_s']:.3g} s, {g['total_s']:.0f} s in all (longest: {listed}).")
    j = comp.checks.get("gnss_jumps") or {}
    if j.get("count"):
        listed = ", ".join(f"{d['distance_m']:.1f} m at {d['t1']:.1f} s" for d in j["largest"][:5])
        out.append(f"GNSS jumps: {j['count']} steps between consecutive fixes faster than "
                   f"{j['speed_bound_mps']:.3g} m/s plus 5σ of the fixes ({listed}).")
    sl = comp.checks.get("speed_log") or {}
    spread = (sl.get("scale_spread") or 0.0) / math.sqrt(max(len(sl.get("windows") or []), 1))
    if sl.get("scale") is not None and abs(sl["scale"] - 1.0) > max(0.02, 3.0 * spread):  # 2 %, beyond its spread
        way = "under" if sl["scale"] > 1.0 else "over"
        out.append(f"Speed log: it {way}-reads by {abs(sl['scale'] - 1.0) * 100:.0f} % against the GNSS velocity "
                   f"(scale {sl['scale']:.3f} over {len(sl['windows'])} windows of {LOG_WINDOW_S:.0f} s); every "
                   "estimator takes its readings at face value, so a dead reckoning on it drifts by that fraction "
                   "of the distance sailed through a GNSS gap.")
    return out or ["No gaps in time and no GNSS jumps found."]
