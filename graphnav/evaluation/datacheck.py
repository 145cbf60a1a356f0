"""What can be judged in a log without looking at an estimate: gaps in time and jumps in the GNSS
fixes. ``graphnav info`` lists them; the comparison report shows them (most useful without truth)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..log import NavLog

#: A gap is a step between consecutive records longer than this many times the median step (and
#: than GAP_MIN_S): a GNSS outage, a logger pause, a lost stretch of file.
GAP_FACTOR = 5.0
GAP_MIN_S = 1.0
GAPS_LISTED = 10
#: A GNSS jump: consecutive fixes farther apart than JUMP_SPEED_FACTOR x the fixes' 95th-percentile
#: speed (+ JUMP_SPEED_FLOOR m/s) covers in the interval, plus JUMP_SIGMAS x the two fixes' sigma.
JUMP_SPEED_FACTOR = 3.0
JUMP_SPEED_FLOOR = 1.0
JUMP_SIGMAS = 5.0
JUMPS_LISTED = 10


def time_gaps(t: np.ndarray) -> dict[str, Any]:
    """The gaps of a sorted time series: steps longer than ``max(GAP_MIN_S, GAP_FACTOR x median
    step)``; their count, total length [s] and the longest :data:`GAPS_LISTED` as ``[t0, t1]``."""
    dt = np.diff(t)
    pos = dt[dt > 0]
    threshold = max(GAP_MIN_S, GAP_FACTOR * float(np.median(pos))) if pos.size else GAP_MIN_S
    idx = np.flatnonzero(dt > threshold)
    longest = idx[np.argsort(-dt[idx], kind="stable")][:GAPS_LISTED]
    return {"threshold_s": threshold, "count": int(idx.size), "total_s": float(dt[idx].sum()),
            "longest": [[float(t[i]), float(t[i + 1])] for i in sorted(longest)]}


def gaps(log: NavLog) -> dict[str, dict[str, Any]]:
    """:func:`time_gaps` of all records together (``"all"``) and of each timed record kind with at
    least 3 records."""
    t_all = np.array([r.t for r in log.records], dtype=float)
    out = {"all": time_gaps(t_all)} if t_all.size >= 3 else {}
    kinds = np.array([r.kind for r in log.records])
    for k in log.counts():
        sel = kinds == k
        if int(sel.sum()) >= 3:
            out[k] = time_gaps(t_all[sel])
    return out


def gnss_jumps(log: NavLog) -> dict[str, Any]:
    """Jumps between consecutive GNSS fixes (see :data:`JUMP_SPEED_FACTOR`): ``count``, the speed
    bound used [m/s] and the largest :data:`JUMPS_LISTED` as ``{"t0", "t1", "distance_m"}``."""
    if len(log.of("gnss")) < 3:
        return {"count": 0, "speed_bound_mps": None, "largest": []}
    c = log.columns("gnss")
    t, x, y, s = (np.asarray(c[k], float) for k in ("t", "x", "y", "sigma"))
    dt, d = np.diff(t), np.hypot(np.diff(x), np.diff(y))
    ok = dt > 0
    v = d[ok] / dt[ok]
    bound = JUMP_SPEED_FACTOR * float(np.percentile(v, 95)) + JUMP_SPEED_FLOOR if v.size else JUMP_SPEED_FLOOR
    allowed = bound * np.maximum(dt, 0.0) + JUMP_SIGMAS * np.hypot(s[1:], s[:-1])
    idx = np.flatnonzero(d > allowed)
    big = sorted(idx[np.argsort(-d[idx], kind="stable")][:JUMPS_LISTED])
    return {"count": int(idx.size), "speed_bound_mps": bound,
            "largest": [{"t0": float(t[i]), "t1": float(t[i + 1]), "distance_m": float(d[i])} for i in big]}


def data_checks(log: NavLog) -> dict[str, Any]:
    """``{"gaps": gaps(log), "gnss_jumps": gnss_jumps(log)}``."""
    return {"gaps": gaps(log), "gnss_jumps": gnss_jumps(log)}
